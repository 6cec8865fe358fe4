#include "haptics/force_safety.hpp"

#include <gtest/gtest.h>

#include <cmath>

namespace tissue::haptics {
namespace {

constexpr double kDt_s = 1e-3;

config::ForceLimits limits() {
  config::ForceLimits l;  // defaults: 3 N, 300 N/s, ramp in 0.5 s, ramp out 0.05 s
  return l;
}

// Runs until the scale reached 1 with a zero desired force.
void ramp_in(ForceSafety& s) {
  for (int i = 0; i < 600; ++i) s.apply(Vec3::Zero(), kDt_s, kFaultNone);
  ASSERT_EQ(s.scale(), 1.0);
}

TEST(ForceSafety, ClampsMagnitudeAndRate) {
  ForceSafety s(limits());
  ramp_in(s);
  const Vec3 desired(10.0, -20.0, 5.0);  // far above 3 N
  Vec3 previous = s.output_N();
  for (int i = 0; i < 100; ++i) {
    const Vec3 out = s.apply(desired, kDt_s, kFaultNone);
    EXPECT_LE(out.norm(), 3.0 + 1e-12);
    EXPECT_LE((out - previous).norm(), 300.0 * kDt_s + 1e-12);
    previous = out;
  }
  EXPECT_NEAR(previous.norm(), 3.0, 1e-12);
  EXPECT_NEAR(previous.normalized().dot(desired.normalized()), 1.0, 1e-12);  // clamped, not bent
}

TEST(ForceSafety, RampsInAfterStart) {
  config::ForceLimits l = limits();
  l.max_force_rate_N_per_s = 1e9;  // isolate the ramp
  ForceSafety s(l);
  const Vec3 desired(0.0, 0.0, 2.0);
  double previous_N = 0.0;
  for (int i = 1; i <= 500; ++i) {
    const double z = s.apply(desired, kDt_s, kFaultNone).z();
    EXPECT_NEAR(z, 2.0 * i * kDt_s / 0.5, 1e-9);
    EXPECT_GE(z, previous_N);
    previous_N = z;
  }
  EXPECT_NEAR(previous_N, 2.0, 1e-9);
}

// A device that comes back deep inside the object asks for hundreds of
// newtons: the ramp-in still takes ramp_in_s to reach max_force_N (the clamp
// comes before the scale), instead of reaching it within a few ticks at the
// rate limit.
TEST(ForceSafety, RampsInAForceFarAboveTheLimitOverTheWholeRamp) {
  ForceSafety s(limits());
  const Vec3 desired(0.0, 0.0, -400.0);
  for (int i = 1; i <= 500; ++i) {
    const Vec3 out = s.apply(desired, kDt_s, kFaultNone);
    EXPECT_NEAR(out.z(), -3.0 * i * kDt_s / 0.5, 1e-9) << "tick " << i;
    EXPECT_NEAR(out.x(), 0.0, 0.0);
  }
  EXPECT_NEAR(s.output_N().norm(), 3.0, 1e-9);
}

TEST(ForceSafety, FaultRampsToZeroWithinRampOutWithoutSteps) {
  ForceSafety s(limits());
  ramp_in(s);
  for (int i = 0; i < 50; ++i) s.apply(Vec3(0, 3.0, 0), kDt_s, kFaultNone);
  ASSERT_NEAR(s.output_N().norm(), 3.0, 1e-12);
  Vec3 previous = s.output_N();
  int ticks = 0;
  while (!s.quiescent() && ticks < 1000) {
    const Vec3 out = s.apply(Vec3(0, 3.0, 0), kDt_s, kFaultStaleModel);
    EXPECT_LE((out - previous).norm(), 300.0 * kDt_s + 1e-12);
    previous = out;
    ++ticks;
  }
  EXPECT_LE(ticks * kDt_s, 0.05 + 1e-9);  // ramp_out_s
  EXPECT_EQ(s.trips(0), 1u);
  // Recovery ramps in again rather than stepping back.
  const Vec3 first = s.apply(Vec3(0, 3.0, 0), kDt_s, kFaultNone);
  EXPECT_LE(first.norm(), 3.0 * kDt_s / 0.5 + 1e-12);
}

TEST(ForceSafety, NonFiniteDesiredForceNeverReachesTheOutput) {
  ForceSafety s(limits());
  ramp_in(s);
  for (int i = 0; i < 20; ++i) s.apply(Vec3(1.0, 0, 0), kDt_s, kFaultNone);
  const Vec3 before = s.output_N();
  for (int i = 0; i < 200; ++i) {
    const Vec3 out = s.apply(Vec3(std::nan(""), INFINITY, 0.0), kDt_s, kFaultNone);
    ASSERT_TRUE(out.allFinite());
    EXPECT_LE(out.norm(), before.norm() + 1e-12);  // ramps down from the last finite force
  }
  EXPECT_EQ(s.nonfinite_inputs(), 200u);
  EXPECT_EQ(s.trips(4), 1u);
  EXPECT_TRUE(s.quiescent());
  // Bad time steps do not open the limits.
  EXPECT_TRUE(s.apply(Vec3(3, 0, 0), std::nan(""), kFaultNone).isZero(0.0));
  EXPECT_TRUE(s.apply(Vec3(3, 0, 0), -1.0, kFaultNone).isZero(0.0));
}

TEST(ForceSafety, CountsEachFaultKindOnItsRisingEdge) {
  ForceSafety s(limits());
  s.apply(Vec3::Zero(), kDt_s, kFaultDeviceLost);
  s.apply(Vec3::Zero(), kDt_s, kFaultDeviceLost | kFaultWatchdog);
  s.apply(Vec3::Zero(), kDt_s, kFaultNone);
  s.apply(Vec3::Zero(), kDt_s, kFaultDeviceLost | kFaultStop);
  EXPECT_EQ(s.trips(1), 2u);
  EXPECT_EQ(s.trips(2), 1u);
  EXPECT_EQ(s.trips(3), 1u);
  EXPECT_EQ(s.total_trips(), 4u);
}

}  // namespace
}  // namespace tissue::haptics
