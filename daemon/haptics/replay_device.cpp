#include "haptics/replay_device.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>

namespace tissue::haptics {
namespace {

std::string fmt(double v) {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%.4g", v);
  return buffer;
}

}  // namespace

ReplayDevice::ReplayDevice(std::vector<double> time_s, std::vector<Vec3> position_m, double speed, bool loop,
                           double max_speed_m_per_s)
    : time_s_(std::move(time_s)),
      position_m_(std::move(position_m)),
      speed_(speed),
      loop_(loop),
      max_speed_m_per_s_(max_speed_m_per_s) {}

bool ReplayDevice::start(std::string* error) {
  auto fail = [&](const std::string& why) {
    if (error) *error = "replay device: " + why;
    return false;
  };
  if (time_s_.empty() || time_s_.size() != position_m_.size()) return fail("the track is empty or inconsistent");
  if (!(speed_ > 0.0) || !std::isfinite(speed_)) return fail("speed must be a positive number");
  for (std::size_t i = 0; i < time_s_.size(); ++i) {
    if (!std::isfinite(time_s_[i]) || (i > 0 && time_s_[i] < time_s_[i - 1]))
      return fail("track times must be finite and non-decreasing (row " + std::to_string(i) + ")");
    if (!position_m_[i].allFinite()) return fail("non-finite position at row " + std::to_string(i));
  }
  // The loop rejects a sample faster than device.limits.max_speed_m_per_s as
  // a glitch: a replay sped up past it would lose the hand on the track's
  // fast strokes and ramp the force out mid-replay, with no word why.
  // Each step is measured over the time since its position came, as the loop
  // measured it live: a device slower than the loop is recorded as a
  // position held for some rows, then a step (one row's time would make a
  // 250 Hz device look four times as fast as it moved).
  double peak_m_per_s = 0.0;
  double held_since_s = time_s_.front();
  for (std::size_t i = 1; i < time_s_.size(); ++i) {
    if (position_m_[i] == position_m_[i - 1]) continue;
    const double dt_s = time_s_[i] - held_since_s;
    if (dt_s > 0.0) peak_m_per_s = std::max(peak_m_per_s, (position_m_[i] - position_m_[i - 1]).norm() / dt_s);
    held_since_s = time_s_[i];
  }
  if (peak_m_per_s * speed_ > max_speed_m_per_s_)
    return fail("device.replay.speed " + fmt(speed_) + " plays the track at up to " + fmt(peak_m_per_s * speed_) +
                " m/s (its peak " + fmt(peak_m_per_s) + " m/s in the device frame, times the speed), above " +
                "device.limits.max_speed_m_per_s " + fmt(max_speed_m_per_s_) +
                ": the haptic loop would reject the hand as a glitch and ramp the force out; use a speed of at most " +
                fmt(max_speed_m_per_s_ / peak_m_per_s) + " for this track");
  start_ns_ = -1;
  cursor_ = 0;
  return true;
}

bool ReplayDevice::read(std::int64_t now_ns, DeviceSample* out) noexcept {
  if (time_s_.empty()) return false;
  if (start_ns_ < 0) start_ns_ = now_ns;
  double t = time_s_.front() + speed_ * 1e-9 * static_cast<double>(now_ns - start_ns_);
  const double span = duration_s();
  if (loop_ && span > 0.0 && t > time_s_.back()) {
    t = time_s_.front() + std::fmod(t - time_s_.front(), span);
    if (t < time_s_[cursor_]) cursor_ = 0;
  }
  if (t >= time_s_.back()) {
    out->position_m = position_m_.back();
    out->velocity_m_per_s.setZero();
    return true;
  }
  while (cursor_ + 1 < time_s_.size() && time_s_[cursor_ + 1] <= t) ++cursor_;
  const std::size_t i = cursor_, j = std::min(cursor_ + 1, time_s_.size() - 1);
  const double dt = time_s_[j] - time_s_[i];
  const double u = dt > 0.0 ? std::clamp((t - time_s_[i]) / dt, 0.0, 1.0) : 0.0;
  out->position_m = (1.0 - u) * position_m_[i] + u * position_m_[j];
  out->velocity_m_per_s = dt > 0.0 ? Vec3(speed_ * (position_m_[j] - position_m_[i]) / dt) : Vec3::Zero();
  return true;
}

}  // namespace tissue::haptics
