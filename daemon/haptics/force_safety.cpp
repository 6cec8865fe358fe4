#include "haptics/force_safety.hpp"

#include <algorithm>
#include <cmath>

namespace tissue::haptics {

ForceSafety::ForceSafety(const config::ForceLimits& limits) : limits_(limits) {}

void ForceSafety::reset() noexcept {
  scale_ = 0.0;
  output_N_.setZero();
  held_desired_N_.setZero();
  faults_ = kFaultNone;
}

std::uint64_t ForceSafety::total_trips() const noexcept {
  std::uint64_t sum = 0;
  for (std::uint64_t t : trips_) sum += t;
  return sum;
}

Vec3 ForceSafety::apply(const Vec3& desired_N, double dt_s, unsigned faults) noexcept {
  // A bad clock must not open the rate limit: no time, no change.
  if (!(std::isfinite(dt_s) && dt_s > 0.0)) dt_s = 0.0;
  if (desired_N.allFinite()) {
    held_desired_N_ = desired_N;
  } else {
    ++nonfinite_inputs_;
    faults |= kFaultNonFinite;
  }
  for (int bit = 0; bit < kSafetyFaultKinds; ++bit)
    if ((faults & (1u << bit)) && !(faults_ & (1u << bit))) ++trips_[bit];
  faults_ = faults;

  if (faults != kFaultNone)
    scale_ = limits_.ramp_out_s > 0.0 ? std::max(0.0, scale_ - dt_s / limits_.ramp_out_s) : 0.0;
  else
    scale_ = limits_.ramp_in_s > 0.0 ? std::min(1.0, scale_ + dt_s / limits_.ramp_in_s) : 1.0;

  // Clamp first, then scale: scaling first would let a desired force far
  // above the limit (a device that comes back deep inside the object asks
  // for hundreds of newtons) reach max_force_N at a scale of a few percent,
  // and the ramp-in would be no ramp at all.
  Vec3 target_N = held_desired_N_;
  const double max_force_N = std::max(0.0, limits_.max_force_N);
  const double magnitude_N = target_N.norm();
  if (magnitude_N > max_force_N) target_N *= max_force_N / magnitude_N;
  target_N *= scale_;

  Vec3 step_N = target_N - output_N_;
  const double max_step_N = std::max(0.0, limits_.max_force_rate_N_per_s) * dt_s;
  const double step_magnitude_N = step_N.norm();
  if (step_magnitude_N > max_step_N) step_N *= max_step_N / step_magnitude_N;
  output_N_ += step_N;
  if (!output_N_.allFinite()) output_N_.setZero();  // unreachable by construction; never let NaN out
  return output_N_;
}

}  // namespace tissue::haptics
