#include "haptics/loop_wrap.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>

#include "haptics/sim_device.hpp"

namespace tissue::haptics {
namespace {

std::string wrap_text(const std::string& key, double jump_m, double max_speed_m_per_s, double rate_hz) {
  char text[512];
  std::snprintf(text, sizeof text,
                "%s: the looping track goes from its last point back to its first in one tick, a %.3g m jump "
                "(device frame), more than the %.3g m a tick the haptic loop accepts (device.limits.max_speed_m_per_s "
                "%g at haptics.rate_hz %g): the force ramps out and back in at every wrap (inputs rejected as too "
                "fast, then device lost); end the track where it starts for a seamless loop",
                key.c_str(), jump_m, max_speed_m_per_s / rate_hz, max_speed_m_per_s, rate_hz);
  return text;
}

}  // namespace

std::string loop_wrap_warning(const std::string& key, double jump_m, double max_speed_m_per_s, double rate_hz,
                              double no_sample_s) {
  if (!(no_sample_s > 0.0)) {
    if (!(jump_m > max_speed_m_per_s / rate_hz)) return {};
    return wrap_text(key, jump_m, max_speed_m_per_s, rate_hz);
  }
  // The loop judges the first sample after the wrap against the last one it
  // accepted before it over the wall time between them: the time without
  // samples, and never less than the tick between two reads.
  const double judged_over_s = std::max(no_sample_s, 1.0 / rate_hz);
  if (!(jump_m > max_speed_m_per_s * judged_over_s)) return {};
  char text[768];
  std::snprintf(text, sizeof text,
                "%s: the looping track goes from its last sample back to its first through %.3g s (wall time) "
                "without samples, a %.3g m jump (device frame) the haptic loop judges over that time: %.3g m/s, "
                "more than device.limits.max_speed_m_per_s %g: it rejects the samples after every wrap as too fast "
                "until %.3g s after the last one it accepted, so the force stays out (device lost) that much longer "
                "at every wrap; end the track where it starts for a seamless loop",
                key.c_str(), no_sample_s, jump_m, jump_m / judged_over_s, max_speed_m_per_s,
                jump_m / max_speed_m_per_s);
  return text;
}

SimLoopPlan plan_sim_loop_check(double first_s, double last_s, double rate_hz, bool hand, double max_substeps) {
  SimLoopPlan plan;
  const double span_s = last_s - first_s;
  if (!(span_s > 0.0) || !std::isfinite(span_s) || !std::isfinite(last_s) || !(rate_hz > 0.0) ||
      !std::isfinite(rate_hz) || !(max_substeps > 0.0) || !std::isfinite(max_substeps))
    return plan;
  double h_s = 0.0;
  const double cost_per_read = hand ? std::max(1, SimDevice::hand_substeps(1.0 / rate_hz, &h_s)) : 1;
  const double budget_reads = std::max(2.0, std::floor(max_substeps / cost_per_read));
  const double wanted_reads = std::ceil((last_s + kSimLoopWrapsChecked * span_s) * rate_hz) + 1.0;
  if (wanted_reads <= budget_reads || std::ceil((last_s + kSimLoopWrapLeadIn_s) * rate_hz) + 1.0 <= budget_reads) {
    // One run from the start reaches the first wrap and a lead-in past it.
    plan.first_pass.reads = static_cast<std::int64_t>(std::min(wanted_reads, budget_reads));
    return plan;
  }
  const double wrap_reads = std::floor(0.5 * budget_reads);
  const double lead_in_reads = std::min(std::round(kSimLoopWrapLeadIn_s * rate_hz), std::floor(0.5 * wrap_reads));
  plan.wrap.first_read = static_cast<std::int64_t>(std::max(0.0, std::floor(last_s * rate_hz) - lead_in_reads));
  plan.wrap.reads =
      static_cast<std::int64_t>(std::min(wrap_reads, wanted_reads - static_cast<double>(plan.wrap.first_read)));
  plan.first_pass.reads = static_cast<std::int64_t>(
      std::min(budget_reads - static_cast<double>(plan.wrap.reads), static_cast<double>(plan.wrap.first_read)));
  return plan;
}

std::optional<SimLoopJudged> judge_sim_loop_window(const config::DeviceSpec& device, double rate_hz,
                                                   const SimLoopWindow& window, const SimLoopJudged& earlier) {
  const config::SimDeviceSpec& sim = device.sim;
  if (sim.waypoints.size() < 2 || !(rate_hz > 0.0) || !std::isfinite(rate_hz)) return std::nullopt;
  const double last_s = sim.waypoints.back().time_s;
  const double span_s = last_s - sim.waypoints.front().time_s;
  const config::ForceLimits& limits = device.limits;
  SimDevice copy(sim);
  if (!copy.start(nullptr)) return std::nullopt;
  const double start_s = static_cast<double>(window.first_read) / rate_hz;
  if (window.first_read > 0) copy.start_timeline_at(start_s);
  SimLoopJudged judged = earlier;
  // The loop's first sample of the window has nothing to be judged against,
  // as the loop's own first sample.
  DeviceSample last_accepted;
  bool have_accepted = false;
  std::int64_t last_accepted_ns = 0;
  for (std::int64_t k = 0; k < window.reads; ++k) {
    const std::int64_t now_ns = std::llround(static_cast<double>(k) * 1e9 / rate_hz);
    const double t_s = start_s + 1e-9 * static_cast<double>(now_ns);  // as SimDevice::read counts it
    DeviceSample s;
    if (!copy.read(now_ns, &s)) return std::nullopt;
    const double since_s = have_accepted ? 1e-9 * static_cast<double>(now_ns - last_accepted_ns) : 0.0;
    const SampleVerdict verdict = judge_device_sample(limits, s, have_accepted ? &last_accepted : nullptr, since_s);
    if (t_s > last_s) {
      double speed_m_per_s = s.velocity_m_per_s.norm();
      if (have_accepted && since_s > 0.0)
        speed_m_per_s = std::max(speed_m_per_s, (s.position_m - last_accepted.position_m).norm() / since_s);
      judged.peak_m_per_s = std::max(judged.peak_m_per_s, speed_m_per_s);
      judged.farthest_m = std::max(judged.farthest_m, s.position_m.norm());
    }
    if (verdict == SampleVerdict::kAccepted) {
      last_accepted = s;
      have_accepted = true;
      last_accepted_ns = now_ns;
    } else if (!judged.rejected) {
      judged.rejected = true;
      judged.first_rejected_s = t_s;
      judged.first_verdict = verdict;
      judged.first_step_m = have_accepted ? (s.position_m - last_accepted.position_m).norm() : 0.0;
    }
    judged.checked_s = t_s;
  }
  // Wraps at last_s + j * span_s before the last read (less a rounding).
  judged.wraps = span_s > 0.0 && judged.checked_s > last_s
                     ? static_cast<int>(std::ceil((judged.checked_s - last_s) / span_s - 1e-9))
                     : 0;
  return judged;
}

std::string sim_loop_wrap_message(const config::DeviceSpec& device, double rate_hz, const SimLoopPlan& plan,
                                  double first_pass_checked_s, const SimLoopJudged& judged) {
  const config::SimDeviceSpec& sim = device.sim;
  if (!judged.rejected || sim.waypoints.empty()) return {};
  const bool hand = sim.mode == config::SimDeviceSpec::Mode::kHand;
  const double last_s = sim.waypoints.back().time_s;
  const char* const what = hand ? "hand (device.sim.mode hand)" : "tip (device.sim.mode trajectory)";
  char text[1024];
  const config::ForceLimits& limits = device.limits;
  const double max_speed_m_per_s = limits.max_speed_m_per_s;
  if (judged.first_rejected_s <= last_s) {
    // Not the wrap: the track itself, and so on every pass.
    std::snprintf(text, sizeof text,
                  "device.sim.waypoints: the simulated %s is rejected by the haptic loop %.3g s into the track's "
                  "first pass, before it wraps (%s): the force ramps out and back in on every pass",
                  what, judged.first_rejected_s,
                  judged.first_verdict == SampleVerdict::kOutsideWorkspace ? "outside device.limits.workspace_radius_m"
                  : judged.first_verdict == SampleVerdict::kTooFast ? "faster than device.limits.max_speed_m_per_s"
                                                                    : "not finite");
    return text;
  }
  if (!hand) return wrap_text("device.sim.waypoints", judged.first_step_m, max_speed_m_per_s, rate_hz);
  const auto& first = sim.waypoints.front().position_m;
  const auto& last = sim.waypoints.back().position_m;
  const double jump_m = Vec3(last[0] - first[0], last[1] - first[1], last[2] - first[2]).norm();
  char checked[512];
  if (plan.wrap.reads == 0)
    std::snprintf(checked, sizeof checked,
                  " (checked at start: the hand simulated with no rendered force, read at haptics.rate_hz %g over the "
                  "first %.3g s, the first pass and %d wrap%s)",
                  rate_hz, judged.checked_s, judged.wraps, judged.wraps == 1 ? "" : "s");
  else
    std::snprintf(checked, sizeof checked,
                  " (checked at start: the hand simulated with no rendered force, read at haptics.rate_hz %g over the "
                  "first %.3g s of the first pass, then from %.3g s (started there on the track, at its velocity) to "
                  "%.3g s, %d wrap%s; the whole run would take more than the check's 10^6 hand sub-steps)",
                  rate_hz, first_pass_checked_s, static_cast<double>(plan.wrap.first_read) / rate_hz, judged.checked_s,
                  judged.wraps, judged.wraps == 1 ? "" : "s");
  if (judged.first_verdict == SampleVerdict::kOutsideWorkspace) {
    std::snprintf(text, sizeof text,
                  "device.sim.waypoints: the looping track's target goes from its last point back to its first in one "
                  "tick, a %.3g m jump (device frame), and the hand (device.sim.mode hand) follows it through its "
                  "spring out to %.3g m from the device origin, beyond device.limits.workspace_radius_m %g: the force "
                  "ramps out and back in at every wrap (inputs rejected outside the workspace, then device lost); end "
                  "the track where it starts for a seamless loop%s",
                  jump_m, judged.farthest_m, limits.workspace_radius_m, checked);
    return text;
  }
  std::snprintf(text, sizeof text,
                "device.sim.waypoints: the looping track's target goes from its last point back to its first in one "
                "tick, a %.3g m jump (device frame), and the hand (device.sim.mode hand) follows it through its "
                "spring at up to %.3g m/s, more than device.limits.max_speed_m_per_s %g: the force ramps out and "
                "back in at every wrap (inputs rejected as too fast, then device lost); end the track where it "
                "starts for a seamless loop%s",
                jump_m, judged.peak_m_per_s, max_speed_m_per_s, checked);
  return text;
}

std::string sim_loop_wrap_warning(const config::DeviceSpec& device, double rate_hz) {
  const config::SimDeviceSpec& sim = device.sim;
  if (device.kind != config::DeviceSpec::Kind::kSim || !sim.loop || sim.waypoints.size() < 2) return {};
  const SimLoopPlan plan = plan_sim_loop_check(sim.waypoints.front().time_s, sim.waypoints.back().time_s, rate_hz,
                                               sim.mode == config::SimDeviceSpec::Mode::kHand);
  if (plan.first_pass.reads == 0 && plan.wrap.reads == 0) return {};
  {
    SimDevice probe(sim);
    if (!probe.start(nullptr)) return {};  // start() itself says why, when the device starts
  }
  // The first pass first: a rejection there is the earliest, the track's own.
  const std::optional<SimLoopJudged> first_pass = judge_sim_loop_window(device, rate_hz, plan.first_pass);
  if (!first_pass) return {};
  std::optional<SimLoopJudged> judged = first_pass;
  if (plan.wrap.reads > 0) judged = judge_sim_loop_window(device, rate_hz, plan.wrap, *first_pass);
  if (!judged) return {};
  return sim_loop_wrap_message(device, rate_hz, plan, first_pass->checked_s, *judged);
}

}  // namespace tissue::haptics
