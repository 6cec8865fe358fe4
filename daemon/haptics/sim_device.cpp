#include "haptics/sim_device.hpp"

#include <algorithm>
#include <cmath>

namespace tissue::haptics {

SimDevice::SimDevice(const config::SimDeviceSpec& spec) : spec_(spec) {
  waypoint_m_.reserve(spec_.waypoints.size());
  waypoint_time_s_.reserve(spec_.waypoints.size());
  for (const config::Waypoint& w : spec_.waypoints) {
    waypoint_m_.emplace_back(w.position_m[0], w.position_m[1], w.position_m[2]);
    waypoint_time_s_.push_back(w.time_s);
  }
  if (!waypoint_m_.empty()) position_m_ = waypoint_m_.front();
}

bool SimDevice::start(std::string* error) {
  auto fail = [&](const std::string& why) {
    if (error) *error = "sim device: " + why;
    return false;
  };
  if (waypoint_m_.empty()) return fail("needs at least one waypoint");
  for (std::size_t i = 0; i < waypoint_m_.size(); ++i) {
    if (!waypoint_m_[i].allFinite() || !std::isfinite(waypoint_time_s_[i]))
      return fail("waypoint " + std::to_string(i) + " is not finite");
    if (i > 0 && waypoint_time_s_[i] < waypoint_time_s_[i - 1])
      return fail("waypoint times must not decrease (waypoint " + std::to_string(i) + ")");
  }
  if (spec_.mode == config::SimDeviceSpec::Mode::kHand &&
      !(spec_.hand_mass_kg > 0.0 && spec_.hand_stiffness_N_per_m >= 0.0 && spec_.hand_damping_N_s_per_m >= 0.0 &&
        std::isfinite(spec_.hand_mass_kg) && std::isfinite(spec_.hand_stiffness_N_per_m) &&
        std::isfinite(spec_.hand_damping_N_s_per_m)))
    return fail("hand mass must be > 0, stiffness and damping >= 0 and finite");
  if (spec_.mode == config::SimDeviceSpec::Mode::kHand &&
      !(spec_.hand_stability_index() <= config::SimDeviceSpec::kMaxHandStabilityIndex))
    return fail("hand mass " + std::to_string(spec_.hand_mass_kg) + " kg is too light for its stiffness and damping (" +
                "the 0.5 ms sub-steps need at least " + std::to_string(spec_.min_hand_mass_kg()) + " kg)");
  started_clock_ = false;
  timeline_start_s_ = 0.0;
  position_m_ = waypoint_m_.front();
  velocity_m_per_s_.setZero();
  force_N_.setZero();
  return true;
}

void SimDevice::start_timeline_at(double t_s) noexcept {
  if (waypoint_m_.empty() || !std::isfinite(t_s)) return;
  timeline_start_s_ = t_s;
  position_m_ = target_m(t_s);
  velocity_m_per_s_ = spec_.mode == config::SimDeviceSpec::Mode::kHand ? target_velocity_m_per_s(t_s) : Vec3::Zero();
}

double SimDevice::timeline_time_s(double t_s) const noexcept {
  const double t_first = waypoint_time_s_.front();
  const double t_last = waypoint_time_s_.back();
  const double span_s = t_last - t_first;
  if (spec_.loop && span_s > 0.0 && t_s > t_last) return t_first + std::fmod(t_s - t_first, span_s);
  return t_s;
}

int SimDevice::segment_index(double tl_s) const noexcept {
  // Index i such that time[i] <= tl < time[i+1]; waypoint lists are short.
  const auto it = std::upper_bound(waypoint_time_s_.begin(), waypoint_time_s_.end(), tl_s);
  return static_cast<int>(it - waypoint_time_s_.begin()) - 1;
}

Vec3 SimDevice::target_m(double t_s) const noexcept {
  if (waypoint_m_.empty()) return Vec3::Zero();
  const double tl = timeline_time_s(t_s);
  const int i = segment_index(tl);
  if (i < 0) return waypoint_m_.front();
  if (i + 1 >= static_cast<int>(waypoint_m_.size())) return waypoint_m_.back();
  const double span = waypoint_time_s_[i + 1] - waypoint_time_s_[i];
  const double a = span > 0.0 ? (tl - waypoint_time_s_[i]) / span : 1.0;
  return waypoint_m_[i] + a * (waypoint_m_[i + 1] - waypoint_m_[i]);
}

Vec3 SimDevice::target_velocity_m_per_s(double t_s) const noexcept {
  if (waypoint_m_.size() < 2) return Vec3::Zero();
  const double tl = timeline_time_s(t_s);
  const int i = segment_index(tl);
  if (i < 0 || i + 1 >= static_cast<int>(waypoint_m_.size())) return Vec3::Zero();
  const double span = waypoint_time_s_[i + 1] - waypoint_time_s_[i];
  if (span <= 0.0) return Vec3::Zero();
  return (waypoint_m_[i + 1] - waypoint_m_[i]) / span;
}

int SimDevice::hand_substeps(double elapsed_s, double* h_s) noexcept {
  // Clamped as a double: a long gap (a caller that read days ago) would
  // overflow the conversion to int.
  const int substeps = static_cast<int>(std::min<double>(kMaxSubsteps, std::ceil(elapsed_s / kMaxSubstep_s)));
  *h_s = substeps > 0 ? std::min(kMaxSubstep_s, elapsed_s / substeps) : 0.0;
  return std::max(substeps, 0);
}

void SimDevice::hand_substep(const config::SimDeviceSpec& spec, const Vec3& target_m,
                             const Vec3& target_velocity_m_per_s, const Vec3& force_N, double h_s, Vec3* position_m,
                             Vec3* velocity_m_per_s) noexcept {
  // The hand's muscles track the target (spring) and its motion (damper on
  // the velocity error); the rendered force pushes back.
  const Vec3 hand_force_N = spec.hand_stiffness_N_per_m * (target_m - *position_m) +
                            spec.hand_damping_N_s_per_m * (target_velocity_m_per_s - *velocity_m_per_s) + force_N;
  *velocity_m_per_s += (h_s / spec.hand_mass_kg) * hand_force_N;
  *position_m += h_s * *velocity_m_per_s;
}

bool SimDevice::read(std::int64_t now_ns, DeviceSample* out) noexcept {
  if (waypoint_m_.empty()) return false;
  if (!started_clock_) {
    started_clock_ = true;
    t0_ns_ = now_ns;
    last_ns_ = now_ns;
  }
  const double t_s = timeline_start_s_ + 1e-9 * static_cast<double>(now_ns - t0_ns_);
  if (spec_.mode == config::SimDeviceSpec::Mode::kTrajectory) {
    position_m_ = target_m(t_s);
    velocity_m_per_s_ = target_velocity_m_per_s(t_s);
  } else {
    const double remaining_s = 1e-9 * static_cast<double>(std::max<std::int64_t>(0, now_ns - last_ns_));
    double h_s = 0.0;
    const int substeps = hand_substeps(remaining_s, &h_s);
    const double t_begin_s = t_s - h_s * substeps;
    for (int k = 0; k < substeps; ++k) {
      const double t_k_s = t_begin_s + (k + 1) * h_s;
      hand_substep(spec_, target_m(t_k_s), target_velocity_m_per_s(t_k_s), force_N_, h_s, &position_m_,
                   &velocity_m_per_s_);
    }
  }
  last_ns_ = now_ns;
  out->position_m = position_m_;
  out->velocity_m_per_s = velocity_m_per_s_;
  return true;
}

void SimDevice::write(std::int64_t, const Vec3& force_N) noexcept {
  // The loop only writes finite forces; a direct caller gets the same guard.
  force_N_ = force_N.allFinite() ? force_N : Vec3::Zero();
}

}  // namespace tissue::haptics
