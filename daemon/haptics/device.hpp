// Device: what the 1 kHz loop talks to (simulated hand, UDP bridge, vendor SDK,
// a recorded session's hand played back).
//
// start()/stop() may allocate, load libraries and do I/O; they run outside the
// real-time loop. read()/write() run inside HapticLoop::tick() and must not
// allocate, lock or block: they are noexcept and return quickly with what they
// have. Positions, velocities and forces are in the DEVICE frame (HapticLoop
// applies the FrameTransform).
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "config/daemon_config.hpp"
#include "haptics/local_model.hpp"

namespace tissue::haptics {

struct DeviceSample {
  Vec3 position_m = Vec3::Zero();
  Vec3 velocity_m_per_s = Vec3::Zero();
};

class Device {
 public:
  virtual ~Device() = default;

  // Prepares the device. False with a message naming what is missing.
  virtual bool start(std::string* error) = 0;
  virtual void stop() noexcept = 0;

  // The newest pose at now_ns (steady_clock). False when no new sample has
  // come since the last read (the loop counts it and holds the last good
  // one): a held pose handed back as new would defeat the loop's speed check
  // and its device_timeout_s.
  virtual bool read(std::int64_t now_ns, DeviceSample* out) noexcept = 0;
  // The force to render until the next write (device frame, already safe).
  virtual void write(std::int64_t now_ns, const Vec3& force_N) noexcept = 0;

  virtual const char* name() const noexcept = 0;
};

// Builds the device a DeviceSpec asks for (not started). kNone: returns
// nullptr with an empty error (no device, no haptic thread). Unsupported
// kinds: nullptr and *error says why.
std::unique_ptr<Device> make_device(const config::DeviceSpec& spec, std::string* error);

}  // namespace tissue::haptics
