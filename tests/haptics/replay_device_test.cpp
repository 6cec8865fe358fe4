#include "haptics/replay_device.hpp"

#include <gtest/gtest.h>

namespace tissue::haptics {
namespace {

constexpr std::int64_t kMs = 1000000;

ReplayDevice three_points(double speed, bool loop) {
  // 0 s at the origin, 1 s at x = 0.01, 2 s at x = 0.01, y = 0.02.
  return ReplayDevice({0.0, 1.0, 2.0}, {Vec3(0, 0, 0), Vec3(0.01, 0, 0), Vec3(0.01, 0.02, 0)}, speed, loop);
}

TEST(ReplayDevice, InterpolatesAlongTheTrackFromTheFirstRead) {
  ReplayDevice d = three_points(1.0, false);
  std::string error;
  ASSERT_TRUE(d.start(&error)) << error;
  DeviceSample s;
  const std::int64_t t0 = 5'000 * kMs;  // any clock origin: time counts from the first read
  ASSERT_TRUE(d.read(t0, &s));
  EXPECT_EQ(s.position_m, Vec3(0, 0, 0));
  ASSERT_TRUE(d.read(t0 + 500 * kMs, &s));
  EXPECT_NEAR((s.position_m - Vec3(0.005, 0, 0)).norm(), 0.0, 1e-15);
  EXPECT_NEAR((s.velocity_m_per_s - Vec3(0.01, 0, 0)).norm(), 0.0, 1e-12);
  ASSERT_TRUE(d.read(t0 + 1500 * kMs, &s));
  EXPECT_NEAR((s.position_m - Vec3(0.01, 0.01, 0)).norm(), 0.0, 1e-15);
  ASSERT_TRUE(d.read(t0 + 9000 * kMs, &s));  // past the end: held, at rest
  EXPECT_EQ(s.position_m, Vec3(0.01, 0.02, 0));
  EXPECT_EQ(s.velocity_m_per_s, Vec3::Zero());
}

TEST(ReplayDevice, SpeedAndLoop) {
  ReplayDevice fast = three_points(2.0, false);
  ASSERT_TRUE(fast.start(nullptr));
  DeviceSample s;
  fast.read(0, &s);
  fast.read(250 * kMs, &s);  // 0.5 s into the track
  EXPECT_NEAR(s.position_m.x(), 0.005, 1e-15);
  EXPECT_NEAR(s.velocity_m_per_s.x(), 0.02, 1e-12);

  ReplayDevice looping = three_points(1.0, true);
  ASSERT_TRUE(looping.start(nullptr));
  looping.read(0, &s);
  looping.read(2500 * kMs, &s);  // 2.5 s wraps to 0.5 s
  EXPECT_NEAR((s.position_m - Vec3(0.005, 0, 0)).norm(), 0.0, 1e-12);
}

TEST(ReplayDevice, BadTracksAreRefusedAtStart) {
  std::string error;
  EXPECT_FALSE(ReplayDevice({}, {}, 1.0, false).start(&error));
  EXPECT_NE(error.find("empty"), std::string::npos) << error;
  EXPECT_FALSE(ReplayDevice({0.0, 1.0}, {Vec3::Zero()}, 1.0, false).start(&error));
  EXPECT_FALSE(ReplayDevice({1.0, 0.0}, {Vec3::Zero(), Vec3::Zero()}, 1.0, false).start(&error));
  EXPECT_NE(error.find("row 1"), std::string::npos) << error;
  EXPECT_FALSE(ReplayDevice({0.0}, {Vec3(std::numeric_limits<double>::quiet_NaN(), 0, 0)}, 1.0, false).start(&error));
  EXPECT_FALSE(ReplayDevice({0.0}, {Vec3::Zero()}, 0.0, false).start(&error));
}

// device.replay.speed scales the hand's speed: above
// device.limits.max_speed_m_per_s the loop would take every replayed sample
// as a glitch and ramp the force out mid-replay, silently. Refused at start,
// with the numbers, instead.
TEST(ReplayDevice, ASpeedThatTakesTheTrackPastTheSpeedLimitIsRefusedAtStart) {
  // A 0.6 m/s stroke (its peak, device frame) between two slower segments.
  const std::vector<double> time_s{0.0, 1.0, 1.5, 3.5};
  const std::vector<Vec3> position_m{Vec3(0, 0, 0), Vec3(0.1, 0, 0), Vec3(0.1, 0.3, 0), Vec3(0.1, 0.3, 0.2)};
  const double max_speed_m_per_s = 5.0;
  std::string error;
  ReplayDevice too_fast(time_s, position_m, 10.0, false, max_speed_m_per_s);
  EXPECT_FALSE(too_fast.start(&error));
  EXPECT_NE(error.find("replay device: device.replay.speed 10 plays the track at up to 6 m/s"), std::string::npos)
      << error;
  EXPECT_NE(error.find("above device.limits.max_speed_m_per_s 5"), std::string::npos) << error;
  EXPECT_NE(error.find("at most 8.33"), std::string::npos) << error;

  ReplayDevice real_time(time_s, position_m, 1.0, false, max_speed_m_per_s);
  EXPECT_TRUE(real_time.start(&error)) << error;
  ReplayDevice at_the_limit(time_s, position_m, 8.0, false, max_speed_m_per_s);
  EXPECT_TRUE(at_the_limit.start(&error)) << error;
}

// Haptic rows are written every tick, so a device slower than the loop (a
// 250 Hz UDP device) is recorded as a position held for a few rows, then a
// step. Its speed is the step over the time since that position came, as the
// loop measured it live, not over one row: a 1.5 m/s stroke is no 6 m/s one.
TEST(ReplayDevice, ASlowDevicesHeldRowsDoNotCountAsSpeed) {
  std::vector<double> time_s;
  std::vector<Vec3> position_m;
  for (int row = 0; row <= 400; ++row) {  // 0.4 s at 1 kHz, a new pose every 4 rows (6 mm: 1.5 m/s)
    time_s.push_back(1e-3 * row);
    position_m.push_back(Vec3(0.006 * (row / 4), 0, 0));
  }
  std::string error;
  ReplayDevice real_time(time_s, position_m, 1.0, false, 5.0);
  EXPECT_TRUE(real_time.start(&error)) << error;
  ReplayDevice too_fast(time_s, position_m, 4.0, false, 5.0);  // 6 m/s
  EXPECT_FALSE(too_fast.start(&error));
  EXPECT_NE(error.find("its peak 1.5 m/s"), std::string::npos) << error;
}

}  // namespace
}  // namespace tissue::haptics
