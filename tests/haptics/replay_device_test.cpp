#include "haptics/replay_device.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "haptics/haptic_loop.hpp"
#include "haptics/loop_wrap.hpp"

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

// The refusal's "use a speed of at most X" is advice to follow: X is printed
// to 4 significant digits rounded down, so that speed is accepted. Rounded to
// nearest, a 12.3457 mm step in 7 ms (1.764 m/s) at speed 3 suggested 2.835
// (the limit is 2.834995...), and that speed was refused in turn.
// The speed the refusal of a one-step track (step_m in 7 ms) at speed 3 suggests.
std::string suggested_speed(double step_m) {
  const std::vector<double> time_s{0.0, 0.007};
  const std::vector<Vec3> position_m{Vec3::Zero(), Vec3(step_m, 0, 0)};
  std::string error;
  ReplayDevice too_fast(time_s, position_m, 3.0, false, 5.0);
  EXPECT_FALSE(too_fast.start(&error));
  const std::string at_most = "use a speed of at most ";
  const std::size_t at = error.find(at_most);
  EXPECT_NE(at, std::string::npos) << error;
  if (at == std::string::npos) return "";
  return error.substr(at + at_most.size(), error.find(' ', at + at_most.size()) - at - at_most.size());
}

TEST(ReplayDevice, TheSuggestedSpeedIsRoundedDownSoItIsAccepted) {
  const std::vector<double> time_s{0.0, 0.007};
  const std::string review = suggested_speed(0.0123457);
  EXPECT_EQ(review, "2.834");
  std::string error;
  ReplayDevice advised(time_s, {Vec3::Zero(), Vec3(0.0123457, 0, 0)}, std::stod(review), false, 5.0);
  EXPECT_TRUE(advised.start(&error)) << error;
  // Any step: the advice is accepted, and it is the largest 4-digit speed
  // that is (one more in the last digit is refused).
  for (int i = 0; i < 500; ++i) {
    const double step_m = 0.0120 + 1.37e-5 * i;
    const std::string text = suggested_speed(step_m);
    SCOPED_TRACE(std::to_string(step_m) + " m: at most " + text);
    ASSERT_FALSE(text.empty());
    const double speed = std::stod(text);
    ReplayDevice followed(time_s, {Vec3::Zero(), Vec3(step_m, 0, 0)}, speed, false, 5.0);
    EXPECT_TRUE(followed.start(&error)) << error;
    ReplayDevice above(time_s, {Vec3::Zero(), Vec3(step_m, 0, 0)}, speed + 1e-3, false, 5.0);  // speeds 2..3
    EXPECT_FALSE(above.start(&error));
  }
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
// hand stands still too, and makes the first step over three of the device's
// periods, not in one tick, and not drifting over the whole second. Live the
// loop saw that step over one period (the device re-sent the still pose), but
// the recording cannot tell it from up to two lost poses, which the loop
// measured over the whole gap: three periods is never faster than live.
TEST(ReplayDevice, AHandThatStoodStillHoldsUntilThreeDevicePeriodsBeforeItMoves) {
  // Still at the origin for rows 0..999, then a 4 mm step every 4 rows
  // (1 m/s): the first new pose shows at row 1004.
  const SlowDeviceTrack track = slow_device_track(Vec3::Zero(), Vec3(0.004, 0, 0), 1000, 20, {4}, 0);
  ASSERT_EQ(track.position_m[1003], Vec3::Zero());
  ASSERT_EQ(track.position_m[1004], Vec3(0.004, 0, 0));
  ReplayDevice replay(track.time_s, track.position_m, 1.0, false, 5.0);
  std::string error;
  ASSERT_TRUE(replay.start(&error)) << error;
  DeviceSample s;
  for (int ms = 0; ms < 992; ++ms) {  // held exactly, at rest, until three periods (12 ms) before the step
    ASSERT_TRUE(replay.read(ms * kMs, &s));
    ASSERT_EQ(s.position_m, Vec3::Zero()) << "at " << ms << " ms";
    ASSERT_EQ(s.velocity_m_per_s, Vec3::Zero()) << "at " << ms << " ms";
  }
  ASSERT_TRUE(replay.read(998 * kMs, &s));  // half way through the first step: 4 mm over 12 ms
  EXPECT_NEAR((s.position_m - Vec3(0.002, 0, 0)).norm(), 0.0, 1e-12);
  EXPECT_NEAR((s.velocity_m_per_s - Vec3(0.004 / 0.012, 0, 0)).norm(), 0.0, 1e-9);
  ASSERT_TRUE(replay.read(1004 * kMs, &s));
  EXPECT_NEAR((s.position_m - Vec3(0.004, 0, 0)).norm(), 0.0, 1e-12);
  ASSERT_TRUE(replay.read(1010 * kMs, &s));  // and on at 1 m/s, 1 mm a tick
  EXPECT_NEAR((s.position_m - Vec3(0.010, 0, 0)).norm(), 0.0, 1e-12);
  EXPECT_NEAR((s.velocity_m_per_s - Vec3(1.0, 0, 0)).norm(), 0.0, 1e-9);
}

// A recording at 1 kHz of a device that sends a pose every period_rows
// ticks, moving at speed_m_per_s along x from -0.4 m for `rows` rows; the
// packets of the device samples in `lost` never arrived, so the row holds the
// last pose that did (as the loop records a tick without a datagram).
SlowDeviceTrack lost_packet_track(int period_rows, double speed_m_per_s, int rows, const std::vector<int>& lost) {
  SlowDeviceTrack track;
  Vec3 held_m(-0.4, 0, 0);
  for (int row = 0; row < rows; ++row) {
    const int sample = row / period_rows;
    if (row % period_rows == 0 && std::find(lost.begin(), lost.end(), sample) == lost.end())
      held_m = Vec3(-0.4 + speed_m_per_s * 1e-3 * row, 0, 0);
    track.time_s.push_back(1e-3 * row);
    track.position_m.push_back(held_m);
  }
  return track;
}

// A lost or late pose is a gap of two (or three) periods, not a hand that
// stood still: live, UdpDevice::read returned false on the ticks without a
// datagram and the loop measured the step over the time since the last
// accepted sample. Taken for a still hand, the replay squeezed the step into
// one period, at up to twice the speed the loop measured live, and start()
// refused tracks the live session handled ("plays the track at up to 6 m/s
// ... use a speed of at most 0.8333" for 3 m/s at 1 kHz with one duplicate
// row). Up to two lost packets in a row now replay exactly as live.
TEST(ReplayDevice, LostPacketsReplayAtTheSpeedTheLoopMeasuredLive) {
  const config::DeviceSpec spec = no_model_device_spec();
  const double max_speed_m_per_s = spec.limits.max_speed_m_per_s;
  struct Case {
    const char* what;
    int period_rows;
    std::vector<int> lost;
  };
  for (const Case& c : {Case{"1 kHz, one duplicate row", 1, {100}}, Case{"250 Hz, one lost packet", 4, {30}},
                        Case{"250 Hz, two lost packets in a row", 4, {30, 31}},
                        Case{"250 Hz, lost packets here and there", 4, {10, 30, 31, 50}}}) {
    SCOPED_TRACE(c.what);
    // 3 m/s, 0.78 m in 260 ms: within the 1 m workspace.
    const SlowDeviceTrack track = lost_packet_track(c.period_rows, 3.0, 261, c.lost);
    ReplayDevice replay(track.time_s, track.position_m, 1.0, false, max_speed_m_per_s);
    std::string error;
    if (!replay.start(&error)) {  // on to the other cases: each says what it refuses
      ADD_FAILURE() << error;
      continue;
    }
    EXPECT_NEAR(replay.device_period_s(), 1e-3 * c.period_rows, 1e-12);
    const HapticStats st = replay_through_the_loop(replay, spec, static_cast<int>(track.time_s.size()) + 10);
    EXPECT_EQ(st.rejected_speed, 0u);
    EXPECT_EQ(st.device_lost_trips, 0u);
    // Its peak is the 3 m/s the loop measured live, so it plays up to 5/3 times real time.
    ReplayDevice faster(track.time_s, track.position_m, 1.01 * max_speed_m_per_s / 3.0, false, max_speed_m_per_s);
    EXPECT_FALSE(faster.start(&error));
    EXPECT_NE(error.find("its peak 3 m/s"), std::string::npos) << error;
  }
}

// A device as fast as the loop (the simulated hand, a 1 kHz device) changes
// position every row, now and then holding one for a few rows: its period is
// one row, and it replays row to row, as before knots. A pose held 6 rows (a
// still hand, or lost poses: the recording cannot tell) is held until three
// rows before the next pose and the step spread over those three.
TEST(ReplayDevice, A1kHzTrackReplaysRowToRow) {
  std::vector<double> time_s;
  std::vector<Vec3> position_m;
  Vec3 p(0.01, -0.02, 0.03);
  for (int row = 0; row < 300; ++row) {
    time_s.push_back(1e-3 * row);
    position_m.push_back(p);
    if (row % 50 < 45) p += Vec3(1e-4 * (1 + row % 7), -2e-5 * (row % 3), 3e-5);  // rows 45..50 of 50 the same
  }
  ReplayDevice replay(time_s, position_m, 1.0, false, 5.0);
  ASSERT_TRUE(replay.start(nullptr));
  EXPECT_NEAR(replay.device_period_s(), 1e-3, 1e-12);
  DeviceSample s;
  ASSERT_TRUE(replay.read(0, &s));           // the track's time counts from the first read
  for (int row = 0; row + 1 < 300; ++row) {  // half way between each two rows
    ASSERT_TRUE(replay.read(static_cast<std::int64_t>((row + 0.5) * kMs), &s));
    const int into_hold = (row + 5) % 50;  // rows 45..50 of 50: 0..5
    const int held_from = row - into_hold;
    if (row < 45 || into_hold > 5) {  // row to row
      ASSERT_NEAR((s.position_m - 0.5 * (position_m[row] + position_m[row + 1])).norm(), 0.0, 1e-12) << row;
      ASSERT_NEAR((s.velocity_m_per_s - 1e3 * (position_m[row + 1] - position_m[row])).norm(), 0.0, 1e-9) << row;
    } else if (into_hold < 3 || held_from + 6 >= 300) {  // held, at rest (to the end for the last)
      ASSERT_EQ(s.position_m, position_m[held_from]) << row;
      ASSERT_EQ(s.velocity_m_per_s, Vec3::Zero()) << row;
    } else {  // the step to row 51 of 50, over rows 48..51
      const Vec3 step_m = position_m[held_from + 6] - position_m[held_from];
      const double u = (row + 0.5 - (held_from + 3)) / 3.0;
      ASSERT_NEAR((s.position_m - (position_m[held_from] + u * step_m)).norm(), 0.0, 1e-12) << row;
      ASSERT_NEAR((s.velocity_m_per_s - 1e3 / 3.0 * step_m).norm(), 0.0, 1e-9) << row;
    }
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

// A session of format version 3 records on which ticks the device
// delivered a new sample (/haptic/device_fresh). A device that sends a
// sample every `period_rows` rows (at 1 kHz), `pose(k)` for sample k, whose
// samples in `lost` never arrived: the row holds the last sample that did,
// and is flagged only where one came (as HapticLoop records it).
struct FlaggedTrack {
  std::vector<double> time_s;
  std::vector<Vec3> position_m;
  std::vector<std::uint8_t> fresh;
};
FlaggedTrack flagged_track(int period_rows, int rows, const std::function<Vec3(int)>& pose,
                           const std::vector<int>& lost = {}) {
  FlaggedTrack track;
  Vec3 held_m = pose(0);
  for (int row = 0; row < rows; ++row) {
    const int sample = row / period_rows;
    const bool came = row % period_rows == 0 && std::find(lost.begin(), lost.end(), sample) == lost.end();
    if (came) held_m = pose(sample);
    track.time_s.push_back(1e-3 * row);
    track.position_m.push_back(held_m);
    track.fresh.push_back(came ? 1 : 0);
  }
  return track;
}

// Four packets lost in a row from a 250 Hz device at 3 m/s: live the loop
// held the last sample for 20 ms and then measured the 60 mm step over those
// 20 ms (3 m/s). Guessed from the positions alone, the step was squeezed into
// 3 periods (12 ms: 5 m/s, faster than live, and start() refused speeds the
// live session allowed). With the flags the step is spread over the whole
// gap, and the speed check measures that. (No device timeout is given: with
// device.limits.device_timeout_s below the 20 ms gap, live and replayed, the
// device is lost over it instead, see ...AGapLongerThanTheDeviceTimeout....)
TEST(ReplayDevice, WithFreshFlagsFourLostPacketsInARowReplayOverTheWholeGap) {
  const config::DeviceSpec spec = no_model_device_spec();
  const double max_speed_m_per_s = spec.limits.max_speed_m_per_s;
  // Samples 30..33 lost: sample 29 at row 116, the next (34) at row 136.
  const FlaggedTrack track =
      flagged_track(4, 261, [](int k) { return Vec3(-0.4 + 3.0 * 4e-3 * k, 0, 0); }, {30, 31, 32, 33});
  ASSERT_EQ(track.position_m[135], track.position_m[116]);
  ASSERT_EQ(track.fresh[136], 1);
  ReplayDevice replay(track.time_s, track.position_m, 1.0, false, max_speed_m_per_s, track.fresh);
  std::string error;
  ASSERT_TRUE(replay.start(&error)) << error;
  EXPECT_NEAR(replay.device_period_s(), 4e-3, 1e-12);
  DeviceSample s;
  ASSERT_TRUE(replay.read(0, &s));
  for (const int ms : {117, 120, 126, 131, 135}) {  // through the gap at the live 3 m/s
    ASSERT_TRUE(replay.read(ms * kMs, &s));
    EXPECT_NEAR(s.position_m.x(), -0.4 + 3e-3 * ms, 1e-12) << "at " << ms << " ms";
    EXPECT_NEAR(s.velocity_m_per_s.x(), 3.0, 1e-9) << "at " << ms << " ms";
  }
  // Its peak is the 3 m/s the loop measured live: at most 5/3 times real time.
  ReplayDevice faster(track.time_s, track.position_m, 1.01 * max_speed_m_per_s / 3.0, false, max_speed_m_per_s,
                      track.fresh);
  EXPECT_FALSE(faster.start(&error));
  EXPECT_NE(error.find("its peak 3 m/s"), std::string::npos) << error;
  ReplayDevice allowed(track.time_s, track.position_m, 0.99 * max_speed_m_per_s / 3.0, false, max_speed_m_per_s,
                       track.fresh);
  ASSERT_TRUE(allowed.start(&error)) << error;
  const HapticStats st = replay_through_the_loop(allowed, spec, 170);
  EXPECT_EQ(st.rejected_speed, 0u);
  EXPECT_EQ(st.device_lost_trips, 0u);
}

// A still hand on a 250 Hz device: the device re-sent the same pose every
// 4 ms, so live the loop measured the first step over one period. With the
// flags the replay holds the pose exactly until the last re-sent sample and
// makes the first step over that one period; the same track without flags (a
// file from before them) keeps the old rule, three periods.
TEST(ReplayDevice, WithFreshFlagsAStillHandsFirstStepPlaysOverOnePeriod) {
  // Still at the origin for samples 0..250 (rows 0..1000), then 4 mm a
  // sample (1 m/s): the first new pose at row 1004.
  const FlaggedTrack track =
      flagged_track(4, 1081, [](int k) { return k <= 250 ? Vec3::Zero() : Vec3(0.004 * (k - 250), 0, 0); });
  ASSERT_EQ(track.position_m[1003], Vec3::Zero());
  ASSERT_EQ(track.position_m[1004], Vec3(0.004, 0, 0));
  ASSERT_EQ(track.fresh[1000], 1);
  ReplayDevice replay(track.time_s, track.position_m, 1.0, false, 5.0, track.fresh);
  std::string error;
  ASSERT_TRUE(replay.start(&error)) << error;
  DeviceSample s;
  for (int ms = 0; ms < 1000; ++ms) {  // held exactly, at rest, until the last still sample
    ASSERT_TRUE(replay.read(ms * kMs, &s));
    ASSERT_EQ(s.position_m, Vec3::Zero()) << "at " << ms << " ms";
    ASSERT_EQ(s.velocity_m_per_s, Vec3::Zero()) << "at " << ms << " ms";
  }
  ASSERT_TRUE(replay.read(1000 * kMs, &s));  // where the step starts
  EXPECT_EQ(s.position_m, Vec3::Zero());
  ASSERT_TRUE(replay.read(1002 * kMs, &s));  // half way through the first step: 4 mm over 4 ms
  EXPECT_NEAR((s.position_m - Vec3(0.002, 0, 0)).norm(), 0.0, 1e-12);
  EXPECT_NEAR((s.velocity_m_per_s - Vec3(1.0, 0, 0)).norm(), 0.0, 1e-9);
  ASSERT_TRUE(replay.read(1010 * kMs, &s));  // and on at 1 m/s
  EXPECT_NEAR((s.position_m - Vec3(0.010, 0, 0)).norm(), 0.0, 1e-12);

  ReplayDevice unflagged(track.time_s, track.position_m, 1.0, false, 5.0);  // an old file: three periods
  ASSERT_TRUE(unflagged.start(&error)) << error;
  ASSERT_TRUE(unflagged.read(0, &s));
  ASSERT_TRUE(unflagged.read(1000 * kMs, &s));
  EXPECT_NEAR((s.position_m - Vec3(0.004 * 8.0 / 12.0, 0, 0)).norm(), 0.0, 1e-12);
  EXPECT_NEAR((s.velocity_m_per_s - Vec3(0.004 / 0.012, 0, 0)).norm(), 0.0, 1e-9);
}

// Before the device's first sample the loop had no hand: it read no sample
// (the device was lost from its first tick, no force) and judged the first
// one against nothing; the rows hold the device origin. The replay plays
// those rows as no samples, as it plays a lost gap, up to the first sample:
// held at that sample's pose from the first row, they played a live hand the
// loop never had, with forces. Nor does it invent a sweep from the origin
// (0.313 m in 52 ms would be 6 m/s, too fast to play at all).
TEST(ReplayDevice, WithFreshFlagsTheRowsBeforeTheFirstSamplePlayAsNoSamples) {
  const config::DeviceSpec spec = no_model_device_spec();
  FlaggedTrack track = flagged_track(4, 200, [](int k) { return Vec3(0.3 + 1e-3 * k, 0, 0); });
  for (int row = 0; row < 52; ++row) {  // the device came at row 52
    track.position_m[row] = Vec3::Zero();
    track.fresh[row] = 0;
  }
  ReplayDevice replay(track.time_s, track.position_m, 1.0, false, 5.0, track.fresh, spec.limits.device_timeout_s);
  std::string error;
  ASSERT_TRUE(replay.start(&error)) << error;
  EXPECT_EQ(replay.lost_gaps(), 1u) << "the rows before the first sample";
  DeviceSample s;
  for (const std::int64_t ns : {std::int64_t{0}, kMs, 30 * kMs, 51 * kMs, 52 * kMs - 1})
    EXPECT_FALSE(replay.read(ns, &s)) << "before the first sample, at " << ns << " ns: " << s.position_m.transpose();
  ASSERT_TRUE(replay.read(52 * kMs, &s)) << "the first sample";
  EXPECT_EQ(s.position_m, track.position_m[52]);
  ASSERT_TRUE(replay.read(58 * kMs, &s));
  EXPECT_NEAR(s.position_m.x(), 0.3 + 1e-3 * 14.5, 1e-12);

  // Through the loop: no sample on its first 52 ticks (row 0..51), then the
  // hand, none of it rejected.
  ReplayDevice driven(track.time_s, track.position_m, 1.0, false, 5.0, track.fresh, spec.limits.device_timeout_s);
  ASSERT_TRUE(driven.start(&error)) << error;
  const HapticStats st = replay_through_the_loop(driven, spec, 250);
  EXPECT_EQ(st.missing_samples, 52u);
  EXPECT_EQ(st.rejected_speed, 0u);
}

// A looping replay whose recording began before the device's first sample:
// at each wrap it goes from the last position it plays to no samples (the
// rows before the first sample, as on the first pass), then to the first
// sample. The loop holds the last sample it accepted (and loses the device
// once the timeout passes) and judges that first sample against it over the
// wall time since: the rows without a sample / speed. Not a one-tick jump
// (held at the first sample from the first row, it was one, and warned
// about as one), and not nothing (the loop's very first sample, judged
// against nothing, comes on the first pass only).
TEST(ReplayDevice, AWrapThroughTheRowsBeforeTheFirstSampleIsJudgedOverThem) {
  const config::DeviceSpec spec = no_model_device_spec();
  ASSERT_EQ(spec.limits.max_speed_m_per_s, 5.0);
  ASSERT_EQ(spec.limits.device_timeout_s, 0.01);
  // 250 Hz, along y at 1.25 m/s from x = 0.3 m; the device came at row 52
  // (sample 13), the last sample (49) at row 196, held to row 199.
  FlaggedTrack track = flagged_track(4, 200, [](int k) { return Vec3(0.3, 5e-3 * k, 0); });
  for (int row = 0; row < 52; ++row) {
    track.position_m[row] = Vec3::Zero();
    track.fresh[row] = 0;
  }
  const Vec3 first_sample_m = track.position_m[52], last_m = track.position_m.back();
  ASSERT_GT((last_m - track.position_m.front()).norm(), 0.3) << "the raw rows' wrap, from the origin";
  ReplayDevice looping(track.time_s, track.position_m, 1.0, true, 5.0, track.fresh, spec.limits.device_timeout_s);
  EXPECT_EQ(looping.loop_wrap_jump_m(), 0.0) << "not started: no knots, nothing played";
  EXPECT_EQ(looping.loop_wrap_no_sample_s(), 0.0) << "not started";
  std::string error;
  ASSERT_TRUE(looping.start(&error)) << error;
  // From the last sample, held to the end, back to the first sample (not to
  // the origin), over the 52 ms before it.
  EXPECT_NEAR(looping.loop_wrap_jump_m(), (last_m - first_sample_m).norm(), 1e-15);
  EXPECT_NEAR(looping.loop_wrap_jump_m(), 0.18, 1e-12);
  EXPECT_NEAR(looping.loop_wrap_no_sample_s(), 0.052, 1e-12);
  DeviceSample s;
  EXPECT_FALSE(looping.read(0, &s)) << "the first pass starts without a sample too";
  ASSERT_TRUE(looping.read(199 * kMs, &s));  // the last row
  EXPECT_EQ(s.position_m, last_m);
  for (const int ms : {200, 225, 250})  // wrapped to 1, 26 and 51 ms into the track
    EXPECT_FALSE(looping.read(ms * kMs, &s))
        << "wrapped to before the first sample, at " << ms << " ms: " << s.position_m.transpose();
  ASSERT_TRUE(looping.read(252 * kMs + kMs / 2, &s)) << "53.5 ms into the track";
  EXPECT_NEAR((s.position_m - Vec3(0.3, 5e-3 * (13 + 1.5 / 4), 0)).norm(), 0.0, 1e-12);

  // 0.18 m over 52 ms is 3.5 m/s: the loop takes it, and the daemon does
  // not warn (in one tick it would be 180 m/s).
  EXPECT_EQ(
      loop_wrap_warning("device.replay.loop", looping.loop_wrap_jump_m(), 5.0, 1000.0, looping.loop_wrap_no_sample_s()),
      "");
  ReplayDevice driven(track.time_s, track.position_m, 1.0, true, 5.0, track.fresh, spec.limits.device_timeout_s);
  ASSERT_TRUE(driven.start(&error)) << error;
  const HapticStats st = replay_through_the_loop(driven, spec, 4 * 199 + 60);  // five passes, four wraps
  EXPECT_EQ(st.rejected_speed, 0u);
  EXPECT_GE(st.missing_samples, 5u * 51u) << "the rows before the first sample, on every pass";
  EXPECT_EQ(st.device_lost_trips, 5u) << "52 ms without a sample is past the 10 ms timeout, on every pass";

  // At twice the speed the 52 ms pass in 26 ms of wall time: 6.9 m/s. The
  // daemon warns, and the loop does reject the sample after the wrap.
  ReplayDevice twice(track.time_s, track.position_m, 2.0, true, 5.0, track.fresh, spec.limits.device_timeout_s);
  ASSERT_TRUE(twice.start(&error)) << error;  // the hand itself: 2.5 m/s
  EXPECT_NEAR(twice.loop_wrap_no_sample_s(), 0.026, 1e-12) << "wall time";
  EXPECT_NE(
      loop_wrap_warning("device.replay.loop", twice.loop_wrap_jump_m(), 5.0, 1000.0, twice.loop_wrap_no_sample_s()),
      "");
  EXPECT_GE(replay_through_the_loop(twice, spec, 2 * 100 + 10).rejected_speed, 1u);

  ReplayDevice once(track.time_s, track.position_m, 1.0, false, 5.0, track.fresh, spec.limits.device_timeout_s);
  ASSERT_TRUE(once.start(&error)) << error;
  EXPECT_EQ(once.loop_wrap_jump_m(), 0.0) << "it holds the last position: no wrap";
  EXPECT_EQ(once.loop_wrap_no_sample_s(), 0.0) << "no wrap";
  ReplayDevice still({0.0, 0.0}, {Vec3(0.1, 0, 0), Vec3(0.2, 0, 0)}, 1.0, true);
  ASSERT_TRUE(still.start(&error)) << error;
  EXPECT_EQ(still.loop_wrap_jump_m(), 0.0) << "no duration: read() holds one position, never wraps";
}

// A looping track with a sample on its first row wraps in one tick, from the
// last position read() plays to that sample, as ever.
TEST(ReplayDevice, TheLoopWrapJumpIsFromTheLastPlayedPositionToTheFirstSample) {
  const FlaggedTrack track = flagged_track(4, 200, [](int k) { return Vec3(0.3, 1e-3 * k, 0); });
  ReplayDevice looping(track.time_s, track.position_m, 1.0, true, 5.0, track.fresh, 0.01);
  std::string error;
  ASSERT_TRUE(looping.start(&error)) << error;
  EXPECT_NEAR(looping.loop_wrap_jump_m(), 0.049, 1e-12);  // sample 49 back to sample 0
  EXPECT_EQ(looping.loop_wrap_no_sample_s(), 0.0) << "in one tick";
  DeviceSample before, after;
  ASSERT_TRUE(looping.read(0, &before));
  ASSERT_TRUE(looping.read(199 * kMs, &before));  // the last row
  ASSERT_TRUE(looping.read(200 * kMs, &after));   // wrapped to 1 ms into the track
  EXPECT_EQ(before.position_m, track.position_m.back());
  EXPECT_NEAR((after.position_m - Vec3(0.3, 0.25e-3, 0)).norm(), 0.0, 1e-12);
}

// A row whose position changed is a new sample whatever its flag says: the
// recorder drops rows when its ring overflows, and the flagged row may be
// among them. The step to it is spread over the time since the last sample.
TEST(ReplayDevice, WithFreshFlagsAPositionChangeOnAnUnflaggedRowIsStillASample) {
  // One 10 mm step, at sample 5 (row 20).
  FlaggedTrack track = flagged_track(4, 41, [](int k) { return Vec3(k >= 5 ? 0.01 : 0.0, 0, 0); });
  track.fresh[20] = 0;  // its flag lost: the change at row 20 still counts
  ReplayDevice replay(track.time_s, track.position_m, 1.0, false, 5.0, track.fresh);
  std::string error;
  ASSERT_TRUE(replay.start(&error)) << error;
  DeviceSample s;
  ASSERT_TRUE(replay.read(0, &s));
  ASSERT_TRUE(replay.read(18 * kMs, &s));  // from the sample at row 16, over 4 ms (not on to row 24)
  EXPECT_NEAR(s.position_m.x(), 0.005, 1e-12);
  ASSERT_TRUE(replay.read(20 * kMs, &s));
  EXPECT_NEAR(s.position_m.x(), 0.01, 1e-12);
}

TEST(ReplayDevice, FreshFlagsOfAnotherLengthThanTheTrackAreRefusedAtStart) {
  std::string error;
  ReplayDevice d({0.0, 1e-3, 2e-3}, {Vec3::Zero(), Vec3::Zero(), Vec3::Zero()}, 1.0, false, 5.0, {1, 0});
  EXPECT_FALSE(d.start(&error));
  EXPECT_NE(error.find("2 device_fresh flags for 3 rows"), std::string::npos) << error;
  DeviceSample s;
  EXPECT_FALSE(d.read(0, &s)) << "not started";
}

// A session whose device never delivered a sample (every device_fresh flag
// 0, the rows holding the device origin): live the loop never had a hand.
// Played, the origin was a live hand for the whole track; start() refuses it.
TEST(ReplayDevice, WithFreshFlagsATrackWithNoSampleIsRefusedAtStart) {
  const std::vector<double> time_s{0.0, 1e-3, 2e-3, 3e-3};
  const std::vector<Vec3> position_m(4, Vec3::Zero());
  ReplayDevice replay(time_s, position_m, 1.0, false, 5.0, {0, 0, 0, 0}, 0.01);
  std::string error;
  EXPECT_FALSE(replay.start(&error));
  EXPECT_NE(error.find("replay device: the track has no device sample"), std::string::npos) << error;
  EXPECT_NE(error.find("/haptic/device_fresh"), std::string::npos) << error;
  DeviceSample s;
  EXPECT_FALSE(replay.read(0, &s)) << "not started";
  // One flagged row is enough; without flags (an old file) the rule is unchanged.
  ReplayDevice one(time_s, position_m, 1.0, false, 5.0, {0, 0, 1, 0}, 0.01);
  EXPECT_TRUE(one.start(&error)) << error;
  ReplayDevice unflagged(time_s, position_m, 1.0, false, 5.0);
  EXPECT_TRUE(unflagged.start(&error)) << error;
}

// A 250 Hz device that sent nothing for 2 s (samples 26..524 lost), the hand
// 0.2 m away when it came back. Live the loop lost the device 10 ms into the
// gap (device.limits.device_timeout_s), ramped the force out, and took the
// next sample whatever the jump. Spread over the gap, the replay swept the
// hand those 0.2 m over 2 s at full force and never lost the device.
FlaggedTrack two_second_outage() {
  return flagged_track(
      4, 2400, [](int k) { return k <= 25 ? Vec3(0.1, 0, 0) : Vec3(0.1, 0.2, 0); },
      [] {
        std::vector<int> lost;
        for (int k = 26; k <= 524; ++k) lost.push_back(k);
        return lost;
      }());
}

TEST(ReplayDevice, WithFreshFlagsAGapLongerThanTheDeviceTimeoutPlaysAsNoSamples) {
  const config::DeviceSpec spec = no_model_device_spec();
  ASSERT_EQ(spec.limits.device_timeout_s, 0.01);
  const FlaggedTrack track = two_second_outage();
  ASSERT_EQ(track.fresh[100], 1);   // sample 25, the last before the gap
  ASSERT_EQ(track.fresh[2100], 1);  // sample 525, the first after it
  ASSERT_EQ(std::count(track.fresh.begin() + 101, track.fresh.begin() + 2100, 1), 0);
  ReplayDevice replay(track.time_s, track.position_m, 1.0, false, spec.limits.max_speed_m_per_s, track.fresh,
                      spec.limits.device_timeout_s);
  std::string error;
  ASSERT_TRUE(replay.start(&error)) << error;
  EXPECT_EQ(replay.lost_gaps(), 1u);
  DeviceSample s;
  ASSERT_TRUE(replay.read(0, &s));
  ASSERT_TRUE(replay.read(99 * kMs, &s));
  EXPECT_EQ(s.position_m, Vec3(0.1, 0, 0));
  // The sample that starts the gap came live at its tick: the first read at
  // or after it hands it over (once), then nothing (it was withheld: the
  // loop lost the device one tick early).
  ASSERT_TRUE(replay.read(100 * kMs + kMs / 2, &s)) << "the sample that starts the gap";
  EXPECT_EQ(s.position_m, Vec3(0.1, 0, 0));
  EXPECT_FALSE(replay.read(100 * kMs + 3 * kMs / 4, &s)) << "that sample is handed over once";
  for (const int ms : {101, 500, 1100, 2099})
    EXPECT_FALSE(replay.read(ms * kMs, &s)) << "inside the 2 s gap, at " << ms << " ms: " << s.position_m.transpose();
  ASSERT_TRUE(replay.read(2101 * kMs, &s)) << "the sample after the gap";
  EXPECT_EQ(s.position_m, Vec3(0.1, 0.2, 0));
  EXPECT_TRUE(s.velocity_m_per_s.isZero(0.0));

  // Through the loop: the device is lost over the gap, as live, and the jump
  // after it is taken (judged over the whole gap), not rejected.
  ReplayDevice driven(track.time_s, track.position_m, 1.0, false, spec.limits.max_speed_m_per_s, track.fresh,
                      spec.limits.device_timeout_s);
  ASSERT_TRUE(driven.start(&error)) << error;
  const HapticStats st = replay_through_the_loop(driven, spec, 2300);
  EXPECT_GE(st.device_lost_trips, 1u);
  EXPECT_GE(st.missing_samples, 1900u);
  EXPECT_EQ(st.rejected_speed, 0u);
}

// One lost packet at 250 Hz is 8 ms without a sample: under the 10 ms device
// timeout the loop kept the device live and measured the step over the 8 ms,
// so the replay still spreads it over the gap. Played at half speed the same
// gap lasts 16 ms, longer than the timeout, and still glides: the gap was not
// lost live, so it is lost at no speed (the glide gives the loop a sample
// every tick, so it never loses the device over it).
TEST(ReplayDevice, WithFreshFlagsAGapShorterThanTheDeviceTimeoutStillGlides) {
  const FlaggedTrack track = flagged_track(4, 200, [](int k) { return Vec3(1e-3 * k, 0, 0); }, {25});
  ASSERT_EQ(track.fresh[96], 1);
  ASSERT_EQ(track.fresh[100], 0);
  ASSERT_EQ(track.fresh[104], 1);
  ReplayDevice real_time(track.time_s, track.position_m, 1.0, false, 5.0, track.fresh, 0.01);
  std::string error;
  ASSERT_TRUE(real_time.start(&error)) << error;
  EXPECT_EQ(real_time.lost_gaps(), 0u);
  DeviceSample s;
  ASSERT_TRUE(real_time.read(0, &s));
  ASSERT_TRUE(real_time.read(100 * kMs, &s)) << "half way through the 8 ms gap";
  EXPECT_NEAR(s.position_m.x(), 0.025, 1e-12);  // sample 24 (24 mm) to 26 (26 mm) over 96..104 ms
  EXPECT_NEAR(s.velocity_m_per_s.x(), 0.25, 1e-9);

  ReplayDevice half_speed(track.time_s, track.position_m, 0.5, false, 5.0, track.fresh, 0.01);
  ASSERT_TRUE(half_speed.start(&error)) << error;
  EXPECT_EQ(half_speed.lost_gaps(), 0u);
  ASSERT_TRUE(half_speed.read(0, &s));
  ASSERT_TRUE(half_speed.read(200 * kMs, &s)) << "100 ms into the track, half way through the gap";
  EXPECT_NEAR(s.position_m.x(), 0.025, 1e-12);
  EXPECT_NEAR(s.velocity_m_per_s.x(), 0.125, 1e-9);  // 0.25 m/s at half speed
  ASSERT_TRUE(half_speed.read(209 * kMs, &s));       // 104.5 ms in: an eighth of the way from sample 26 to 27
  EXPECT_NEAR(s.position_m.x(), 0.026125, 1e-12);
  const config::DeviceSpec spec = no_model_device_spec();
  ASSERT_EQ(spec.limits.device_timeout_s, 0.01);
  ReplayDevice driven(track.time_s, track.position_m, 0.5, false, 5.0, track.fresh, spec.limits.device_timeout_s);
  ASSERT_TRUE(driven.start(&error)) << error;
  const HapticStats st = replay_through_the_loop(driven, spec, 2 * 200 + 10);
  EXPECT_EQ(st.device_lost_trips, 0u);
  EXPECT_EQ(st.missing_samples, 0u);
}

// Whether a gap was lost is what the live loop saw, whatever the replay's
// speed: a 250 Hz device with no lost packets kept the device at every tick
// live. Judged on the playback gap (gap / speed), every 4 ms sample period
// played at a quarter speed was a 16 ms "outage", longer than the 10 ms
// timeout, and the replay played with no device at all.
TEST(ReplayDevice, WithFreshFlagsASlowReplayOfA250HzTrackKeepsTheDevice) {
  const config::DeviceSpec spec = no_model_device_spec();
  ASSERT_EQ(spec.limits.device_timeout_s, 0.01);
  // 1 m/s: 4 mm a sample, 0.2 m in 50 samples, none lost.
  const FlaggedTrack track = flagged_track(4, 201, [](int k) { return Vec3(-0.1 + 4e-3 * k, 0, 0); });
  ReplayDevice replay(track.time_s, track.position_m, 0.25, false, spec.limits.max_speed_m_per_s, track.fresh,
                      spec.limits.device_timeout_s);
  std::string error;
  ASSERT_TRUE(replay.start(&error)) << error;
  EXPECT_EQ(replay.lost_gaps(), 0u);
  const HapticStats st = replay_through_the_loop(replay, spec, 4 * 201 + 10);
  EXPECT_EQ(st.device_lost_trips, 0u);
  EXPECT_EQ(st.missing_samples, 0u);
  EXPECT_EQ(st.rejected_speed, 0u);
}

// The boundary, on a 1 kHz device: live the loop declared the device lost at
// a tick more than device_timeout_s after the last sample. Ten samples lost
// in a row is an 11 ms gap, but its last tick without a sample came 10 ms
// after the last one, not more: the loop kept the device, and the replay
// glides. Eleven lost samples: 11 ms without one at the last tick, lost.
TEST(ReplayDevice, WithFreshFlagsAGapIsLostWhenItsLastTickWithoutASampleWasPastTheTimeout) {
  const auto lost_run = [](int from, int count) {
    std::vector<int> lost;
    for (int k = from; k < from + count; ++k) lost.push_back(k);
    return lost;
  };
  const auto pose = [](int k) { return Vec3(1e-4 * k, 0, 0); };  // 0.1 m/s
  std::string error;
  DeviceSample s;
  for (const int first : {50, 1003, 2717}) {  // where 1e-3 * rows rounds either way
    const FlaggedTrack ten = flagged_track(1, first + 40, pose, lost_run(first, 10));
    ReplayDevice kept(ten.time_s, ten.position_m, 1.0, false, 5.0, ten.fresh, 0.01);
    ASSERT_TRUE(kept.start(&error)) << error;
    EXPECT_EQ(kept.lost_gaps(), 0u) << "ten lost from sample " << first;
    ASSERT_TRUE(kept.read(0, &s));
    EXPECT_TRUE(kept.read((first + 5) * kMs, &s)) << "inside the 11 ms gap: glided, from sample " << first;

    const FlaggedTrack eleven = flagged_track(1, first + 40, pose, lost_run(first, 11));
    ReplayDevice lost(eleven.time_s, eleven.position_m, 1.0, false, 5.0, eleven.fresh, 0.01);
    ASSERT_TRUE(lost.start(&error)) << error;
    EXPECT_EQ(lost.lost_gaps(), 1u) << "eleven lost from sample " << first;
    ASSERT_TRUE(lost.read(0, &s));
    EXPECT_FALSE(lost.read((first + 5) * kMs, &s)) << "inside the 12 ms gap: no samples, from sample " << first;
  }
}

// A track that ends more than the device timeout after its last sample: live
// the device had stopped, and the loop lost it for the rest of the track.
// Held at the last pose, the replay played a live hand there (forces on a
// hand that was gone) to the end. It plays that tail as no samples, and a
// looping replay makes no one-tick jump at the wrap (the loop has lost the
// device by then and judges the first sample over the whole tail).
TEST(ReplayDevice, WithFreshFlagsATailLongerThanTheDeviceTimeoutPlaysAsNoSamples) {
  const config::DeviceSpec spec = no_model_device_spec();
  ASSERT_EQ(spec.limits.device_timeout_s, 0.01);
  const auto pose = [](int k) { return Vec3(-0.1 + 4e-3 * k, 0, 0); };  // 1 m/s
  std::vector<int> stopped;
  for (int k = 26; k < 50; ++k) stopped.push_back(k);
  // The last sample (25) at row 100, the track on to row 199.
  const FlaggedTrack track = flagged_track(4, 200, pose, stopped);
  ReplayDevice once(track.time_s, track.position_m, 1.0, false, 5.0, track.fresh, spec.limits.device_timeout_s);
  std::string error;
  ASSERT_TRUE(once.start(&error)) << error;
  EXPECT_EQ(once.lost_gaps(), 1u);
  DeviceSample s;
  ASSERT_TRUE(once.read(0, &s));
  ASSERT_TRUE(once.read(99 * kMs, &s));
  EXPECT_NEAR(s.position_m.x(), -0.1 + 4e-3 * 24.75, 1e-12);
  for (const int ms : {101, 150, 199, 250})
    EXPECT_FALSE(once.read(ms * kMs, &s)) << "in the tail, at " << ms << " ms: " << s.position_m.transpose();
  ReplayDevice driven(track.time_s, track.position_m, 1.0, false, 5.0, track.fresh, spec.limits.device_timeout_s);
  ASSERT_TRUE(driven.start(&error)) << error;
  const HapticStats st = replay_through_the_loop(driven, spec, 300);
  EXPECT_GE(st.device_lost_trips, 1u);
  EXPECT_GE(st.missing_samples, 199u);

  ReplayDevice looping(track.time_s, track.position_m, 1.0, true, 5.0, track.fresh, spec.limits.device_timeout_s);
  ASSERT_TRUE(looping.start(&error)) << error;
  // At the wrap the loop judges the first sample against the last one over
  // the tail (99 ms), not over one tick.
  EXPECT_NEAR(looping.loop_wrap_jump_m(), 0.1, 1e-12) << "the last sample (25) back to the first";
  EXPECT_NEAR(looping.loop_wrap_no_sample_s(), 0.099, 1e-12);
  ASSERT_TRUE(looping.read(0, &s));
  EXPECT_FALSE(looping.read(150 * kMs, &s));
  ASSERT_TRUE(looping.read(200 * kMs, &s)) << "wrapped to 1 ms in";
  EXPECT_NEAR(s.position_m.x(), -0.1 + 1e-3, 1e-12);

  // Ending 10 ms after the last sample, the loop still had the device at the
  // last tick: held. 11 ms after: lost.
  for (const int rows : {111, 112}) {
    FlaggedTrack cut = track;
    cut.time_s.resize(rows);
    cut.position_m.resize(rows);
    cut.fresh.resize(rows);
    ReplayDevice replay(cut.time_s, cut.position_m, 1.0, false, 5.0, cut.fresh, spec.limits.device_timeout_s);
    ASSERT_TRUE(replay.start(&error)) << error;
    EXPECT_EQ(replay.lost_gaps(), rows == 111 ? 0u : 1u) << rows << " rows";
    ASSERT_TRUE(replay.read(0, &s));
    EXPECT_EQ(replay.read(105 * kMs, &s), rows == 111) << rows << " rows";
    EXPECT_EQ(replay.read(200 * kMs, &s), rows == 111) << rows << " rows, past the end";
  }
}

// A gap played as no samples is measured by start()'s speed check as the
// loop judges the sample that ends it: against the last sample before the
// gap, over the wall time since (gap / speed), the same as a glide over it.
// Left out, a speed at which the loop rejects that sample was accepted. A
// looping track that ends on such a gap makes no one-tick jump at the wrap.
TEST(ReplayDevice, AGapPlayedAsNoSamplesIsMeasuredOverTheWholeGapNotByTheLoopWrap) {
  const config::DeviceSpec spec = no_model_device_spec();
  ASSERT_EQ(spec.limits.max_speed_m_per_s, 5.0);
  // 0.08 m in the 20 ms of four lost packets: 4 m/s, which the live loop took.
  const FlaggedTrack track =
      flagged_track(4, 141, [](int k) { return k < 30 ? Vec3(0, 0, 0) : Vec3(0.08, 0, 0); }, {30, 31, 32, 33});
  std::string error;
  ReplayDevice lost(track.time_s, track.position_m, 1.0, true, 5.0, track.fresh, 0.01);
  ASSERT_TRUE(lost.start(&error)) << error;
  EXPECT_EQ(lost.lost_gaps(), 1u);
  EXPECT_NEAR(lost.loop_wrap_jump_m(), 0.08, 1e-15) << "the last sample back to the first";
  EXPECT_EQ(lost.loop_wrap_no_sample_s(), 0.0) << "in one tick: the track ends on a sample, held";
  // At 1.5 times real time the sample after the gap comes 13.3 ms of wall
  // time after the one before: 6 m/s. Refused, lost or glided alike.
  for (const double timeout_s : {0.01, std::numeric_limits<double>::infinity()}) {
    ReplayDevice fast(track.time_s, track.position_m, 1.5, false, 5.0, track.fresh, timeout_s);
    EXPECT_FALSE(fast.start(&error)) << "timeout " << timeout_s;
    EXPECT_NE(error.find("its peak 4 m/s"), std::string::npos) << error;
  }
  // ... which is exactly when the loop rejects it.
  ReplayDevice unchecked(track.time_s, track.position_m, 1.5, false, std::numeric_limits<double>::infinity(),
                         track.fresh, 0.01);
  ASSERT_TRUE(unchecked.start(&error)) << error;
  EXPECT_GE(replay_through_the_loop(unchecked, spec, 120).rejected_speed, 1u);
  ReplayDevice allowed(track.time_s, track.position_m, 1.2, false, 5.0, track.fresh, 0.01);
  ASSERT_TRUE(allowed.start(&error)) << error;
  const HapticStats st = replay_through_the_loop(allowed, spec, 130);
  EXPECT_EQ(st.rejected_speed, 0u);
  EXPECT_GE(st.device_lost_trips, 1u) << "16.7 ms of wall time without a sample";

  // The track ends on the sample after the gap: read() gives nothing before
  // the wrap, so no jump happens in one tick.
  FlaggedTrack ends_on_gap = track;
  ends_on_gap.time_s.resize(137);
  ends_on_gap.position_m.resize(137);
  ends_on_gap.fresh.resize(137);
  ASSERT_EQ(ends_on_gap.fresh.back(), 1);
  ReplayDevice wraps_after_gap(ends_on_gap.time_s, ends_on_gap.position_m, 1.0, true, 5.0, ends_on_gap.fresh, 0.01);
  ASSERT_TRUE(wraps_after_gap.start(&error)) << error;
  // The loop judges the first sample against the one before the gap (both
  // at the origin) over the 20 ms gap: read() never plays the sample that
  // ends it, on the last row.
  EXPECT_EQ(wraps_after_gap.loop_wrap_jump_m(), 0.0);
  EXPECT_NEAR(wraps_after_gap.loop_wrap_no_sample_s(), 0.020, 1e-12);
  DeviceSample s;
  ASSERT_TRUE(wraps_after_gap.read(0, &s));
  EXPECT_FALSE(wraps_after_gap.read(135 * kMs, &s)) << "the last milliseconds before the wrap are the gap";
  ASSERT_TRUE(wraps_after_gap.read(137 * kMs, &s)) << "wrapped to 1 ms in";
  EXPECT_EQ(s.position_m, Vec3::Zero());
}

// A hole the recorder left (record::HapticHole): `track` without its rows
// [first, first + count), dropped when the recorder's ring overflowed. The
// rows that remain keep their times, so the hole is a jump in them, and the
// session's hole event names the row after it (rows_after_holes).
struct HoledTrack {
  FlaggedTrack track;
  std::vector<std::size_t> rows_after_holes;
};
HoledTrack with_hole(const FlaggedTrack& full, int first, int count) {
  HoledTrack holed;
  for (int row = 0; row < static_cast<int>(full.time_s.size()); ++row) {
    if (row >= first && row < first + count) continue;
    holed.track.time_s.push_back(full.time_s[row]);
    holed.track.position_m.push_back(full.position_m[row]);
    holed.track.fresh.push_back(full.fresh[row]);
  }
  holed.rows_after_holes = {static_cast<std::size_t>(first)};
  return holed;
}

// A still hand on a healthy 250 Hz device (the pose re-sent every 4 ms),
// recorded while the disk stalled: the recorder dropped 50 ms of rows. Live
// the loop had a sample every 4 ms throughout. The rows after the hole until
// the next flagged one made the gap look like 50-odd ms without a sample, so
// the replay played it as a lost device (a device-lost trip, the force
// ramped out) whenever the row after the hole was not flagged: 3 of the 4
// places the hole can fall in the device's cadence. The ticks in the hole
// are unknown, so only the rows present are judged.
TEST(ReplayDevice, AHoleTheRecorderLeftIsNotPlayedAsALostDevice) {
  const config::DeviceSpec spec = no_model_device_spec();
  ASSERT_EQ(spec.limits.device_timeout_s, 0.01);
  const Vec3 still_m(0.05, 0.02, -0.01);
  const FlaggedTrack full = flagged_track(4, 400, [&](int) { return still_m; });
  std::string error;
  DeviceSample s;
  int lost_without_holes = 0;
  for (const int first : {200, 201, 202, 203}) {
    SCOPED_TRACE("the hole from row " + std::to_string(first));
    const HoledTrack holed = with_hole(full, first, 50);
    const FlaggedTrack& t = holed.track;
    ReplayDevice unaware(t.time_s, t.position_m, 1.0, false, 5.0, t.fresh, spec.limits.device_timeout_s);
    ASSERT_TRUE(unaware.start(&error)) << error;
    lost_without_holes += static_cast<int>(unaware.lost_gaps());

    ReplayDevice replay(t.time_s, t.position_m, 1.0, false, 5.0, t.fresh, spec.limits.device_timeout_s,
                        holed.rows_after_holes);
    ASSERT_TRUE(replay.start(&error)) << error;
    EXPECT_EQ(replay.lost_gaps(), 0u);
    // Every tick has the still pose: held across the hole as across any
    // gap between samples the loop kept the device over.
    for (int ms = 0; ms < 400; ++ms) {
      ASSERT_TRUE(replay.read(ms * kMs, &s)) << "at " << ms << " ms";
      ASSERT_EQ(s.position_m, still_m) << "at " << ms << " ms";
    }
    ReplayDevice driven(t.time_s, t.position_m, 1.0, false, 5.0, t.fresh, spec.limits.device_timeout_s,
                        holed.rows_after_holes);
    ASSERT_TRUE(driven.start(&error)) << error;
    const HapticStats st = replay_through_the_loop(driven, spec, 410);
    EXPECT_EQ(st.device_lost_trips, 0u);
    EXPECT_EQ(st.missing_samples, 0u);
  }
  // The scenario is the one that went wrong: without the holes, the replay
  // took 3 of the 4 for a lost device.
  EXPECT_EQ(lost_without_holes, 3);
}

// A real device loss beside a hole is still one: the rows present without a
// sample count, only the time in the hole does not. The still hand of the
// test above, its device lost before the hole (a sample right after it),
// after it, and on both sides, 9 ms before and 7 ms after (16 ms without a
// sample on the rows present, over the 10 ms timeout, though each side alone
// is under it). Each loss comes where the rows present pass the timeout:
// before the hole, the hole lies inside the loss and plays as no samples;
// after it or across it, the last sample is held over the hole (its time
// does not count) and the loss comes after it. (A moving hand whose samples
// came in the hole shows a new position on the row after it: a sample, so a
// loss after the hole starts there.)
TEST(ReplayDevice, ADeviceLossBesideAHoleIsStillPlayedAsALoss) {
  const config::DeviceSpec spec = no_model_device_spec();
  ASSERT_EQ(spec.limits.device_timeout_s, 0.01);
  const Vec3 still_m(0.05, 0.02, -0.01);
  const auto pose = [&](int) { return still_m; };
  const auto samples = [](int from, int to) {
    std::vector<int> lost;
    for (int k = from; k <= to; ++k) lost.push_back(k);
    return lost;
  };
  struct Case {
    const char* name;
    std::vector<int> lost;  // samples (every 4th row) that never came
    int no_sample_ms;       // a tick of the loss on the rows present
    int next_sample_ms;     // the sample that ends the loss
    bool hole_in_loss;      // the rows before the hole passed the timeout
  };
  // The hole: rows 202..251 (a sample was due at 204 ... 248); 51 ms between
  // rows 201 and 252, left out. After it the last sample (200 ms) is held
  // to 251 ms, lost from 261 ms; across it (192 ms) held to 243, lost from
  // 253 ms, as the rows present pass the timeout at 262 and 254 ms.
  const Case cases[] = {
      {"before the hole", samples(45, 50), 190, 252, true},
      {"after the hole", samples(63, 67), 260, 272, false},
      {"across the hole", samples(49, 64), 255, 260, false},
  };
  std::string error;
  DeviceSample s;
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    const HoledTrack holed = with_hole(flagged_track(4, 400, pose, c.lost), 202, 50);
    const FlaggedTrack& t = holed.track;
    ReplayDevice replay(t.time_s, t.position_m, 1.0, false, 5.0, t.fresh, spec.limits.device_timeout_s,
                        holed.rows_after_holes);
    ASSERT_TRUE(replay.start(&error)) << error;
    EXPECT_EQ(replay.lost_gaps(), 1u);
    ASSERT_TRUE(replay.read(0, &s));
    // In time order (read() plays forwards): a tick of the loss on a row
    // present, and one in the hole, inside the loss or held.
    for (const int ms : {std::min(c.no_sample_ms, 230), std::max(c.no_sample_ms, 230)}) {
      if (ms == 230)
        EXPECT_EQ(replay.read(ms * kMs, &s), !c.hole_in_loss) << "in the hole";
      else
        EXPECT_FALSE(replay.read(ms * kMs, &s)) << "at " << ms << " ms";
    }
    ASSERT_TRUE(replay.read(c.next_sample_ms * kMs, &s)) << "the sample after the loss";
    EXPECT_EQ(s.position_m, still_m);
    ReplayDevice driven(t.time_s, t.position_m, 1.0, false, 5.0, t.fresh, spec.limits.device_timeout_s,
                        holed.rows_after_holes);
    ASSERT_TRUE(driven.start(&error)) << error;
    EXPECT_GE(replay_through_the_loop(driven, spec, 410).device_lost_trips, 1u);
  }
}

// A loss across a hole starts where live it did, not a hole's length early.
// The time in a hole does not count toward the timeout, so live the loop
// lost the device once the rows present without a sample passed it; the
// replay, which loses the device a timeout after the last sample read()
// hands over, must hand the pose over for as long as the holes before that
// point last. Before, read() gave nothing from just after the sample that
// starts the gap: the loss began inside the hole, up to a hole's length
// early. A 1 kHz device (a sample every row), timeout 10 ms, sample at 0 ms,
// the rows of its later samples lost up to `next_sample_ms`, and 50 rows
// dropped (the hole: 51 ms between the rows on either side, all left out).
TEST(ReplayDevice, ALossAcrossAHoleStartsWhereTheRowsPresentPassTheTimeout) {
  const config::DeviceSpec spec = no_model_device_spec();
  ASSERT_EQ(spec.limits.device_timeout_s, 0.01);
  const Vec3 still_m(0.05, 0.02, -0.01);
  struct Case {
    const char* name;
    int hole_first_row;  // rows [first, first + 50) dropped
    int next_sample_ms;  // the sample that ends the loss
    int live_lost_ms;    // the first row present past the timeout, holes left out
  };
  const Case cases[] = {
      // Rows 51..62 present without a sample: 11 ms counted at 62.
      {"the sample right before the hole", 1, 63, 62},
      // Rows 1..5 and 56..70 without a sample: 5 + 6 = 11 ms counted at 62.
      {"rows without a sample before the hole too", 6, 71, 62},
  };
  std::string error;
  DeviceSample s;
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    std::vector<int> lost;
    for (int k = 1; k < c.next_sample_ms; ++k) lost.push_back(k);
    const HoledTrack holed = with_hole(flagged_track(
                                           1, 200, [&](int) { return still_m; }, lost),
                                       c.hole_first_row, 50);
    const FlaggedTrack& t = holed.track;
    ReplayDevice replay(t.time_s, t.position_m, 1.0, false, 5.0, t.fresh, spec.limits.device_timeout_s,
                        holed.rows_after_holes);
    ASSERT_TRUE(replay.start(&error)) << error;
    EXPECT_EQ(replay.lost_gaps(), 1u);
    // The loop loses the device the timeout after the last sample handed
    // over; live that was at live_lost_ms, so the pose comes up to the
    // timeout before it and nothing from the tick after until the next
    // sample.
    const int last_given_ms = c.live_lost_ms - 11;
    int no_sample_ticks = 0, first_no_sample_ms = -1;
    for (int ms = 0; ms < 200; ++ms) {
      if (replay.read(ms * kMs, &s)) {
        EXPECT_EQ(s.position_m, still_m) << "at " << ms << " ms";
        continue;
      }
      if (first_no_sample_ms < 0) first_no_sample_ms = ms;
      ++no_sample_ticks;
    }
    EXPECT_EQ(first_no_sample_ms, last_given_ms + 1);
    EXPECT_EQ(no_sample_ticks, c.next_sample_ms - last_given_ms - 1);
    ReplayDevice driven(t.time_s, t.position_m, 1.0, false, 5.0, t.fresh, spec.limits.device_timeout_s,
                        holed.rows_after_holes);
    ASSERT_TRUE(driven.start(&error)) << error;
    EXPECT_EQ(replay_through_the_loop(driven, spec, 210).device_lost_trips, 1u);
  }
}

// The holes are rows of the track: one outside it, or out of order, is a
// caller's mistake, refused at start().
TEST(ReplayDevice, HolesOutsideTheTrackAreRefusedAtStart) {
  const FlaggedTrack t = flagged_track(4, 40, [](int) { return Vec3::Zero(); });
  std::string error;
  for (const std::vector<std::size_t>& holes : {std::vector<std::size_t>{0}, std::vector<std::size_t>{40},
                                                std::vector<std::size_t>{20, 10}, std::vector<std::size_t>{10, 10}}) {
    ReplayDevice replay(t.time_s, t.position_m, 1.0, false, 5.0, t.fresh, 0.01, holes);
    EXPECT_FALSE(replay.start(&error)) << ::testing::PrintToString(holes);
    EXPECT_NE(error.find("recorder hole"), std::string::npos) << error;
  }
  ReplayDevice fine(t.time_s, t.position_m, 1.0, false, 5.0, t.fresh, 0.01, {1, 39});
  EXPECT_TRUE(fine.start(&error)) << error;
}

}  // namespace
}  // namespace tissue::haptics
