// The daemon config's haptic keys at the extremes the loader accepts: each
// key set alone to the largest, the smallest and 0 (and past 64 bits), and
// every copy the loader takes drives the real haptic loop through a press, a
// fast swing through the surface and a release. What the loader accepts the
// loop must render: finite forces within max_force_N, no non-finite force
// caught by the safety layer (that would be a NaN the config let in). A value
// the loop cannot render must be refused by the loader, naming its key.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "config/daemon_config_yaml.hpp"
#include "haptics/haptic_loop.hpp"
#include "haptics/haptics_test_support.hpp"

namespace tissue::config {
namespace {

using haptics::Vec3;
using haptics::test::kMs;

// The shipped limits and coupling; a scripted device, so no sim section is
// exercised here (sim_device's own extremes are its tests').
const std::string kConfig = R"(scene: scenes/cantilever.yaml
device:
  kind: udp
  offset_m: [0, 0, 0]
  scale: 1
  limits:
    max_force_N: 3.0
    max_force_rate_N_per_s: 300
    max_stiffness_N_per_m: 1000
    ramp_in_s: 0.5
    ramp_out_s: 0.05
    stale_model_s: 0.1
    device_timeout_s: 0.01
    max_speed_m_per_s: 5
    workspace_radius_m: 1
haptics:
  rate_hz: 1000
  coupling_stiffness_N_per_m: 400
  coupling_damping_N_s_per_m: 1
  crossfade_s: 0.01
)";

struct Rendered {
  int ticks = 0;
  int nonfinite_written = 0;
  double peak_N = 0.0;
  std::uint64_t nonfinite_forces = 0;  // caught by the safety layer
};

// 3 s at the config's rate against a flat patch at z = 0 (stiffness 600 N/m,
// a model every tick): 1 s above it, 1 s pressed 2 mm in, then a swing of
// 20 mm amplitude at 5 Hz through it (0.63 m/s peak, under every accepted
// max_speed_m_per_s above 1 m/s), either in the scene frame (mapped to the
// device frame through the config's offset_m and scale: a hand that reaches
// the patch) or in the device frame (what a hand inside the workspace gives
// whatever the mapping: positions far out in the scene).
Rendered render(const DaemonConfig& c, bool scene_frame) {
  haptics::test::ScriptedDevice device;
  auto models = std::make_unique<haptics::LocalModelBuffer>();
  auto samples = std::make_unique<haptics::ToolSampleRing>();
  haptics::HapticLoop loop(device, c.device, c.haptics, *models, *samples);
  haptics::LocalModel model = haptics::test::make_flat_patch(0.1, 4);
  haptics::test::set_linear_contact(model, 600.0);
  const Vec3 offset_m(c.device.offset_m[0], c.device.offset_m[1], c.device.offset_m[2]);
  const auto to_device = [&](const Vec3& scene_m) { return Vec3((scene_m - offset_m) / c.device.scale); };
  const double dt_s = 1.0 / c.haptics.rate_hz;
  const auto period_ns = static_cast<std::int64_t>(std::llround(1e9 * dt_s));
  std::int64_t now_ns = 1000 * kMs;
  Rendered r;
  const int ticks = static_cast<int>(3.0 * c.haptics.rate_hz);
  for (int i = 0; i < ticks; ++i) {
    const double t_s = i * dt_s;
    Vec3 scene_m(0, 0, 0.01), velocity_m_per_s = Vec3::Zero();
    if (t_s >= 1.0 && t_s < 2.0) scene_m.z() = -0.002;
    if (t_s >= 2.0) {
      const double w = 2.0 * M_PI * 5.0;
      scene_m.z() = 0.02 * std::sin(w * (t_s - 2.0));
      velocity_m_per_s.z() = 0.02 * w * std::cos(w * (t_s - 2.0));
    }
    device.position_m = scene_frame ? to_device(scene_m) : scene_m;
    device.velocity_m_per_s = scene_frame ? Vec3(velocity_m_per_s / c.device.scale) : velocity_m_per_s;
    model.version = static_cast<std::uint64_t>(i + 1);
    model.built_ns = now_ns;
    models->write(model);
    now_ns += period_ns;
    loop.tick(now_ns);
    ++r.ticks;
    if (!device.last_force_N.allFinite())
      ++r.nonfinite_written;
    else
      r.peak_N = std::max(r.peak_N, device.last_force_N.norm());
    haptics::ToolSample s;
    while (samples->try_pop(s)) {
    }
  }
  r.nonfinite_forces = loop.stats().nonfinite_forces;
  return r;
}

TEST(DaemonConfigHapticExtremes, EveryAcceptedExtremeRendersFiniteForcesWithinTheLimit) {
  const std::vector<std::string> keys = {
      "device.limits.max_force_N",
      "device.limits.max_force_rate_N_per_s",
      "device.limits.max_stiffness_N_per_m",
      "device.limits.ramp_in_s",
      "device.limits.ramp_out_s",
      "device.limits.stale_model_s",
      "device.limits.device_timeout_s",
      "device.limits.max_speed_m_per_s",
      "device.limits.workspace_radius_m",
      "device.offset_m[0]",
      "device.offset_m[2]",
      "device.scale",
      "haptics.rate_hz",
      "haptics.coupling_stiffness_N_per_m",
      "haptics.coupling_damping_N_s_per_m",
      "haptics.crossfade_s",
  };
  const std::vector<std::string> extremes = {"1e308", "1.8e19", "1e9", "1e4", "1", "1e-9", "5e-324", "0", "-1e308"};
  // The harness renders contact at all: the base config presses 2 mm into
  // the 600 N/m patch and swings through it (a regression that rendered no
  // force would pass every check below).
  const Rendered base = render(parse_daemon_config(kConfig, "extremes.yaml"), true);
  EXPECT_GT(base.peak_N, 0.5);
  EXPECT_EQ(base.nonfinite_written, 0);
  int accepted = 0, refused = 0;
  for (const std::string& key : keys) {
    for (const std::string& value : extremes) {
      const std::string override = key + "=" + value;
      DaemonConfig c;
      try {
        c = parse_daemon_config(kConfig, "extremes.yaml", {override});
      } catch (const ConfigError& e) {
        EXPECT_NE(std::string(e.what()).find(key.substr(key.rfind('.') + 1, key.find('[') - key.rfind('.') - 1)),
                  std::string::npos)
            << override << ": " << e.what();
        ++refused;
        continue;
      }
      ++accepted;
      for (const bool scene_frame : {true, false}) {
        const Rendered r = render(c, scene_frame);
        const std::string what = override + (scene_frame ? " (scene-frame motion)" : " (device-frame motion)");
        EXPECT_EQ(r.nonfinite_written, 0) << what;
        EXPECT_EQ(r.nonfinite_forces, 0u) << what << ": the safety layer caught non-finite forces";
        EXPECT_LE(r.peak_N, c.device.limits.max_force_N * (1 + 1e-12)) << what;
        std::printf("accepted %s: peak %.3g N\n", what.c_str(), r.peak_N);
      }
    }
  }
  // Both outcomes occur: the sweep reaches past the loader's bounds and
  // inside them.
  EXPECT_GT(accepted, 20);
  EXPECT_GT(refused, 20);
}

}  // namespace
}  // namespace tissue::config
