#include "haptics/sim_device.hpp"

#include <gtest/gtest.h>

#include "haptics/haptics_test_support.hpp"

namespace tissue::haptics {
namespace {

using test::kMs;

config::SimDeviceSpec spec(config::SimDeviceSpec::Mode mode) {
  config::SimDeviceSpec s;
  s.mode = mode;
  s.waypoints = {{0.0, {0.0, 0.0, 0.0}}, {1.0, {0.1, 0.0, -0.1}}, {2.0, {0.1, 0.2, -0.1}}};
  return s;
}

TEST(SimDevice, TrajectoryFollowsWaypointsPiecewiseLinearly) {
  SimDevice d(spec(config::SimDeviceSpec::Mode::kTrajectory));
  std::string error;
  ASSERT_TRUE(d.start(&error)) << error;
  DeviceSample s;
  const std::int64_t t0 = 123 * kMs;
  ASSERT_TRUE(d.read(t0, &s));
  EXPECT_TRUE(s.position_m.isApprox(Vec3(0, 0, 0)) || s.position_m.norm() < 1e-15);
  ASSERT_TRUE(d.read(t0 + 500 * kMs, &s));
  EXPECT_TRUE(s.position_m.isApprox(Vec3(0.05, 0.0, -0.05), 1e-12));
  EXPECT_TRUE(s.velocity_m_per_s.isApprox(Vec3(0.1, 0.0, -0.1), 1e-12));
  ASSERT_TRUE(d.read(t0 + 1500 * kMs, &s));
  EXPECT_TRUE(s.position_m.isApprox(Vec3(0.1, 0.1, -0.1), 1e-12));
  ASSERT_TRUE(d.read(t0 + 5000 * kMs, &s));  // past the end: holds the last waypoint
  EXPECT_TRUE(s.position_m.isApprox(Vec3(0.1, 0.2, -0.1), 1e-12));
  EXPECT_EQ(s.velocity_m_per_s, Vec3::Zero());
  d.write(0, Vec3(100, 0, 0));  // a trajectory ignores forces
  ASSERT_TRUE(d.read(t0 + 5001 * kMs, &s));
  EXPECT_TRUE(s.position_m.isApprox(Vec3(0.1, 0.2, -0.1), 1e-12));
}

TEST(SimDevice, LoopRepeatsTheTimeline) {
  config::SimDeviceSpec s = spec(config::SimDeviceSpec::Mode::kTrajectory);
  s.loop = true;
  SimDevice d(s);
  ASSERT_TRUE(d.start(nullptr));
  EXPECT_TRUE(d.target_m(2.5).isApprox(d.target_m(0.5), 1e-12));
  EXPECT_TRUE(d.target_m(4.25).isApprox(d.target_m(0.25), 1e-12));
}

// docs/daemon-config.md: a looping timeline whose first waypoint is after 0
// repeats from the first waypoint to the last (period last - first); the
// first position is held before the first time on the first pass only.
TEST(SimDevice, ALoopStartingAfterZeroRepeatsFromTheFirstWaypoint) {
  config::SimDeviceSpec s;
  s.mode = config::SimDeviceSpec::Mode::kTrajectory;
  s.waypoints = {{1.0, {0.0, 0.0, 0.0}}, {3.0, {0.02, 0.0, 0.0}}};
  s.loop = true;
  SimDevice d(s);
  ASSERT_TRUE(d.start(nullptr));
  EXPECT_TRUE(d.target_m(0.5).isApprox(Vec3(0.0, 0.0, 0.0), 1e-12));  // held before the first time
  EXPECT_TRUE(d.target_m(3.5).isApprox(d.target_m(1.5), 1e-12));      // period 2 s, not 3 s
  EXPECT_NEAR(d.target_m(3.5).x(), 0.005, 1e-12);
}

TEST(SimDevice, HandSettlesOnTargetAndYieldsToTheRenderedForce) {
  config::SimDeviceSpec s;
  s.mode = config::SimDeviceSpec::Mode::kHand;
  s.waypoints = {{0.0, {0.0, 0.0, 0.0}}};
  SimDevice d(s);
  ASSERT_TRUE(d.start(nullptr));
  DeviceSample sample;
  // Constant 1 N up: equilibrium offset F / k_hand = 1 / 200 = 5 mm.
  for (int i = 0; i <= 3000; ++i) {
    ASSERT_TRUE(d.read(i * kMs, &sample));
    d.write(i * kMs, Vec3(0, 0, 1.0));
  }
  EXPECT_NEAR(sample.position_m.z(), 1.0 / s.hand_stiffness_N_per_m, 1e-6);
  EXPECT_NEAR(sample.velocity_m_per_s.norm(), 0.0, 1e-6);
  // Non-finite forces are ignored rather than integrated.
  d.write(0, Vec3(std::nan(""), 0, 0));
  ASSERT_TRUE(d.read(3001 * kMs, &sample));
  EXPECT_TRUE(sample.position_m.allFinite());
}

TEST(SimDevice, StartRejectsBadSpecsWithAMessage) {
  config::SimDeviceSpec s;
  std::string error;
  EXPECT_FALSE(SimDevice(s).start(&error));
  EXPECT_NE(error.find("at least one waypoint"), std::string::npos) << error;
  s.waypoints = {{1.0, {0, 0, 0}}, {0.5, {0, 0, 0}}};
  EXPECT_FALSE(SimDevice(s).start(&error));
  EXPECT_NE(error.find("must not decrease"), std::string::npos) << error;
  s.waypoints = {{0.0, {0, 0, 0}}};
  s.hand_mass_kg = 0.0;
  EXPECT_FALSE(SimDevice(s).start(&error));
  EXPECT_NE(error.find("mass"), std::string::npos) << error;
}

// 0.1 g on the default spring and damper: semi-implicit Euler at 0.5 ms
// blows up (h c / m = 20): pushed by 1 N, the hand's position is non-finite
// after 240 sub-steps (120 reads), and every sample after that was refused. start() refuses it; the
// lightest hand it accepts settles.
TEST(SimDevice, StartRefusesAHandTooLightToIntegrate) {
  config::SimDeviceSpec s;
  s.mode = config::SimDeviceSpec::Mode::kHand;
  s.waypoints = {{0.0, {0.0, 0.0, 0.0}}};
  s.hand_mass_kg = 1e-4;
  std::string error;
  EXPECT_FALSE(SimDevice(s).start(&error));
  EXPECT_NE(error.find("too light"), std::string::npos) << error;

  s.hand_mass_kg = s.min_hand_mass_kg();
  SimDevice d(s);
  ASSERT_TRUE(d.start(&error)) << error;
  DeviceSample sample;
  for (int i = 0; i <= 3000; ++i) {
    ASSERT_TRUE(d.read(i * kMs, &sample));
    ASSERT_TRUE(sample.position_m.allFinite()) << i;
    d.write(i * kMs, Vec3(0, 0, 1.0));
  }
  EXPECT_NEAR(sample.position_m.z(), 1.0 / s.hand_stiffness_N_per_m, 1e-6);
}

// A read long after the last one (a caller that stopped for weeks)
// integrates the hand's last kMaxSubsteps sub-steps; the sub-step count was
// converted to int before the clamp, which overflowed and integrated nothing.
TEST(SimDevice, AReadAfterALongGapStillMovesTheHand) {
  config::SimDeviceSpec s;
  s.mode = config::SimDeviceSpec::Mode::kHand;
  s.waypoints = {{0.0, {0.0, 0.0, 0.0}}, {1.0, {0.1, 0.0, 0.0}}};
  SimDevice d(s);
  ASSERT_TRUE(d.start(nullptr));
  DeviceSample first, later;
  ASSERT_TRUE(d.read(0, &first));
  const std::int64_t gap_ns = 3'000'000'000'000'000;  // ~35 days: 6e12 sub-steps of 0.5 ms
  ASSERT_TRUE(d.read(gap_ns, &later));
  EXPECT_TRUE(later.position_m.allFinite());
  EXPECT_GT(later.position_m.x(), 1e-4);  // pulled towards the last waypoint (0.1 m)
}

}  // namespace
}  // namespace tissue::haptics
