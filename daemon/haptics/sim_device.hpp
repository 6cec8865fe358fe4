// SimDevice: the simulated device of SimDeviceSpec.
//
// kTrajectory: the tip follows the waypoint timeline exactly (piecewise
//   linear; the velocity is the segment slope). Rendered forces are ignored,
//   like a position-controlled robot holding the stylus.
// kHand: a point mass (the user's hand) is pulled towards the waypoint target
//   by a spring-damper and pushed by the rendered force, integrated on every
//   read() with semi-implicit Euler in sub-steps of at most kMaxSubstep_s, so
//   the whole force path (render -> safety -> device -> motion) is exercised
//   and the "user" yields when the object pushes back.
// The timeline starts at the first read() after start() (t = 0 there).
#pragma once

#include <vector>

#include "config/daemon_config.hpp"
#include "haptics/device.hpp"

namespace tissue::haptics {

class SimDevice final : public Device {
 public:
  // Stability of the hand integration: the stiffest loop is hand spring +
  // coupling (~1 kN/m on 0.1 kg, omega ~ 100 rad/s); 0.5 ms keeps omega*dt
  // small. start() refuses a hand too light for its spring and damper at this
  // step (config::SimDeviceSpec::hand_stability_index).
  static constexpr double kMaxSubstep_s = config::SimDeviceSpec::kHandSubstep_s;
  // A stalled caller must not make read() do unbounded work.
  static constexpr int kMaxSubsteps = 64;

  explicit SimDevice(const config::SimDeviceSpec& spec);

  bool start(std::string* error) override;
  void stop() noexcept override {}
  bool read(std::int64_t now_ns, DeviceSample* out) noexcept override;
  void write(std::int64_t now_ns, const Vec3& force_N) noexcept override;
  const char* name() const noexcept override { return "sim"; }

  // Start-time checks (sim_loop_wrap_warning) that cannot afford to simulate
  // a long track from its start: the timeline begins at t_s instead of 0 (the
  // first read() is at t_s), the hand on the target there and moving with it,
  // which is where a hand that has followed a straight segment long enough
  // has settled. Call after start() and before the first read().
  void start_timeline_at(double t_s) noexcept;

  // The waypoint target at t seconds since the timeline started.
  Vec3 target_m(double t_s) const noexcept;
  // The slope of the timeline at t (zero past the end of a non-looping one).
  Vec3 target_velocity_m_per_s(double t_s) const noexcept;
  // The sub-steps a read() integrates over elapsed_s since the last: their
  // count (at most kMaxSubsteps) and length (at most kMaxSubstep_s) in *h_s.
  // A read after a longer gap integrates only kMaxSubsteps * kMaxSubstep_s
  // of hand time (below about 31 Hz, every read).
  static int hand_substeps(double elapsed_s, double* h_s) noexcept;

  // Hand state (kHand) or trajectory point at the last read().
  const Vec3& position_m() const noexcept { return position_m_; }
  const Vec3& velocity_m_per_s() const noexcept { return velocity_m_per_s_; }

 private:
  // One semi-implicit Euler sub-step of the hand of `spec`.
  static void hand_substep(const config::SimDeviceSpec& spec, const Vec3& target_m, const Vec3& target_velocity_m_per_s,
                           const Vec3& force_N, double h_s, Vec3* position_m, Vec3* velocity_m_per_s) noexcept;
  double timeline_time_s(double t_s) const noexcept;
  int segment_index(double tl_s) const noexcept;

  config::SimDeviceSpec spec_;
  std::vector<Vec3> waypoint_m_;
  std::vector<double> waypoint_time_s_;
  bool started_clock_ = false;
  std::int64_t t0_ns_ = 0;
  std::int64_t last_ns_ = 0;
  double timeline_start_s_ = 0.0;  // timeline time of the first read (start_timeline_at)
  Vec3 position_m_ = Vec3::Zero();
  Vec3 velocity_m_per_s_ = Vec3::Zero();
  Vec3 force_N_ = Vec3::Zero();  // last rendered force, acts on the hand
};

}  // namespace tissue::haptics
