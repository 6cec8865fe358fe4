// ReplayDevice: the device positions of a recorded session, played back on
// the steady clock (issue 6): a lab reruns a user's motion against a changed
// scene, or checks that the daemon reproduces a session's forces.
//
// The track is given in memory (the service reads it from the session file
// with record::read_haptic_track before the loop starts), so read() and
// write() only interpolate and never allocate, lock or block. Positions are
// in the device frame: a session records them in the scene frame, and the
// service maps them back with the config's device.offset_m and scale
// (HapticSideImpl), so the hand retraces the recorded path whatever those are.
#pragma once

#include <limits>
#include <vector>

#include "haptics/device.hpp"

namespace tissue::haptics {

class ReplayDevice final : public Device {
 public:
  // time_s non-decreasing, the same length as position_m, at least one row.
  // max_speed_m_per_s: device.limits.max_speed_m_per_s (device frame, as
  // position_m): start() refuses a speed that plays the track faster.
  ReplayDevice(std::vector<double> time_s, std::vector<Vec3> position_m, double speed, bool loop,
               double max_speed_m_per_s = std::numeric_limits<double>::infinity());

  bool start(std::string* error) override;
  void stop() noexcept override {}
  // The position at (now - first read) * speed into the track: linear between
  // rows, held at the end (or wrapped when looping). Velocity by the slope.
  bool read(std::int64_t now_ns, DeviceSample* out) noexcept override;
  void write(std::int64_t /*now_ns*/, const Vec3& force_N) noexcept override { last_force_N_ = force_N; }
  const char* name() const noexcept override { return "replay"; }

  double duration_s() const noexcept { return time_s_.back() - time_s_.front(); }
  const Vec3& last_force_N() const noexcept { return last_force_N_; }

 private:
  std::vector<double> time_s_;
  std::vector<Vec3> position_m_;
  double speed_;
  bool loop_;
  double max_speed_m_per_s_;
  std::int64_t start_ns_ = -1;
  std::size_t cursor_ = 0;  // row at or before the last time read (monotone search)
  Vec3 last_force_N_ = Vec3::Zero();
};

}  // namespace tissue::haptics
