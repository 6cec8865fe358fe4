#include "haptics/replay_device.hpp"

#include <gtest/gtest.h>

#include <memory>

#include "haptics/haptic_loop.hpp"

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

// A session recorded at 1 kHz from a device that sends a new pose only every
// few ticks (a 250 Hz UDP device: 4): `still_rows` rows at `from_m`, then
// `poses` new poses, each `step_m` on from the last and shown after the last
// was held for rows_between_poses[pose] rows (cycled: a jittery cadence), then
// the last pose for 1 + tail_rows rows.
struct SlowDeviceTrack {
  std::vector<double> time_s;
  std::vector<Vec3> position_m;
};
SlowDeviceTrack slow_device_track(const Vec3& from_m, const Vec3& step_m, int still_rows, int poses,
                                  const std::vector<int>& rows_between_poses, int tail_rows) {
  SlowDeviceTrack track;
  int row = 0;
  Vec3 p = from_m;
  auto add_rows = [&](int n) {
    for (int r = 0; r < n; ++r) {
      track.time_s.push_back(1e-3 * row++);
      track.position_m.push_back(p);
    }
  };
  add_rows(still_rows);
  for (int pose = 0; pose < poses; ++pose) {
    add_rows(rows_between_poses[pose % rows_between_poses.size()]);
    p += step_m;
  }
  add_rows(1 + tail_rows);
  return track;
}

// The haptic loop's judgement of a replayed hand: ticks `ticks` times at
// 1 kHz with no model (only the device side is judged) and returns its stats.
HapticStats replay_through_the_loop(ReplayDevice& replay, const config::DeviceSpec& device_spec, int ticks) {
  config::HapticSpec haptic_spec;
  auto models = std::make_unique<LocalModelBuffer>();
  auto samples = std::make_unique<ToolSampleRing>();
  HapticLoop loop(replay, device_spec, haptic_spec, *models, *samples);
  std::int64_t now_ns = 1000 * kMs;
  for (int tick = 0; tick < ticks; ++tick) {
    now_ns += kMs;
    loop.tick(now_ns);
    ToolSample drained;
    while (samples->try_pop(drained)) {
    }
  }
  return loop.stats();
}

config::DeviceSpec no_model_device_spec() {
  config::DeviceSpec spec;
  spec.limits.stale_model_s = 10.0;  // no model: only the device side is judged
  return spec;
}

// A 250 Hz device moving at half of device.limits.max_speed_m_per_s was
// accepted live (the loop saw each pose 4 ms after the last). Its recording
// holds each pose for 4 rows, then steps: replayed row to row, the whole
// 4 ms of motion came in one 1 ms tick at 4 times the speed, every step was
// rejected as too fast and the replay lost the hand.
TEST(ReplayDevice, A250HzDeviceAtHalfTheSpeedLimitReplaysWithoutASpeedRejection) {
  const config::DeviceSpec spec = no_model_device_spec();
  ASSERT_EQ(spec.limits.max_speed_m_per_s, 5.0);
  // 2.5 m/s: 10 mm every 4 ms, 0.8 m in 80 poses (within the 1 m workspace).
  const SlowDeviceTrack track = slow_device_track(Vec3(-0.4, 0, 0), Vec3(0.01, 0, 0), 0, 80, {4}, 20);
  ReplayDevice replay(track.time_s, track.position_m, 1.0, false, spec.limits.max_speed_m_per_s);
  std::string error;
  ASSERT_TRUE(replay.start(&error)) << error;
  const HapticStats st = replay_through_the_loop(replay, spec, static_cast<int>(track.time_s.size()) + 10);
  EXPECT_EQ(st.rejected_speed, 0u);
  EXPECT_EQ(st.device_lost_trips, 0u);
  DeviceSample end;
  ASSERT_TRUE(replay.read(2000 * kMs, &end));  // past the end: the track was played to its last pose
  EXPECT_NEAR(end.position_m.x(), 0.4, 1e-12);
}

// A recorded hand that stood still for a second and then moved: the replayed
// hand stands still too, and makes the first step over one of the device's
// periods (as the loop saw it live: a pose, then the next 4 ms later), not in
// one tick, and not drifting over the whole second.
TEST(ReplayDevice, AHandThatStoodStillHoldsUntilOneDevicePeriodBeforeItMoves) {
  // Still at the origin for rows 0..999, then a 4 mm step every 4 rows
  // (1 m/s): the first new pose shows at row 1004.
  const SlowDeviceTrack track = slow_device_track(Vec3::Zero(), Vec3(0.004, 0, 0), 1000, 20, {4}, 0);
  ASSERT_EQ(track.position_m[1003], Vec3::Zero());
  ASSERT_EQ(track.position_m[1004], Vec3(0.004, 0, 0));
  ReplayDevice replay(track.time_s, track.position_m, 1.0, false, 5.0);
  std::string error;
  ASSERT_TRUE(replay.start(&error)) << error;
  DeviceSample s;
  for (int ms = 0; ms < 1000; ++ms) {  // held exactly, at rest, until one period (4 ms) before the step
    ASSERT_TRUE(replay.read(ms * kMs, &s));
    ASSERT_EQ(s.position_m, Vec3::Zero()) << "at " << ms << " ms";
    ASSERT_EQ(s.velocity_m_per_s, Vec3::Zero()) << "at " << ms << " ms";
  }
  ASSERT_TRUE(replay.read(1002 * kMs, &s));  // half way through the first step, at the device's speed
  EXPECT_NEAR((s.position_m - Vec3(0.002, 0, 0)).norm(), 0.0, 1e-12);
  EXPECT_NEAR((s.velocity_m_per_s - Vec3(1.0, 0, 0)).norm(), 0.0, 1e-9);
  ASSERT_TRUE(replay.read(1004 * kMs, &s));
  EXPECT_NEAR((s.position_m - Vec3(0.004, 0, 0)).norm(), 0.0, 1e-12);
  ASSERT_TRUE(replay.read(1010 * kMs, &s));  // and on at 1 m/s, 1 mm a tick
  EXPECT_NEAR((s.position_m - Vec3(0.010, 0, 0)).norm(), 0.0, 1e-12);
  EXPECT_NEAR((s.velocity_m_per_s - Vec3(1.0, 0, 0)).norm(), 0.0, 1e-9);
}

// A device as fast as the loop (the simulated hand, a 1 kHz device) changes
// position every row, now and then holding one for a few rows: its period is
// one row, and it replays row to row, as before knots.
TEST(ReplayDevice, A1kHzTrackReplaysRowToRow) {
  std::vector<double> time_s;
  std::vector<Vec3> position_m;
  Vec3 p(0.01, -0.02, 0.03);
  for (int row = 0; row < 300; ++row) {
    time_s.push_back(1e-3 * row);
    position_m.push_back(p);
    if (row % 50 < 45) p += Vec3(1e-4 * (1 + row % 7), -2e-5 * (row % 3), 3e-5);  // then 5 rows held
  }
  ReplayDevice replay(time_s, position_m, 1.0, false, 5.0);
  ASSERT_TRUE(replay.start(nullptr));
  EXPECT_NEAR(replay.device_period_s(), 1e-3, 1e-12);
  DeviceSample s;
  ASSERT_TRUE(replay.read(0, &s));  // the track's time counts from the first read
  for (int row = 0; row + 1 < 300; ++row) {  // half way between each two rows
    ASSERT_TRUE(replay.read(static_cast<std::int64_t>((row + 0.5) * kMs), &s));
    ASSERT_NEAR((s.position_m - 0.5 * (position_m[row] + position_m[row + 1])).norm(), 0.0, 1e-12) << row;
    ASSERT_NEAR((s.velocity_m_per_s - 1e3 * (position_m[row + 1] - position_m[row])).norm(), 0.0, 1e-9) << row;
  }
}

// start() refuses exactly the speeds at which read() would hand the loop a
// too-fast sample: one rule for both. A jittery device (3, 4 and 5 ms between
// poses of 4 mm: 1.33, 1 and 0.8 m/s) after a half-second pause: its fastest
// stretch is 4 mm in 3 ms, so at most 5 / 1.333 = 3.75 times real time.
TEST(ReplayDevice, StartRefusesExactlyTheSpeedsAtWhichReadIsTooFast) {
  const config::DeviceSpec spec = no_model_device_spec();
  const double max_speed_m_per_s = spec.limits.max_speed_m_per_s;
  const SlowDeviceTrack track = slow_device_track(Vec3(-0.2, 0, 0), Vec3(0.004, 0, 0), 500, 90, {4, 3, 5, 4}, 50);
  const double allowed = max_speed_m_per_s / (0.004 / 0.003);
  std::string error;
  ReplayDevice above(track.time_s, track.position_m, 1.01 * allowed, false, max_speed_m_per_s);
  EXPECT_FALSE(above.start(&error));
  EXPECT_NE(error.find("its peak 1.333 m/s"), std::string::npos) << error;
  EXPECT_NE(error.find("at most 3.75"), std::string::npos) << error;

  ReplayDevice below(track.time_s, track.position_m, 0.99 * allowed, false, max_speed_m_per_s);
  ASSERT_TRUE(below.start(&error)) << error;
  const double duration_ticks = 1e3 * (track.time_s.back() - track.time_s.front()) / (0.99 * allowed);
  const HapticStats st = replay_through_the_loop(below, spec, static_cast<int>(duration_ticks) + 10);
  EXPECT_EQ(st.rejected_speed, 0u);
  EXPECT_EQ(st.device_lost_trips, 0u);
}

}  // namespace
}  // namespace tissue::haptics
