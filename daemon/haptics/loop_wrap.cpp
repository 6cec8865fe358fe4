#include "haptics/loop_wrap.hpp"

#include <cstdio>

#include "haptics/sim_device.hpp"

namespace tissue::haptics {

std::string loop_wrap_warning(const std::string& key, double jump_m, double max_speed_m_per_s, double rate_hz) {
  const double per_tick_m = max_speed_m_per_s / rate_hz;
  if (!(jump_m > per_tick_m)) return {};
  char text[512];
  std::snprintf(text, sizeof text,
                "%s: the looping track goes from its last point back to its first in one tick, a %.3g m jump "
                "(device frame), more than the %.3g m a tick the haptic loop accepts (device.limits.max_speed_m_per_s "
                "%g at haptics.rate_hz %g): the force ramps out and back in at every wrap (inputs rejected as too "
                "fast, then device lost); end the track where it starts for a seamless loop",
                key.c_str(), jump_m, per_tick_m, max_speed_m_per_s, rate_hz);
  return text;
}

std::string sim_loop_wrap_warning(const config::DeviceSpec& device, double rate_hz) {
  const config::SimDeviceSpec& sim = device.sim;
  if (device.kind != config::DeviceSpec::Kind::kSim || !sim.loop || sim.waypoints.empty()) return {};
  const auto& first = sim.waypoints.front().position_m;
  const auto& last = sim.waypoints.back().position_m;
  const double jump_m = Vec3(last[0] - first[0], last[1] - first[1], last[2] - first[2]).norm();
  if (sim.mode == config::SimDeviceSpec::Mode::kTrajectory)
    return loop_wrap_warning("device.sim.waypoints", jump_m, device.limits.max_speed_m_per_s, rate_hz);
  // mode: hand follows the jumped target through its spring: not in one
  // tick, but a long jump still swings it past the speed the loop accepts.
  const double peak_m_per_s = SimDevice::hand_jump_peak_speed_m_per_s(sim, jump_m, rate_hz);
  const double max_speed_m_per_s = device.limits.max_speed_m_per_s;
  if (!(peak_m_per_s > max_speed_m_per_s)) return {};
  char text[640];
  std::snprintf(text, sizeof text,
                "device.sim.waypoints: the looping track's target goes from its last point back to its first in one "
                "tick, a %.3g m jump (device frame), and the hand (device.sim.mode hand) follows it through its "
                "spring at up to %.3g m/s, more than device.limits.max_speed_m_per_s %g: the force ramps out and "
                "back in at every wrap (inputs rejected as too fast, then device lost); end the track where it "
                "starts for a seamless loop, or keep the jump under %.3g m",
                jump_m, peak_m_per_s, max_speed_m_per_s, jump_m * max_speed_m_per_s / peak_m_per_s);
  return text;
}

}  // namespace tissue::haptics
