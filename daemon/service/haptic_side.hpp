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
#include "service/sim_thread.hpp"

namespace tissue::service {

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
  // " | haptic 1000 Hz F 0.42 N contact" for the status line.
  virtual void summary(char* buffer, std::size_t size) const = 0;
  virtual nlohmann::json status_json() const = 0;
  // Device, scheduling and memory locking actually obtained.
  virtual void print_startup(std::FILE* out) const = 0;
};

}  // namespace tissue::service
