// OpenHapticsDevice: a Phantom/Touch through the vendor's HD API (OpenHaptics),
// loaded with dlopen at start() so the daemon builds and runs where the SDK is
// absent (the SDK is proprietary and not packaged for Debian).
//
// The HD API owns its own 1 kHz servo thread (hdStartScheduler); device state
// may only be touched inside its scheduler callbacks. The bridge therefore
// runs one asynchronous callback that, inside hdBeginFrame/hdEndFrame, publishes
// the pose into a LatestValue and renders the newest force it finds in
// another LatestValue. read()/write() only touch those triple buffers, so they
// stay wait-free and allocation-free; the price is one servo tick of latency.
//
// Only the failure path (library missing -> clear error naming the library and
// dlerror()) can be tested on machines without the SDK.
#pragma once

#include <atomic>
#include <string>

#include "concurrency/latest_value.hpp"
#include "config/daemon_config.hpp"
#include "haptics/device.hpp"

namespace tissue::haptics {

class OpenHapticsDevice final : public Device {
 public:
  explicit OpenHapticsDevice(const config::OpenHapticsSpec& spec);
  ~OpenHapticsDevice() override;

  bool start(std::string* error) override;
  void stop() noexcept override;
  bool read(std::int64_t now_ns, DeviceSample* out) noexcept override;
  void write(std::int64_t now_ns, const Vec3& force_N) noexcept override;
  const char* name() const noexcept override { return "openhaptics"; }

  // Called on the SDK's servo thread (public only for the C trampoline).
  unsigned int servo_callback() noexcept;

 private:
  struct Api;  // resolved HD entry points
  config::OpenHapticsSpec spec_;
  void* library_ = nullptr;
  Api* api_ = nullptr;
  unsigned int device_handle_ = 0;
  unsigned long scheduler_handle_ = 0;
  bool running_ = false;
  concurrency::LatestValue<DeviceSample> pose_;  // servo thread -> haptic loop
  concurrency::LatestValue<Vec3> force_;         // haptic loop -> servo thread
  std::atomic<bool> have_pose_{false};
};

}  // namespace tissue::haptics
