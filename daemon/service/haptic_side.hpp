// The haptic half of the service: the device, the 1 kHz loop and its thread,
// connected to the sim thread through the tool-sample ring and the local
// model channel. Exists only when the config names a device and the scene
// has a tool.
#pragma once

#include <cstdint>
#include <cstdio>
#include <memory>
#include <nlohmann/json.hpp>

#include "config/daemon_config.hpp"
#include "haptics/haptic_loop.hpp"
#include "haptics/udp_device.hpp"
#include "service/sim_thread.hpp"

namespace tissue::service {

// The haptic part of the status line, e.g. " | haptic sim F 0.42 N contact",
// and after a safety fault " (safety trips: 1 stale model, 2 other)": which
// fault ramped the force out is what an operator needs to act on (a stale
// model points at the sim thread, a lost device at the device or its link).
// Device samples the loop refused follow, by reason (" (inputs rejected: 3
// too fast)"), and for the UDP bridge (link non-null) the datagrams it
// dropped (" (udp dropped: 5 size, 2 out of order)"): the once-a-second line
// is their rate limit. Never allocates; truncates to size.
void format_haptic_summary(const haptics::HapticStats& stats, const char* device_name,
                           const haptics::UdpDevice::Stats* link, char* buffer, std::size_t size);
// The UDP bridge's counters for `tissue ctl status` (haptic.link).
nlohmann::json udp_link_json(const haptics::UdpDevice::Stats& link);

class HapticSide {
 public:
  // Builds and starts the device and the haptic thread. Throws
  // std::runtime_error naming the device and the reason when it cannot start.
  static std::unique_ptr<HapticSide> start(const config::DaemonConfig& config, ToolSampleRing& samples,
                                           LocalModelChannel& models, std::FILE* out);
  virtual ~HapticSide() = default;

  // Ramps the force to zero, then stops the thread and the device. Idempotent.
  virtual void stop() = 0;
  // Advances every tick: the watchdog is fed only while it moves.
  virtual std::uint64_t heartbeat() const = 0;
  // format_haptic_summary() of the loop's current stats.
  virtual void summary(char* buffer, std::size_t size) const = 0;
  virtual nlohmann::json status_json() const = 0;
  // The loop's counters (relaxed reads: a snapshot for the io thread).
  virtual haptics::HapticStats stats() const = 0;
  // Device, scheduling and memory locking actually obtained.
  virtual void print_startup(std::FILE* out) const = 0;
};

}  // namespace tissue::service
