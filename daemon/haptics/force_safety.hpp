// ForceSafety: the last stage before the device, applied on every tick.
//
//   1. Non-finite desired force: counted, treated as a fault for that tick,
//      and replaced by the last finite one (so the ramp-out has a direction).
//   2. Scale s in [0, 1]: rises at 1/ramp_in_s while no fault is present
//      (ramp-in after start or after a fault clears), falls at 1/ramp_out_s
//      while any fault is present (stale model, lost device, stop, watchdog,
//      non-finite force). Faults never step the force to zero; they ramp it.
//   3. The output aims at s * F', F' = F clamped to max_force_N: the clamp
//      comes before the scale, so a ramp is a ramp whatever F asks for.
//   4. The change per tick is clamped to max_force_rate_N_per_s * dt (vector
//      norm), so no cause whatsoever produces a step above the rate limit.
// The output is always finite and within max_force_N (the rate-limited point
// lies on a segment between two points of the max-force ball).
#pragma once

#include <cstdint>

#include "config/daemon_config.hpp"
#include "haptics/local_model.hpp"

namespace tissue::haptics {

enum SafetyFault : unsigned {
  kFaultNone = 0,
  kFaultStaleModel = 1u << 0,
  kFaultDeviceLost = 1u << 1,
  kFaultStop = 1u << 2,
  kFaultWatchdog = 1u << 3,
  kFaultNonFinite = 1u << 4,
};
inline constexpr int kSafetyFaultKinds = 5;

class ForceSafety {
 public:
  explicit ForceSafety(const config::ForceLimits& limits);

  // Scale 0, output 0: the next forces ramp in again.
  void reset() noexcept;
  // One tick: dt_s since the previous call, faults a SafetyFault mask.
  Vec3 apply(const Vec3& desired_N, double dt_s, unsigned faults) noexcept;

  const Vec3& output_N() const noexcept { return output_N_; }
  double scale() const noexcept { return scale_; }
  // Scale and output both zero: safe to stop writing.
  bool quiescent() const noexcept { return scale_ == 0.0 && output_N_.isZero(0.0); }
  // Rising edges of each fault kind (index = bit position) and in total.
  std::uint64_t trips(int fault_bit) const noexcept { return trips_[fault_bit]; }
  std::uint64_t total_trips() const noexcept;
  std::uint64_t nonfinite_inputs() const noexcept { return nonfinite_inputs_; }

 private:
  config::ForceLimits limits_;
  double scale_ = 0.0;
  Vec3 output_N_ = Vec3::Zero();
  Vec3 held_desired_N_ = Vec3::Zero();
  unsigned faults_ = kFaultNone;
  std::uint64_t trips_[kSafetyFaultKinds] = {};
  std::uint64_t nonfinite_inputs_ = 0;
};

}  // namespace tissue::haptics
