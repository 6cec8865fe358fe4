#include "service/haptic_side.hpp"

#include <stdexcept>
#include <string>
#include <utility>

#include "haptics/device.hpp"
#include "haptics/frame_transform.hpp"
#include "haptics/haptic_loop.hpp"
#include "haptics/haptic_thread.hpp"
#include "haptics/loop_wrap.hpp"
#include "haptics/replay_device.hpp"
#include "record/session_tools.hpp"

namespace tissue::service {

void format_haptic_summary(const haptics::HapticStats& stats, const char* device_name,
                           const haptics::UdpDevice::Stats* link, char* buffer, std::size_t size) {
  if (size == 0) return;
  std::size_t used = 0;
  // Appends while there is room; snprintf truncates the last piece.
  const auto append = [&](const char* format, auto... args) {
    if (used >= size) return;
    const int n = std::snprintf(buffer + used, size - used, format, args...);
    if (n > 0) used += static_cast<std::size_t>(n);
  };
  append(" | haptic %s F %.2f N%s", device_name, stats.force_N, stats.contact ? " contact" : "");
  using Count = std::pair<std::uint64_t, const char*>;
  // " (title: 1 a, 2 b)" over the non-zero counts; nothing when all are zero.
  const auto counts = [&](const char* title, std::initializer_list<Count> items) {
    const char* separator = title;
    for (const auto& [count, what] : items) {
      if (count == 0) continue;
      append("%s%llu %s", separator, static_cast<unsigned long long>(count), what);
      separator = ", ";
    }
    if (separator != title) append(")");
  };
  // The loop counts rising edges per kind; "other" is a stop request, the
  // watchdog or a non-finite force (the JSON status counts the last).
  const std::uint64_t named = stats.stale_model_trips + stats.device_lost_trips;
  const std::uint64_t other = stats.safety_trips > named ? stats.safety_trips - named : 0;
  counts(" (safety trips: ", {Count{stats.stale_model_trips, "stale model"},
                              Count{stats.device_lost_trips, "device lost"}, Count{other, "other"}});
  counts(" (inputs rejected: ",
         {Count{stats.rejected_speed, "too fast"}, Count{stats.rejected_workspace, "outside the workspace"},
          Count{stats.rejected_nonfinite, "non-finite"}});
  if (link) {
    using R = haptics::UdpDevice::Reject;
    const auto& r = link->rejected;
    const auto n = [&](R reason) {
      return Count{r[static_cast<int>(reason)], haptics::UdpDevice::reject_name(reason)};
    };
    counts(" (udp dropped: ", {n(R::kSize), n(R::kFingerprint), n(R::kVersion), n(R::kKind), n(R::kNonFinite),
                               n(R::kOtherSender), Count{link->out_of_order, "out of order"}});
  }
}

nlohmann::json udp_link_json(const haptics::UdpDevice::Stats& link) {
  nlohmann::json rejected = nlohmann::json::object();
  for (int i = 0; i < static_cast<int>(haptics::UdpDevice::Reject::kCount); ++i)
    rejected[haptics::UdpDevice::reject_name(static_cast<haptics::UdpDevice::Reject>(i))] = link.rejected[i];
  return {{"received", link.received},
          {"accepted", link.accepted},
          {"rejected", rejected},
          {"out_of_order", link.out_of_order},
          {"resyncs", link.resyncs},
          {"sessions", link.sessions},
          {"receive_errors", link.receive_errors},
          {"sent", link.sent},
          {"send_failures", link.send_failures},
          {"reply_source_fallbacks", link.reply_source_fallbacks}};
}

namespace {

class HapticSideImpl final : public HapticSide {
 public:
  HapticSideImpl(const config::DaemonConfig& config, ToolSampleRing& samples, LocalModelChannel& models,
                 std::FILE* out) {
    std::string error;
    std::string wrap_warning;  // a looping track's wrap the loop will take as a glitch
    const haptics::ReplayDevice* replay = nullptr;
    if (config.device.kind == config::DeviceSpec::Kind::kReplay) {
      const record::HapticTrack track = record::read_haptic_track(config.device.replay.session);  // names the file
      std::vector<haptics::Vec3> positions;
      positions.reserve(track.device_position_m.size());
      // Recorded in the scene frame; the loop maps device -> scene with this
      // config's offset and scale, so the hand retraces the recorded path
      // whatever they are.
      const haptics::FrameTransform frame = haptics::FrameTransform::from(config.device.offset_m, config.device.scale);
      for (const auto& p : track.device_position_m)
        positions.push_back(frame.position_to_device(haptics::Vec3(p[0], p[1], p[2])));
      // With the session's device_fresh flags (empty for a file from before
      // them) the replay spreads each step exactly as the loop measured it,
      // and a gap over which the live loop lost the device (judged with this
      // config's device timeout on the recorded times) gives no samples, so
      // the loop loses the device over it as it did live. The holes the
      // recorder left (rows it dropped) are not judged as time without a
      // sample: the device's ticks there are unknown.
      auto device = std::make_unique<haptics::ReplayDevice>(
          track.time_s, std::move(positions), config.device.replay.speed, config.device.replay.loop,
          config.device.limits.max_speed_m_per_s, track.device_fresh, config.device.limits.device_timeout_s,
          track.rows_after_holes);
      replay = device.get();
      device_ = std::move(device);
    } else {
      device_ = haptics::make_device(config.device, &error);
      wrap_warning = haptics::sim_loop_wrap_warning(config.device, config.haptics.rate_hz);
    }
    if (!device_) throw std::runtime_error("haptic device: " + (error.empty() ? "none configured" : error));
    udp_ = dynamic_cast<const haptics::UdpDevice*>(device_.get());
    if (!device_->start(&error)) {
      // A replay's refusal is about the session's track: name the file.
      const std::string which =
          replay ? std::string(" (device.replay.session ") + config.device.replay.session + ")" : std::string();
      throw std::runtime_error(std::string("haptic device ") + device_->name() + which + ": " + error);
    }
    // The wrap as the replay plays it (start() built its knots): from the last
    // sample it plays to the first, which is the device's first sample when
    // the recording began before it, not the track's first row (the device
    // origin): judged on the raw rows, a seamless loop was warned about and a
    // real jump missed. Through the time it plays no samples across the wrap
    // (the rows before that first sample, a tail after the last): the loop
    // judges the jump over that time, not over one tick.
    if (replay)
      wrap_warning = haptics::loop_wrap_warning("device.replay.loop", replay->loop_wrap_jump_m(),
                                                config.device.limits.max_speed_m_per_s, config.haptics.rate_hz,
                                                replay->loop_wrap_no_sample_s());
    memory_ = haptics::lock_memory(config.realtime.lock_memory);
    loop_ = std::make_unique<haptics::HapticLoop>(*device_, config.device, config.haptics, models, samples);
    thread_ = std::make_unique<haptics::HapticThread>(*loop_, config.haptics, config.realtime);
    if (!thread_->start(&error)) {
      device_->stop();
      throw std::runtime_error("haptic thread: " + error);
    }
    rate_hz_ = config.haptics.rate_hz;
    limits_ = config.device.limits;
    if (out && !wrap_warning.empty()) {
      std::fprintf(out, "tissued: warning: %s\n", wrap_warning.c_str());
      std::fflush(out);
    }
  }
  ~HapticSideImpl() override { stop(); }

  void stop() override {
    if (stopped_) return;
    stopped_ = true;
    thread_->request_stop();  // ramps the force to zero first
    thread_->join();
    device_->stop();
  }

  std::uint64_t heartbeat() const override { return loop_->heartbeat().load(std::memory_order_relaxed); }

  void summary(char* buffer, std::size_t size) const override {
    haptics::UdpDevice::Stats link;
    if (udp_) link = udp_->stats();
    format_haptic_summary(loop_->stats(), device_->name(), udp_ ? &link : nullptr, buffer, size);
  }

  haptics::HapticStats stats() const override { return loop_->stats(); }

  nlohmann::json status_json() const override {
    const haptics::HapticStats s = loop_->stats();
    const haptics::TimingSummary t = thread_->timing();
    nlohmann::json j = {
        {"device", device_->name()},
        {"rate_hz", rate_hz_},
        {"ticks", s.ticks},
        {"contact", s.contact},
        {"force_N", s.force_N},
        {"force_scale", s.force_scale},
        // The limits in force (a reload applies new ones): what the operator set.
        {"limits",
         {{"max_force_N", limits_.max_force_N},
          {"max_force_rate_N_per_s", limits_.max_force_rate_N_per_s},
          {"max_stiffness_N_per_m", limits_.max_stiffness_N_per_m}}},
        {"model_version", s.model_version},
        {"passivity_energy_J", s.passivity_energy_J},
        {"rejected_inputs", s.rejected_inputs},
        {"rejected_inputs_by_reason",
         {{"too_fast", s.rejected_speed},
          {"outside_workspace", s.rejected_workspace},
          {"non_finite", s.rejected_nonfinite}}},
        {"missing_samples", s.missing_samples},
        {"safety_trips", s.safety_trips},
        {"stale_model_trips", s.stale_model_trips},
        {"device_lost_trips", s.device_lost_trips},
        {"ring_drops", s.ring_drops},
        {"overruns", t.overruns},
        {"lateness_us",
         {{"p50", 1e-3 * t.lateness_p50_ns}, {"p99", 1e-3 * t.lateness_p99_ns}, {"p999", 1e-3 * t.lateness_p999_ns}}},
        {"compute_us",
         {{"p50", 1e-3 * t.compute_p50_ns}, {"p99", 1e-3 * t.compute_p99_ns}, {"p999", 1e-3 * t.compute_p999_ns}}},
        {"scheduling", thread_->scheduling().summary()},
        {"memory_lock", memory_.message}};
    if (udp_) j["link"] = udp_link_json(udp_->stats());
    return j;
  }

  void print_startup(std::FILE* out) const override {
    std::fprintf(out, "tissued: haptic device %s at %g Hz; %s; memory: %s\n", device_->name(), rate_hz_,
                 thread_->scheduling().summary().c_str(), memory_.message.c_str());
  }

 private:
  std::unique_ptr<haptics::Device> device_;
  const haptics::UdpDevice* udp_ = nullptr;  // device_ when it is the UDP bridge: its counters go in the status
  std::unique_ptr<haptics::HapticLoop> loop_;
  std::unique_ptr<haptics::HapticThread> thread_;
  haptics::MemoryLockReport memory_;
  double rate_hz_ = 0.0;
  config::ForceLimits limits_;
  bool stopped_ = false;
};

}  // namespace

std::unique_ptr<HapticSide> HapticSide::start(const config::DaemonConfig& config, ToolSampleRing& samples,
                                              LocalModelChannel& models, std::FILE* out) {
  return std::make_unique<HapticSideImpl>(config, samples, models, out);
}

}  // namespace tissue::service
