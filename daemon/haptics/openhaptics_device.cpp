#include "haptics/openhaptics_device.hpp"

#include <dlfcn.h>

#include <type_traits>

namespace tissue::haptics {
namespace {

// The subset of the HD API used here, with the values of its public header
// (hdDefines.h). Units of the HD API: millimetres, millimetres per second, newtons.
using HHD = unsigned int;
using HDenum = unsigned int;
using HDCallbackCode = unsigned int;
using HDSchedulerHandle = unsigned long;
struct HDErrorInfo {
  unsigned int errorCode;
  int internalErrorCode;
  HHD hHD;
};
constexpr HHD kHdInvalidHandle = 0xFFFFFFFFu;
constexpr unsigned int kHdSuccess = 0x0000;
constexpr HDenum kHdCurrentPosition = 0x2050;
constexpr HDenum kHdCurrentVelocity = 0x2051;
constexpr HDenum kHdCurrentForce = 0x2700;
constexpr HDenum kHdForceOutput = 0x4000;
constexpr HDCallbackCode kHdCallbackContinue = 1;
constexpr unsigned short kHdDefaultSchedulerPriority = 500;
constexpr double kMmToM = 1e-3;

HDCallbackCode servo_trampoline(void* self) { return static_cast<OpenHapticsDevice*>(self)->servo_callback(); }

}  // namespace

struct OpenHapticsDevice::Api {
  HHD (*hdInitDevice)(const char*) = nullptr;
  void (*hdDisableDevice)(HHD) = nullptr;
  HDErrorInfo (*hdGetError)() = nullptr;
  void (*hdEnable)(HDenum) = nullptr;
  void (*hdStartScheduler)() = nullptr;
  void (*hdStopScheduler)() = nullptr;
  HDSchedulerHandle (*hdScheduleAsynchronous)(HDCallbackCode (*)(void*), void*, unsigned short) = nullptr;
  void (*hdUnschedule)(HDSchedulerHandle) = nullptr;
  void (*hdBeginFrame)(HHD) = nullptr;
  void (*hdEndFrame)(HHD) = nullptr;
  void (*hdGetDoublev)(HDenum, double*) = nullptr;
  void (*hdSetDoublev)(HDenum, const double*) = nullptr;
};

OpenHapticsDevice::OpenHapticsDevice(const config::OpenHapticsSpec& spec) : spec_(spec) {}

OpenHapticsDevice::~OpenHapticsDevice() {
  stop();
  delete api_;
  if (library_) dlclose(library_);
}

bool OpenHapticsDevice::start(std::string* error) {
  auto fail = [&](const std::string& why) {
    if (error) *error = "openhaptics device: " + why;
    return false;
  };
  if (!library_) {
    dlerror();  // clear any stale message
    library_ = dlopen(spec_.library.c_str(), RTLD_NOW | RTLD_LOCAL);
    if (!library_) {
      const char* why = dlerror();
      return fail("cannot load vendor library '" + spec_.library + "': " + (why ? why : "unknown dlopen error") +
                  " (install OpenHaptics or set device.openhaptics.library)");
    }
  }
  if (!api_) {
    auto api = new Api;
    std::string missing;
    auto resolve = [&](auto& fn, const char* symbol) {
      dlerror();
      void* p = dlsym(library_, symbol);
      if (!p) missing += std::string(missing.empty() ? "" : ", ") + symbol;
      fn = reinterpret_cast<std::remove_reference_t<decltype(fn)>>(p);
    };
    resolve(api->hdInitDevice, "hdInitDevice");
    resolve(api->hdDisableDevice, "hdDisableDevice");
    resolve(api->hdGetError, "hdGetError");
    resolve(api->hdEnable, "hdEnable");
    resolve(api->hdStartScheduler, "hdStartScheduler");
    resolve(api->hdStopScheduler, "hdStopScheduler");
    resolve(api->hdScheduleAsynchronous, "hdScheduleAsynchronous");
    resolve(api->hdUnschedule, "hdUnschedule");
    resolve(api->hdBeginFrame, "hdBeginFrame");
    resolve(api->hdEndFrame, "hdEndFrame");
    resolve(api->hdGetDoublev, "hdGetDoublev");
    resolve(api->hdSetDoublev, "hdSetDoublev");
    if (!missing.empty()) {
      delete api;
      return fail("library '" + spec_.library + "' lacks HD API symbols: " + missing);
    }
    api_ = api;
  }
  device_handle_ = api_->hdInitDevice(spec_.device_name.c_str());
  const HDErrorInfo init_error = api_->hdGetError();
  if (device_handle_ == kHdInvalidHandle || init_error.errorCode != kHdSuccess)
    return fail("hdInitDevice('" + spec_.device_name + "') failed with HD error " +
                std::to_string(init_error.errorCode) + " (internal " + std::to_string(init_error.internalErrorCode) +
                ")");
  force_.write(Vec3::Zero());
  api_->hdEnable(kHdForceOutput);
  scheduler_handle_ = api_->hdScheduleAsynchronous(&servo_trampoline, this, kHdDefaultSchedulerPriority);
  api_->hdStartScheduler();
  const HDErrorInfo sched_error = api_->hdGetError();
  if (sched_error.errorCode != kHdSuccess) {
    api_->hdUnschedule(scheduler_handle_);
    api_->hdDisableDevice(device_handle_);
    return fail("hdStartScheduler failed with HD error " + std::to_string(sched_error.errorCode));
  }
  running_ = true;
  return true;
}

void OpenHapticsDevice::stop() noexcept {
  if (!running_) return;
  api_->hdStopScheduler();
  api_->hdUnschedule(scheduler_handle_);
  api_->hdDisableDevice(device_handle_);
  running_ = false;
}

unsigned int OpenHapticsDevice::servo_callback() noexcept {
  api_->hdBeginFrame(device_handle_);
  double position_mm[3] = {0, 0, 0};
  double velocity_mm_per_s[3] = {0, 0, 0};
  api_->hdGetDoublev(kHdCurrentPosition, position_mm);
  api_->hdGetDoublev(kHdCurrentVelocity, velocity_mm_per_s);
  DeviceSample& sample = pose_.write_buffer();
  sample.position_m = kMmToM * Vec3(position_mm[0], position_mm[1], position_mm[2]);
  sample.velocity_m_per_s = kMmToM * Vec3(velocity_mm_per_s[0], velocity_mm_per_s[1], velocity_mm_per_s[2]);
  pose_.publish();
  have_pose_.store(true, std::memory_order_release);
  const Vec3& force_N = *force_.read().value;
  const double force[3] = {force_N.x(), force_N.y(), force_N.z()};
  api_->hdSetDoublev(kHdCurrentForce, force);
  api_->hdEndFrame(device_handle_);
  return kHdCallbackContinue;
}

bool OpenHapticsDevice::read(std::int64_t, DeviceSample* out) noexcept {
  if (!running_ || !have_pose_.load(std::memory_order_acquire)) return false;
  const auto r = pose_.read();
  *out = *r.value;
  return r.is_new;  // no new servo frame since the last tick: the loop holds the last pose
}

void OpenHapticsDevice::write(std::int64_t, const Vec3& force_N) noexcept {
  if (running_) force_.write(force_N.allFinite() ? force_N : Vec3::Zero());
}

}  // namespace tissue::haptics
