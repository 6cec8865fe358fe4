#include "haptics/loop_wrap.hpp"

#include <gtest/gtest.h>

#include <memory>

#include "haptics/haptic_loop.hpp"
#include "haptics/haptics_test_support.hpp"
#include "haptics/sim_device.hpp"

namespace tissue::haptics {
namespace {

// A looping track jumps from its last point to its first in one tick: longer
// than max_speed_m_per_s / rate_hz, the loop rejects the jump and the force
// ramps out at each wrap. Said once at start, naming the key and the numbers.
TEST(LoopWrap, AWrapLongerThanATickAllowsIsAWarningNamingTheKeyAndTheNumbers) {
  // 5 m/s at 1 kHz: 5 mm a tick. The review's 0.3 m wrap.
  const std::string w = loop_wrap_warning("device.replay.loop", 0.3, 5.0, 1000.0);
  EXPECT_EQ(w.rfind("device.replay.loop: the looping track goes from its last point back to its first in one tick, "
                    "a 0.3 m jump (device frame), more than the 0.005 m a tick the haptic loop accepts "
                    "(device.limits.max_speed_m_per_s 5 at haptics.rate_hz 1000): the force ramps out and back in "
                    "at every wrap",
                    0),
            0u)
      << w;
  EXPECT_NE(loop_wrap_warning("device.sim.waypoints", 0.006, 5.0, 1000.0).find("device.sim.waypoints: "),
            std::string::npos);
}

TEST(LoopWrap, AWrapWithinATickIsNoWarning) {
  EXPECT_EQ(loop_wrap_warning("device.replay.loop", 0.0, 5.0, 1000.0), "");  // ends where it starts
  EXPECT_EQ(loop_wrap_warning("device.replay.loop", 0.005, 5.0, 1000.0), "");
  EXPECT_EQ(loop_wrap_warning("device.sim.waypoints", 0.3, 5.0, 10.0), "");  // 0.5 m a tick at 10 Hz
}

// A looping simulated device whose last waypoint is jump_m from its first:
// it holds the first point for 0.5 s, moves to the last over 1 s, holds it
// for 1 s (the hand settles), then wraps at 2.5 s and holds the first point
// again for 0.5 s, so what the hand does just after the wrap is its answer
// to the jump alone.
config::DeviceSpec looping_sim(config::SimDeviceSpec::Mode mode, double jump_m) {
  config::DeviceSpec d;
  d.kind = config::DeviceSpec::Kind::kSim;
  d.sim.mode = mode;
  d.sim.loop = true;
  d.sim.waypoints = {{0.0, {-0.1, 0.0, 0.0}},
                     {0.5, {-0.1, 0.0, 0.0}},
                     {1.5, {-0.1 + jump_m, 0.0, 0.0}},
                     {2.5, {-0.1 + jump_m, 0.0, 0.0}}};
  d.limits.stale_model_s = 10.0;  // no model: only the device side is judged
  return d;
}

// The samples the haptic loop rejects as too fast over the first pass and
// the 0.4 s after the wrap, the device ticked at 1 kHz.
std::uint64_t rejected_as_too_fast_around_the_wrap(const config::DeviceSpec& device_spec) {
  SimDevice device(device_spec.sim);
  EXPECT_TRUE(device.start(nullptr));
  config::HapticSpec haptic_spec;
  auto models = std::make_unique<LocalModelBuffer>();
  auto samples = std::make_unique<ToolSampleRing>();
  HapticLoop loop(device, device_spec, haptic_spec, *models, *samples);
  std::int64_t now_ns = 1000 * test::kMs;
  for (int tick = 0; tick <= 2900; ++tick) {
    loop.tick(now_ns);
    now_ns += test::kMs;
    ToolSample drained;
    while (samples->try_pop(drained)) {
    }
  }
  return loop.stats().rejected_speed;
}

// mode: trajectory jumps with the target at the wrap: loop_wrap_warning.
TEST(LoopWrap, ALoopingTrajectoryIsWarnedAboutItsJump) {
  const config::DeviceSpec d = looping_sim(config::SimDeviceSpec::Mode::kTrajectory, 0.3);
  EXPECT_EQ(sim_loop_wrap_warning(d, 1000.0), loop_wrap_warning("device.sim.waypoints", 0.3, 5.0, 1000.0));
  EXPECT_EQ(sim_loop_wrap_warning(looping_sim(config::SimDeviceSpec::Mode::kTrajectory, 0.004), 1000.0), "");
  config::DeviceSpec once = d;
  once.sim.loop = false;
  EXPECT_EQ(sim_loop_wrap_warning(once, 1000.0), "");
  EXPECT_GT(rejected_as_too_fast_around_the_wrap(d), 0u);
}

// mode: hand follows the jumped target through its spring, and a long wrap
// trips the loop's speed check all the same (the review's 0.3 m: 61 samples
// rejected and one device-lost trip per wrap); it was not warned about. The
// warning now says so exactly when the loop rejects the hand after the wrap.
TEST(LoopWrap, ALoopingHandThatFollowsALongWrapTooFastIsWarnedAboutIt) {
  const config::DeviceSpec review = looping_sim(config::SimDeviceSpec::Mode::kHand, 0.3);
  const std::string w = sim_loop_wrap_warning(review, 1000.0);
  EXPECT_EQ(w.rfind("device.sim.waypoints: the looping track's target goes from its last point back to its first "
                    "in one tick, a 0.3 m jump (device frame), and the hand (device.sim.mode hand) follows it "
                    "through its spring at up to ",
                    0),
            0u)
      << w;
  EXPECT_NE(w.find(" m/s, more than device.limits.max_speed_m_per_s 5: the force ramps out and back in at every "
                   "wrap"),
            std::string::npos)
      << w;
  for (const double jump_m : {0.05, 0.15, 0.17, 0.21, 0.25, 0.3}) {
    SCOPED_TRACE(jump_m);
    const config::DeviceSpec d = looping_sim(config::SimDeviceSpec::Mode::kHand, jump_m);
    EXPECT_EQ(sim_loop_wrap_warning(d, 1000.0).empty(), rejected_as_too_fast_around_the_wrap(d) == 0u);
  }
  EXPECT_GT(rejected_as_too_fast_around_the_wrap(review), 0u);
  EXPECT_EQ(rejected_as_too_fast_around_the_wrap(looping_sim(config::SimDeviceSpec::Mode::kHand, 0.15)), 0u);
}

// One rule for the warning and the hand: the jump at which the simulated
// hand's peak speed reaches device.limits.max_speed_m_per_s splits the wraps
// the loop rejects from those it takes, within 2 %. The default hand (0.1 kg,
// 200 N/m, 4 N s/m) peaks at about 26 times the jump per second
// (docs/daemon-config.md): from about 0.19 m at 5 m/s.
TEST(LoopWrap, TheHandsWrapWarningStartsWhereTheLoopStartsRejecting) {
  config::SimDeviceSpec hand;
  const double per_m = SimDevice::hand_jump_peak_speed_m_per_s(hand, 1.0, 1000.0);
  EXPECT_NEAR(per_m, 26.0, 1.0);
  EXPECT_NEAR(SimDevice::hand_jump_peak_speed_m_per_s(hand, 0.3, 1000.0), 0.3 * per_m, 1e-9);  // linear
  const double threshold_m = 5.0 / per_m;
  EXPECT_NEAR(threshold_m, 0.19, 0.01);
  const config::DeviceSpec above = looping_sim(config::SimDeviceSpec::Mode::kHand, 1.02 * threshold_m);
  EXPECT_NE(sim_loop_wrap_warning(above, 1000.0), "");
  EXPECT_GT(rejected_as_too_fast_around_the_wrap(above), 0u);
  const config::DeviceSpec below = looping_sim(config::SimDeviceSpec::Mode::kHand, 0.98 * threshold_m);
  EXPECT_EQ(sim_loop_wrap_warning(below, 1000.0), "");
  EXPECT_EQ(rejected_as_too_fast_around_the_wrap(below), 0u);
  // A stiffer, lighter hand swings faster: the same wrap is then warned about.
  config::DeviceSpec stiff = below;
  stiff.sim.hand_stiffness_N_per_m = 800.0;
  EXPECT_NE(sim_loop_wrap_warning(stiff, 1000.0), "");
  EXPECT_GT(rejected_as_too_fast_around_the_wrap(stiff), 0u);
  // No spring: the hand never follows the jump.
  config::SimDeviceSpec limp;
  limp.hand_stiffness_N_per_m = 0.0;
  EXPECT_EQ(SimDevice::hand_jump_peak_speed_m_per_s(limp, 1.0, 1000.0), 0.0);
}

}  // namespace
}  // namespace tissue::haptics
