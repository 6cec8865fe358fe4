// Session replay (daemon/replay): the timeline, pacing against a fake clock
// (no sleeping), the conversions, the row reader's errors on bad files, and
// `tissue session replay` end to end. The CLI cases publish to LCM's
// in-process memq:// provider (no network). The ReplayNetns cases need
// TISSUE_TEST_LCM_URL and run through the ctest entry inside a private
// network namespace (tests/transport/in_netns.sh): a subscriber in this
// process receives what the replay process publishes.
#include "replay/session_replay.hpp"

#include <gtest/gtest.h>

#include <signal.h>
#include <sys/wait.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <lcm/lcm-cpp.hpp>
#include <limits>
#include <optional>
#include <thread>

#include "record/session_writer.hpp"
#include "record_test_support.hpp"
#include "replay_test_support.hpp"
#include "support/loopback_listener.hpp"
#include "transport/lcm_messages.hpp"

namespace tissue::replay {
namespace {

using record::testing::quote;
using record::testing::RunResult;
using record::testing::TempDir;
using testing::FakeClock;
using testing::RecordingSink;
using testing::VectorFrameSource;

// ---------------------------------------------------------------- timeline

TEST(ReplayTimeline, MergesTheStreamsInTimeOrderMeshFirstAtEqualTimes) {
  TimelineOptions o;
  o.haptic_rate_hz = 0;
  o.stats_rate_hz = 0;
  const auto items = build_timeline({0.0, 0.5, 1.0}, {0.0, 0.25, 0.5, 0.75}, {0.1, 0.5}, o);
  const std::vector<TimelineItem> expected = {
      {0.0, StreamKind::kMesh, 0},    {0.0, StreamKind::kHaptic, 0},  {0.1, StreamKind::kStats, 0},
      {0.25, StreamKind::kHaptic, 1}, {0.5, StreamKind::kMesh, 1},    {0.5, StreamKind::kHaptic, 2},
      {0.5, StreamKind::kStats, 1},   {0.75, StreamKind::kHaptic, 3}, {1.0, StreamKind::kMesh, 2}};
  EXPECT_EQ(items, expected);
}

TEST(ReplayTimeline, WindowIsInclusiveAndApplesToEveryStream) {
  TimelineOptions o;
  o.haptic_rate_hz = 0;
  o.stats_rate_hz = 0;
  o.from_s = 0.5;
  o.to_s = 0.75;
  const auto items = build_timeline({0.0, 0.5, 1.0}, {0.25, 0.5, 0.75, 0.8}, {0.1, 0.6}, o);
  const std::vector<TimelineItem> expected = {{0.5, StreamKind::kMesh, 1},
                                              {0.5, StreamKind::kHaptic, 1},
                                              {0.6, StreamKind::kStats, 1},
                                              {0.75, StreamKind::kHaptic, 2}};
  EXPECT_EQ(items, expected);
}

TEST(ReplayTimeline, DecimatesKiloHertzRowsToThePublishRate) {
  std::vector<double> haptic;
  for (int i = 0; i < 1000; ++i) haptic.push_back(i * 1e-3);  // as the recorder stores 1 kHz ticks
  std::vector<double> sim;
  for (int i = 0; i < 50; ++i) sim.push_back(i * 0.02);
  TimelineOptions o;  // 100 Hz haptic, 5 Hz stats
  const auto items = build_timeline({}, haptic, sim, o);
  std::vector<std::size_t> h, s;
  for (const TimelineItem& it : items) (it.kind == StreamKind::kHaptic ? h : s).push_back(it.index);
  ASSERT_EQ(h.size(), 100u);
  for (std::size_t k = 0; k < h.size(); ++k) EXPECT_EQ(h[k], 10 * k) << "every 10th tick";
  EXPECT_EQ(s, (std::vector<std::size_t>{0, 10, 20, 30, 40}));
  // After a gap the grid restarts at the first row after it.
  const auto gap = build_timeline({}, {0.0, 0.01, 0.5, 0.505, 0.51}, {}, o);
  std::vector<double> times;
  for (const TimelineItem& it : gap) times.push_back(it.time_s);
  EXPECT_EQ(times, (std::vector<double>{0.0, 0.01, 0.5, 0.51}));
}

TEST(ReplayTimeline, BadOptionsAreErrors) {
  TimelineOptions o;
  o.from_s = 2.0;
  o.to_s = 1.0;
  EXPECT_THROW(build_timeline({0.0}, {}, {}, o), ReplayError);
  o = {};
  o.haptic_rate_hz = -1.0;
  EXPECT_THROW(build_timeline({0.0}, {}, {}, o), ReplayError);
}

// The refusal shows the options as given: two ends that differ never read
// the same ("--from 0.000000 --to 0.000000" said %f), a huge one is not 300
// digits long.
TEST(ReplayTimeline, ARefusedWindowOrRateShowsTheNumbersAsGiven) {
  const auto message = [](const TimelineOptions& o) {
    try {
      build_timeline({0.0}, {}, {}, o);
    } catch (const ReplayError& e) {
      return std::string(e.what());
    }
    ADD_FAILURE() << "accepted";
    return std::string();
  };
  TimelineOptions o;
  o.from_s = 1e-7;
  o.to_s = 0.0;
  EXPECT_NE(message(o).find("window --from 1e-07 --to 0:"), std::string::npos) << message(o);
  o.from_s = 1e300;
  EXPECT_NE(message(o).find("window --from 1e+300 --to 0:"), std::string::npos) << message(o);
  o = {};
  o.haptic_rate_hz = -1e-9;
  EXPECT_NE(message(o).find("haptic rate -1e-09 Hz"), std::string::npos) << message(o);
}

// The window is inclusive at both ends, so one instant (from == to) is a
// window too: it holds the items at exactly that time.
TEST(ReplayTimeline, AWindowOfOneInstantHoldsTheItemsAtThatTime) {
  TimelineOptions o;
  o.haptic_rate_hz = 0;
  o.stats_rate_hz = 0;
  o.from_s = o.to_s = 0.5;
  const auto items = build_timeline({0.0, 0.5, 1.0}, {0.25, 0.5, 0.75}, {0.1, 0.6}, o);
  const std::vector<TimelineItem> expected = {{0.5, StreamKind::kMesh, 1}, {0.5, StreamKind::kHaptic, 1}};
  EXPECT_EQ(items, expected);
}

// A rate must be a finite number >= 0 (0: every row); an infinite or NaN
// rate is a mistyped option, refused naming the stream.
TEST(ReplayTimeline, ARateThatIsNotAFiniteNumberIsRefusedNamingTheStream) {
  for (const double bad : {std::numeric_limits<double>::infinity(), std::numeric_limits<double>::quiet_NaN()}) {
    TimelineOptions o;
    o.haptic_rate_hz = bad;
    try {
      build_timeline({0.0}, {0.0}, {}, o);
      ADD_FAILURE() << "haptic rate " << bad << " accepted";
    } catch (const ReplayError& e) {
      EXPECT_NE(std::string(e.what()).find("haptic rate"), std::string::npos) << e.what();
    }
    o = {};
    o.stats_rate_hz = bad;
    try {
      build_timeline({0.0}, {}, {0.0}, o);
      ADD_FAILURE() << "stats rate " << bad << " accepted";
    } catch (const ReplayError& e) {
      EXPECT_NE(std::string(e.what()).find("stats rate"), std::string::npos) << e.what();
    }
  }
}

// ---------------------------------------------------------------- pacing

// Frames at 0, 0.1, ... 0.9 s; haptic rows every 10 ms; stats every 50 ms.
struct Material {
  VectorFrameSource frames{testing::moving_frames(10, 0.1)};
  SessionRows rows = testing::rows(100, 0.01, 20, 0.05);
};

TEST(ReplayPacing, EveryItemGoesOutAtItsDueTimeAtSpeedOne) {
  Material m;
  FakeClock clock(1000.0);
  RecordingSink sink(&clock);
  std::atomic<bool> stop{false};
  ReplayOptions o;
  o.timeline.haptic_rate_hz = 0;
  o.timeline.stats_rate_hz = 0;
  const ReplaySummary s = replay_session(m.frames, m.rows, o, sink, clock, stop);
  EXPECT_EQ(s.frames, 10u);
  EXPECT_EQ(s.haptic_rows, 100u);
  EXPECT_EQ(s.stats, 20u);
  EXPECT_EQ(s.passes, 1u);
  EXPECT_FALSE(s.stopped);
  EXPECT_EQ(s.late_items, 0u);
  ASSERT_EQ(sink.sent.size(), 130u);
  for (const auto& e : sink.sent) EXPECT_NEAR(e.wall_s - 1000.0, e.time_s, 1e-9) << "item at t=" << e.time_s;
  EXPECT_DOUBLE_EQ(s.session_span_s, 0.99);
  EXPECT_NEAR(s.wall_s, 0.99, 1e-9);
  EXPECT_NEAR(s.pace(), 1.0, 1e-9);
  // Mesh sequences count up from 1 and the frames are the source's.
  std::uint64_t seq = 0;
  for (const auto& e : sink.sent)
    if (e.kind == StreamKind::kMesh) {
      EXPECT_EQ(e.sequence, ++seq);
      EXPECT_EQ(e.vertices, m.frames.frame(seq - 1).vertices_m.size());
    }
}

TEST(ReplayPacing, SpeedFourTakesAQuarterOfTheTimeAndTheWindowStartsAtOnce) {
  Material m;
  FakeClock clock(50.0);
  RecordingSink sink(&clock);
  std::atomic<bool> stop{false};
  ReplayOptions o;
  o.speed = 4.0;
  o.timeline.from_s = 0.25;
  o.timeline.to_s = 0.75;
  const ReplaySummary s = replay_session(m.frames, m.rows, o, sink, clock, stop);
  EXPECT_EQ(s.frames, 5u);  // 0.3 .. 0.7
  ASSERT_FALSE(sink.sent.empty());
  const double t0 = sink.sent.front().time_s, t1 = sink.sent.back().time_s;
  EXPECT_GE(t0, 0.25);
  EXPECT_LE(t1, 0.75);
  EXPECT_DOUBLE_EQ(sink.sent.front().wall_s, 50.0) << "no wait before the first item of the window";
  for (const auto& e : sink.sent) EXPECT_NEAR(e.wall_s - 50.0, (e.time_s - t0) / 4.0, 1e-9);
  EXPECT_NEAR(s.wall_s, (t1 - t0) / 4.0, 1e-9);
  EXPECT_GT(t1 - t0, 0.45);
  EXPECT_NEAR(s.pace(), 4.0, 1e-9);
}

TEST(ReplayPacing, ASlowPublishDelaysOnlyTheItemsRightAfterIt) {
  Material m;
  FakeClock clock(0.0);
  RecordingSink sink(&clock);
  sink.mesh_cost_s = {{4, 0.25}};  // publishing frame 3 (t = 0.3 s, sequence 4) takes 250 ms
  std::atomic<bool> stop{false};
  ReplayOptions o;
  o.timeline.haptic_rate_hz = 0;
  o.timeline.stats_rate_hz = 0;
  const ReplaySummary s = replay_session(m.frames, m.rows, o, sink, clock, stop);
  const auto slow = std::find_if(sink.sent.begin(), sink.sent.end(), [](const auto& e) { return e.sequence == 4; });
  ASSERT_NE(slow, sink.sent.end());
  const double free_at_s = slow->wall_s + 0.25;
  for (auto e = sink.sent.begin(); e != sink.sent.end(); ++e) {
    if (e <= slow)
      EXPECT_NEAR(e->wall_s, e->time_s, 1e-12) << "before the slow frame: on time";
    else if (e->time_s < free_at_s)
      EXPECT_NEAR(e->wall_s, free_at_s, 1e-12) << "held up by the slow frame, sent at once after it";
    else
      EXPECT_NEAR(e->wall_s, e->time_s, 1e-12) << "back on the original schedule";
  }
  EXPECT_GT(s.late_items, 20u);  // haptic rows 0.31 .. 0.54 and more
  EXPECT_GT(s.max_lag_s, 0.2);
  EXPECT_LE(s.max_lag_s, 0.25 + 1e-9);
}

// "Items sent more than 10 ms after their due time" are late: a publish of
// 5 ms delays the items right after it a little, and none of them is late.
TEST(ReplayPacing, ALagOfTenMillisecondsOrLessIsNotCountedLate) {
  Material m;
  FakeClock clock(0.0);
  RecordingSink sink(&clock);
  sink.mesh_cost_s = {{4, 0.005}};
  std::atomic<bool> stop{false};
  ReplayOptions o;
  o.timeline.haptic_rate_hz = 0;
  o.timeline.stats_rate_hz = 0;
  const ReplaySummary s = replay_session(m.frames, m.rows, o, sink, clock, stop);
  EXPECT_NEAR(s.max_lag_s, 0.005, 1e-9) << "the items right after the slow frame lag";
  EXPECT_EQ(s.late_items, 0u);
}

// speed is a number from 1e-3 to 1e6: infinity would send everything at
// once, and 1e-300 made the second item due in 1e299 s (a wait for ever).
TEST(ReplayPacing, AnInfiniteOrNanSpeedIsRefused) {
  Material m;
  FakeClock clock(0.0);
  RecordingSink sink(&clock);
  std::atomic<bool> stop{false};
  for (const double bad : {std::numeric_limits<double>::infinity(), std::numeric_limits<double>::quiet_NaN(), 1e-300,
                           1e300, 0.999e-3, 1.001e6}) {
    ReplayOptions o;
    o.speed = bad;
    EXPECT_THROW(replay_session(m.frames, m.rows, o, sink, clock, stop), ReplayError) << bad;
  }
  EXPECT_TRUE(sink.sent.empty());
  for (const double good : {kMinSpeed, kMaxSpeed}) {
    ReplayOptions o;
    o.speed = good;
    EXPECT_GT(replay_session(m.frames, m.rows, o, sink, clock, stop).frames, 0u) << good;
  }
}

TEST(ReplayPacing, LoopStartsTheNextPassWhenTheLastEndsUntilStopped) {
  Material m;
  FakeClock clock(0.0);
  RecordingSink sink(&clock);
  std::atomic<bool> stop{false};
  sink.stop_after = 25;  // 10 frames per pass: stop in the third pass
  sink.stop = &stop;
  ReplayOptions o;
  o.loop = true;
  o.timeline.haptic_rate_hz = 0;
  o.timeline.stats_rate_hz = 0;
  o.timeline.to_s = 0.9;  // frames, rows and stats up to 0.9 s: the span is 0.9 s
  const ReplaySummary s = replay_session(m.frames, m.rows, o, sink, clock, stop);
  EXPECT_TRUE(s.stopped);
  EXPECT_EQ(s.passes, 2u);
  std::vector<const RecordingSink::Sent*> meshes;
  for (const auto& e : sink.sent)
    if (e.kind == StreamKind::kMesh) meshes.push_back(&e);
  ASSERT_GE(meshes.size(), 21u);
  EXPECT_DOUBLE_EQ(meshes[10]->wall_s, 0.9) << "pass 2 starts where pass 1 ended";
  EXPECT_DOUBLE_EQ(meshes[20]->wall_s, 1.8);
  EXPECT_EQ(meshes[20]->sequence, 21u) << "sequences keep counting across passes";
  EXPECT_EQ(s.frames, meshes.size());
}

// `stopped` says the replay was cut short. A single pass whose stop request
// comes while its last item goes out has sent everything: it ended by its
// end, and says so (a caller reporting "stopped" would claim items were lost).
TEST(ReplayPacing, AStopDuringTheLastItemOfAPassWithoutLoopIsNotAStop) {
  Material m;
  m.rows = testing::rows(90, 0.01, 18, 0.05);  // rows end before the last frame (0.9 s): it is the last item
  FakeClock clock(0.0);
  RecordingSink sink(&clock);
  std::atomic<bool> stop{false};
  sink.stop_after = 10;  // the 10th and last frame of the pass
  sink.stop = &stop;
  ReplayOptions o;
  o.timeline.haptic_rate_hz = 0;
  o.timeline.stats_rate_hz = 0;
  const ReplaySummary s = replay_session(m.frames, m.rows, o, sink, clock, stop);
  EXPECT_EQ(s.frames, 10u);
  EXPECT_EQ(s.passes, 1u);
  EXPECT_FALSE(s.stopped) << "every item was sent";
  // Looping, the same request ends the replay before a second pass: a stop.
  std::atomic<bool> stop2{false};
  RecordingSink sink2(&clock);
  sink2.stop_after = 10;
  sink2.stop = &stop2;
  o.loop = true;
  const ReplaySummary looped = replay_session(m.frames, m.rows, o, sink2, clock, stop2);
  EXPECT_EQ(looped.passes, 1u);
  EXPECT_TRUE(looped.stopped);
}

TEST(ReplayPacing, StopEndsAWaitAndBadOptionsAreRefused) {
  Material m;
  FakeClock clock(0.0);
  RecordingSink sink(&clock);
  std::atomic<bool> stop{true};
  ReplaySummary s = replay_session(m.frames, m.rows, ReplayOptions{}, sink, clock, stop);
  EXPECT_TRUE(s.stopped);
  EXPECT_TRUE(sink.sent.empty());
  stop = false;
  ReplayOptions o;
  o.speed = 0.0;
  EXPECT_THROW(replay_session(m.frames, m.rows, o, sink, clock, stop), ReplayError);
  o = {};
  o.timeline.from_s = 5.0;  // after everything
  EXPECT_THROW(replay_session(m.frames, m.rows, o, sink, clock, stop), ReplayError);
  o = {};
  o.loop = true;
  o.timeline.from_s = o.timeline.to_s = 0.5;  // one instant: a loop would never advance
  EXPECT_THROW(replay_session(m.frames, m.rows, o, sink, clock, stop), ReplayError);
}

// A window with nothing in it is said with the window as given and the
// span of the session's frames and rows, so the user sees where to look. It
// said only "nothing to replay (no frame or row in the window)".
TEST(ReplayPacing, AWindowWithNothingInItSaysTheWindowAndTheSessionsSpan) {
  Material m;  // frames 0 .. 0.9 s, haptic rows 0 .. 0.99 s, sim rows 0 .. 0.95 s
  FakeClock clock(0.0);
  RecordingSink sink(&clock);
  std::atomic<bool> stop{false};
  const auto message = [&](std::optional<double> from_s, std::optional<double> to_s) {
    ReplayOptions o;
    o.timeline.from_s = from_s;
    o.timeline.to_s = to_s;
    try {
      replay_session(m.frames, m.rows, o, sink, clock, stop);
    } catch (const ReplayError& e) {
      return std::string(e.what());
    }
    ADD_FAILURE() << "replayed";
    return std::string();
  };
  const std::string span = ": the session's frames and rows are from t=0 s to t=0.99 s";
  EXPECT_EQ(message(5.0, 6.0), "'test frames': nothing to replay in the window --from 5 --to 6" + span);
  EXPECT_EQ(message(5.0, std::nullopt), "'test frames': nothing to replay in the window --from 5" + span);
  EXPECT_EQ(message(std::nullopt, -1e-7), "'test frames': nothing to replay in the window --to -1e-07" + span);
  EXPECT_TRUE(sink.sent.empty());
}

// A loop over a window a picosecond long advanced its due time by nothing
// (a clock at 1e5 s absorbs 1e-12 s): it published every item at once, for
// ever. A pass must last 1 ms of wall time.
TEST(ReplayPacing, ALoopOfLessThanAMillisecondPerPassIsRefused) {
  x3d::SurfaceFrame a = testing::moving_frames(1, 0.0).front();
  a.time_s = 0.5;
  x3d::SurfaceFrame b = a;
  b.time_s = 0.5 + 0x1p-40;  // 9.09e-13 s later, exactly
  testing::VectorFrameSource frames({a, b});
  FakeClock clock(1e5);
  RecordingSink sink(&clock);
  std::atomic<bool> stop{false};
  sink.stop_after = 50;
  sink.stop = &stop;
  ReplayOptions o;
  o.loop = true;
  try {
    replay_session(frames, SessionRows{}, o, sink, clock, stop);
    ADD_FAILURE() << "looped; sent " << sink.sent.size() << " items";
  } catch (const ReplayError& e) {
    EXPECT_EQ(std::string(e.what()),
              "'test frames': --loop needs a pass of at least 1 ms of wall time: the window spans 9.09495e-13 s of "
              "session time, 9.09495e-13 s at speed 1");
  }
  EXPECT_TRUE(sink.sent.empty());
  // The same 1 ms at speed 1000 takes a second of session time.
  b.time_s = 1.5;
  testing::VectorFrameSource second({a, b});
  o.speed = 1000.0;
  std::atomic<bool> stop2{false};
  RecordingSink sink2(&clock);
  sink2.stop_after = 50;
  sink2.stop = &stop2;
  const double start_s = clock.now_s();
  const ReplaySummary s = replay_session(second, SessionRows{}, o, sink2, clock, stop2);
  EXPECT_TRUE(s.stopped);
  ASSERT_EQ(sink2.sent.size(), 50u);
  // Due times from the start, pass by pass: pass p's first frame at p ms.
  for (std::size_t k = 0; k < sink2.sent.size(); ++k)
    EXPECT_DOUBLE_EQ(sink2.sent[k].wall_s, start_s + 1e-3 * static_cast<double>((k + 1) / 2)) << k;
}

// A hole the recorder left in /haptic (ticks it dropped, its ring full) is
// a stretch without rows: the replay sends no haptic_state over it, and a
// viewer sees the hand stop there with nothing to tell it from a still hand
// or a lost device, though live the hand moved on. So the replay says so
// where it reaches one: the sink hears the hole right after the last haptic
// state before it (when the stream stops), and the summary counts the holes
// crossed and the session time they span. A hole the window does not reach
// across is not announced. Before, nothing said it.
TEST(ReplayPacing, AHoleTheRecorderLeftIsAnnouncedWhereTheStreamStops) {
  VectorFrameSource frames{{}};
  SessionRows rows = testing::rows(100, 0.001, 0, 0.0);
  // Rows 0..49 at 0..49 ms, then 30 ticks dropped: row 50 is at 80 ms.
  for (std::size_t i = 50; i < rows.haptic.size(); ++i) rows.haptic[i].time_s += 0.030;
  rows.haptic_holes = {record::HapticHole{30, 50, rows.haptic[49].time_s, rows.haptic[50].time_s}};
  FakeClock clock(10.0);
  RecordingSink sink(&clock);
  std::atomic<bool> stop{false};
  ReplayOptions o;  // 100 Hz: rows 0, 10, .., 40, then 50 (80 ms)
  const ReplaySummary s = replay_session(frames, rows, o, sink, clock, stop);
  ASSERT_EQ(sink.holes.size(), 1u);
  EXPECT_EQ(sink.holes[0].hole.row_after, 50u);
  EXPECT_EQ(sink.holes[0].hole.ticks_lost, 30u);
  const std::size_t k = sink.holes[0].after_sent;
  ASSERT_GE(k, 1u);
  ASSERT_LT(k, sink.sent.size());
  EXPECT_NEAR(sink.sent[k - 1].time_s, 0.040, 1e-12) << "heard after the last state before the hole";
  EXPECT_NEAR(sink.sent[k].time_s, 0.080, 1e-12) << "heard before the first state after the hole";
  EXPECT_EQ(s.haptic_holes, 1u);
  EXPECT_NEAR(s.haptic_hole_time_s, 0.031, 1e-12);

  // Every row sent: heard after row 49.
  RecordingSink every(&clock);
  o.timeline.haptic_rate_hz = 0;
  EXPECT_EQ(replay_session(frames, rows, o, every, clock, stop).haptic_holes, 1u);
  ASSERT_EQ(every.holes.size(), 1u);
  EXPECT_EQ(every.holes[0].after_sent, 50u);

  // A window that starts after the hole, or ends before it, does not cross it.
  for (const auto& [from_s, to_s] : {std::pair{0.081, 0.2}, std::pair{0.0, 0.049}}) {
    RecordingSink outside(&clock);
    o.timeline.from_s = from_s;
    o.timeline.to_s = to_s;
    EXPECT_EQ(replay_session(frames, rows, o, outside, clock, stop).haptic_holes, 0u) << from_s << " " << to_s;
    EXPECT_TRUE(outside.holes.empty()) << from_s << " " << to_s;
  }
}

// At the published haptic rate (100 Hz by default, a state every 10 ms) a
// hole only shows when a whole publish period passes with no state beyond
// the usual one: the states on either side of it 2 periods apart or more, a
// state the stream would carry missing. A hole no longer than a period never
// does that (the next state comes late by less than a period, as network
// jitter makes it), so it is not announced: before, each one printed a line
// (at every pass of a loop) though nothing could be seen. One of two periods
// or more always is.
TEST(ReplayPacing, AHoleThatLeavesNoStateMissingAtThePublishedRateIsNotAnnounced) {
  VectorFrameSource frames{{}};
  FakeClock clock(10.0);
  std::atomic<bool> stop{false};
  // Rows 0..99 at 1 ms; `ticks` dropped after row `before`.
  const auto holed = [](std::size_t before, std::uint64_t ticks) {
    SessionRows rows = testing::rows(100, 0.001, 0, 0.0);
    for (std::size_t i = before + 1; i < rows.haptic.size(); ++i)
      rows.haptic[i].time_s += 0.001 * static_cast<double>(ticks);
    rows.haptic_holes = {
        record::HapticHole{ticks, before + 1, rows.haptic[before].time_s, rows.haptic[before + 1].time_s}};
    return rows;
  };
  struct Case {
    std::size_t before;
    std::uint64_t ticks;
    bool announced;
    const char* why;
  };
  for (const Case& c : {
           // Row 50, due at 50 ms, is at 51 ms: states at 40 and 51 ms.
           Case{49, 1, false, "1 tick where a state is due: it comes 1 ms late"},
           // 49 -> 59 ms, one period, as late as it can fall: states at 40, 59 ms.
           Case{49, 9, false, "a hole of one period: the state due at 50 ms comes at 59 ms"},
           // 40 -> 60 ms, two periods, right after a state: states at 40, 60 ms.
           Case{40, 19, true, "a hole of two periods: the state due at 50 ms is missing"},
           Case{49, 30, true, "a hole of 31 ms"},
       }) {
    const SessionRows rows = holed(c.before, c.ticks);
    RecordingSink sink(&clock);
    ReplayOptions o;  // 100 Hz
    const ReplaySummary s = replay_session(frames, rows, o, sink, clock, stop);
    EXPECT_EQ(sink.holes.size(), c.announced ? 1u : 0u) << c.why;
    EXPECT_EQ(s.haptic_holes, c.announced ? 1u : 0u) << c.why;
    // Every row sent: any hole leaves states missing.
    RecordingSink every(&clock);
    o.timeline.haptic_rate_hz = 0;
    EXPECT_EQ(replay_session(frames, rows, o, every, clock, stop).haptic_holes, 1u) << c.why;
    EXPECT_EQ(every.holes.size(), 1u) << c.why;
  }
}

// A --from inside a hole: the replay starts with the other streams while no
// haptic state comes until the row after the hole, the same stop a viewer
// sees at a hole crossed, so the sink hears of it before the first item
// (at every pass). Before, nothing said it. A window that starts with that
// row leaves nothing missing and says nothing.
TEST(ReplayPacing, AWindowThatStartsInsideAHoleAnnouncesItAtTheStart) {
  VectorFrameSource frames{{}};
  // Haptic rows 0..49 at 0..49 ms, 30 ticks dropped, row 50 at 80 ms; sim
  // rows every 10 ms.
  SessionRows rows = testing::rows(100, 0.001, 20, 0.010);
  for (std::size_t i = 50; i < rows.haptic.size(); ++i) rows.haptic[i].time_s += 0.030;
  rows.haptic_holes = {record::HapticHole{30, 50, rows.haptic[49].time_s, rows.haptic[50].time_s}};
  FakeClock clock(10.0);
  std::atomic<bool> stop{false};
  ReplayOptions o;
  o.timeline.stats_rate_hz = 0;  // every sim row: the stats at 60 and 70 ms go out before row 50
  o.timeline.from_s = 0.060;
  RecordingSink sink(&clock);
  const ReplaySummary s = replay_session(frames, rows, o, sink, clock, stop);
  ASSERT_EQ(sink.holes.size(), 1u);
  EXPECT_EQ(sink.holes[0].hole.row_after, 50u);
  EXPECT_EQ(sink.holes[0].after_sent, 0u) << "heard before the first item";
  ASSERT_GE(sink.sent.size(), 3u);
  EXPECT_EQ(sink.sent[0].kind, StreamKind::kStats);
  EXPECT_EQ(s.haptic_holes, 1u);
  EXPECT_NEAR(s.haptic_hole_time_s, 0.031, 1e-12);

  // Only haptic rows in the window: it starts with row 50, nothing missing.
  o.timeline.stats_rate_hz = 5.0;
  SessionRows haptic_only = rows;
  haptic_only.sim.clear();
  RecordingSink at_once(&clock);
  EXPECT_EQ(replay_session(frames, haptic_only, o, at_once, clock, stop).haptic_holes, 0u);
  EXPECT_TRUE(at_once.holes.empty());
}

TEST(ReplayPacing, SteadyClockWaitEndsSoonAfterStop) {
  SteadyReplayClock clock;
  std::atomic<bool> stop{false};
  std::thread stopper([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    stop = true;
  });
  const double t0 = clock.now_s();
  EXPECT_FALSE(clock.wait_until(t0 + 30.0, stop));
  stopper.join();
  EXPECT_LT(clock.now_s() - t0, 5.0) << "a 30 s wait must end on stop, not run out";
  EXPECT_TRUE(clock.wait_until(clock.now_s() + 0.01, stop = false));
}

// ---------------------------------------------------------------- conversions

TEST(ReplayConversions, SnapshotCarriesTheFrameAndStrainWhenPresent) {
  x3d::SurfaceFrame f = testing::moving_frames(1, 0.1)[0];
  service::MeshSnapshot s = to_snapshot(f, 7);
  EXPECT_EQ(s.sequence, 7u);
  EXPECT_EQ(s.sim_time_s, f.time_s);
  EXPECT_EQ(s.vertices_m, f.vertices_m);
  EXPECT_EQ(s.triangles, f.triangles);
  EXPECT_EQ(s.vertex_level, f.vertex_level);
  EXPECT_TRUE(s.triangle_strain_energy_J_per_m3.empty()) << "no strain in the frame: none in the snapshot";
  f.vertex_strain_energy_Pa.resize(f.vertices_m.size());
  for (std::size_t i = 0; i < f.vertices_m.size(); ++i) f.vertex_strain_energy_Pa[i] = static_cast<float>(3 * i);
  s = to_snapshot(f, 8);
  ASSERT_EQ(s.triangle_strain_energy_J_per_m3.size(), f.triangles.size());
  for (std::size_t t = 0; t < f.triangles.size(); ++t) {
    const auto& tri = f.triangles[t];
    EXPECT_FLOAT_EQ(s.triangle_strain_energy_J_per_m3[t], static_cast<float>(tri[0] + tri[1] + tri[2]))
        << "only per-vertex strain: each triangle gets the mean of its vertices";
  }
  // A triangle naming a vertex without a value (a damaged frame) counts that
  // vertex as 0, never another vertex's value or memory past the array.
  {
    x3d::SurfaceFrame bad = f;
    bad.vertex_strain_energy_Pa[0] = 30.0f;
    bad.triangles[0] = {1, 2, static_cast<std::uint32_t>(bad.vertex_strain_energy_Pa.size())};
    const service::MeshSnapshot b = to_snapshot(bad, 10);
    EXPECT_FLOAT_EQ(b.triangle_strain_energy_J_per_m3[0], static_cast<float>((3.0 + 6.0 + 0.0) / 3.0));
  }
  // Per-triangle values present (next to the per-vertex ones): sent unchanged.
  f.triangle_strain_energy_J_per_m3 = record::testing::test_frame(0).triangle_strain_energy_J_per_m3;
  s = to_snapshot(f, 9);
  EXPECT_EQ(s.triangle_strain_energy_J_per_m3, f.triangle_strain_energy_J_per_m3);
  // And from a session file through the session source, as the replay reads
  // it: every frame's per-triangle strain is the recorded one, bit for bit.
  TempDir dir;
  auto source = x3d::open_session_source(testing::write_session(dir / "s.h5", 6));
  ASSERT_EQ(source->frame_count(), 6u);
  for (std::size_t k = 0; k < 6; ++k) {
    const record::testing::TestFrame recorded = record::testing::test_frame(k);
    s = to_snapshot(source->read_frame(k), k + 1);
    EXPECT_EQ(s.triangle_strain_energy_J_per_m3, recorded.triangle_strain_energy_J_per_m3) << "frame " << k;
  }
}

TEST(ReplayConversions, RowsBecomeTheStatusFieldsThePublishersRead) {
  const record::HapticRow h = record::testing::haptic_row(3);  // contact on (3 % 3 == 0)
  const service::SimStatus hs = haptic_status(h);
  EXPECT_EQ(hs.sim_time_s, h.time_s);
  EXPECT_EQ(hs.device_position_m, h.device_position_m);
  EXPECT_EQ(hs.proxy_position_m, h.proxy_position_m);
  EXPECT_EQ(hs.force_on_device_N, h.force_N);
  EXPECT_TRUE(hs.tool_contact);
  EXPECT_EQ(hs.model_version, h.model_version);
  EXPECT_FALSE(haptic_status(record::testing::haptic_row(4)).tool_contact);
  const record::SimRow r = record::testing::sim_row(9);
  const service::SimStatus ss = sim_status(r);
  EXPECT_EQ(ss.sim_time_s, r.time_s);
  EXPECT_EQ(ss.real_time_factor, r.real_time_factor);
  EXPECT_EQ(ss.step_ms_last, r.step_ms);
  EXPECT_EQ(ss.nodes, r.nodes);
  EXPECT_EQ(ss.tets, r.tets);
  EXPECT_EQ(ss.springs, r.springs);
  EXPECT_EQ(ss.refines, r.refines);
  EXPECT_EQ(ss.merges, r.merges);
  EXPECT_EQ(ss.kinetic_energy_J, r.kinetic_J);
  EXPECT_EQ(ss.elastic_energy_J, r.elastic_J);
}

// ---------------------------------------------------------------- files
// The rows themselves are read by record::read_session_rows (tested in
// tests/record/session_tools_test.cpp); replay turns its errors into
// ReplayError, which the CLI reports with exit code 1.

TEST(ReplayRows, BadFilesAreErrorsNamingTheFile) {
  TempDir dir;
  for (const std::string& path : record::testing::bad_session_files(dir)) {
    SCOPED_TRACE(path);
    try {
      read_session_rows(path);
      ADD_FAILURE() << "accepted " << path;
    } catch (const ReplayError& e) {
      EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
    }
  }
}

// ---------------------------------------------------------------- CLI (no network)

std::string tissue() { return quote(TISSUE_CLI_BINARY); }

TEST(ReplayCli, ReplaysEverythingAndPrintsTheSummary) {
  TempDir dir;
  const std::string path = testing::write_session(dir / "s.h5", 45);  // frames at 30 Hz: 1.467 s
  const RunResult r =
      record::testing::run(tissue() + " session replay " + quote(path) + " --lcm memq:// --speed 8", dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.err, "");
  // 45 frames; 1500 haptic rows at 1 kHz -> 150 at 100 Hz; 75 sim rows at 50 Hz -> 8 at 5 Hz.
  EXPECT_NE(r.out.find("replayed " + path + ": 45 mesh frames, 150 haptic states, 8 stats"), std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("LCM memq://: 45 meshes, 150 haptic states, 8 stats sent, 0 failures"), std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("(asked 8.000x)"), std::string::npos) << r.out;
}

// `tissue session replay` prints each recorder hole as it reaches it (no
// haptic_state goes out over it; a viewer sees the hand stop) and counts them
// in the summary; the holes come from the session's hole events.
TEST(ReplayCli, SaysWhereTheRecordedHapticRowsHaveAHole) {
  TempDir dir;
  const std::string path = dir / "holes.h5";
  {
    auto w = record::SessionWriter::create(path, record::SessionMetadata{});
    std::vector<record::HapticRow> rows;
    // Rows 49 and 50 are at 49 and 80 ms: 30 ticks dropped between them.
    for (std::uint64_t i = 0; i < 200; ++i) rows.push_back(record::testing::haptic_row(i < 50 ? i : i + 30));
    w->append_haptic(rows);
    const record::HapticHole hole{30, 50, rows[49].time_s, rows[50].time_s};
    const std::vector<record::Event> events = {
        record::Event::make(hole.time_before_s, record::EventKind::kWarning, record::haptic_hole_message(hole))};
    w->append_events(events);
    w->close();
  }
  ASSERT_EQ(record::read_session_rows(path).haptic_holes.size(), 1u);
  const RunResult r =
      record::testing::run(tissue() + " session replay " + quote(path) + " --lcm memq:// --speed 10", dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("hole: no haptic_state from t=0.049 s to t=0.080 s (0.031 s of session time): the recorder "
                       "dropped 30 haptic ticks there"),
            std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("1 recorder hole crossed (0.031 s without haptic rows)"), std::string::npos) << r.out;
}

// `--lcm`'s URL is optional: a FILE right after it is the FILE, published on
// the default URL (docs/replay-and-live.md), not taken as the URL, which left
// no FILE ("file is required", exit 2). Without the network: a bad file after
// `--lcm` is opened and reported (the file is read before any transport
// starts), and a URL-less value with a FILE beside it is an error naming it.
TEST(ReplayCli, AFileRightAfterLcmIsTheFileNotTheUrl) {
  TempDir dir;
  const std::string bad = dir / "not-a-session.h5";
  record::testing::write_bytes(bad, "not HDF5");
  RunResult r = record::testing::run(tissue() + " session replay --lcm " + quote(bad) + " --speed 100", dir);
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_EQ(r.err.rfind("tissue session replay: '" + bad + "': ", 0), 0u) << r.err;

  const std::string path = testing::write_session(dir / "s.h5", 5);
  r = record::testing::run(tissue() + " session replay --lcm memq:// " + quote(path) + " --speed 100", dir);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("LCM memq://: 5 meshes"), std::string::npos) << r.out;

  r = record::testing::run(tissue() + " session replay --lcm nourl " + quote(path), dir);
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find("--lcm: 'nourl' is not an LCM URL (PROVIDER://...)"), std::string::npos) << r.err;
  r = record::testing::run(tissue() + " session replay --lcm", dir);
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find("file is required"), std::string::npos) << r.err;
}

// A tcpq:// server that accepts and never greets (a web server, a typo'd
// port) is exit 3 within the greeting wait (10 s), not a hang: LCM's own
// client waits for the greeting without a limit. Bounded by timeout(1).
TEST(ReplayCli, ASilentTcpqServerIsACannotConnectExitNotAHang) {
  TempDir dir;
  const std::string path = testing::write_session(dir / "s.h5", 3);
  tissue::testing::LoopbackListener silent("");
  ASSERT_TRUE(silent.ok());
  const RunResult r =
      record::testing::run("timeout 60 " + tissue() + " session replay " + quote(path) + " --lcm " + silent.url(), dir);
  EXPECT_EQ(r.exit_code, 3) << r.err;
  EXPECT_NE(r.err.find(silent.url()), std::string::npos) << r.err;
}

// Ctrl-C while the probe waits for a silent tcpq:// server's greeting is a
// stop request like any other: the replay ends at once, exit 0, and says it
// stopped (it waited out the 10 s greeting wait and exited 3).
TEST(ReplayCli, AStopSignalWhileWaitingForATcpqServerStopsTheReplayAtOnce) {
  TempDir dir;
  const std::string path = testing::write_session(dir / "s.h5", 3);
  tissue::testing::LoopbackListener silent("");
  ASSERT_TRUE(silent.ok());
  tissue::testing::BackgroundProcess p({TISSUE_CLI_BINARY, "session", "replay", path, "--lcm", silent.url()},
                                       dir / "out", dir / "err");
  std::this_thread::sleep_for(std::chrono::seconds(1));
  ASSERT_TRUE(p.signal(SIGINT));
  const std::optional<int> status = p.wait_for_exit(60.0);
  ASSERT_TRUE(status.has_value());
  ASSERT_TRUE(WIFEXITED(*status)) << WTERMSIG(*status);
  EXPECT_EQ(WEXITSTATUS(*status), 0) << p.err();
  EXPECT_EQ(p.out(), "stopped: " + path + ": by SIGINT while waiting for the tcpq server at '" + silent.url() +
                         "' to answer; nothing was sent\n")
      << p.err();
}

// The same for a live `tissue x3d --timeout 600` against a silent tcpq://
// server: it waited out connection and greeting (up to 20 minutes) before
// it saw the request. A stop before the first frame: exit 4.
TEST(LiveCli, AStopSignalWhileWaitingForATcpqServerIsAStopBeforeTheFirstFrame) {
  TempDir dir;
  tissue::testing::LoopbackListener silent("");
  ASSERT_TRUE(silent.ok());
  tissue::testing::BackgroundProcess p(
      {TISSUE_CLI_BINARY, "x3d", "--lcm", silent.url(), "--timeout", "600", "-o", dir / "none.x3d"}, dir / "out",
      dir / "err");
  std::this_thread::sleep_for(std::chrono::seconds(1));
  ASSERT_TRUE(p.signal(SIGINT));
  const std::optional<int> status = p.wait_for_exit(30.0);
  ASSERT_TRUE(status.has_value()) << "still waiting 30 s after SIGINT";
  ASSERT_TRUE(WIFEXITED(*status)) << WTERMSIG(*status);
  EXPECT_EQ(WEXITSTATUS(*status), 4) << p.err();
  EXPECT_EQ(p.err(),
            "tissue x3d: stopped by SIGINT before any surface_mesh arrived on LCM channel "
            "TISSUE_SURFACE_MESH on " +
                silent.url() + "\n");
  EXPECT_FALSE(std::filesystem::exists(dir / "none.x3d"));
}

TEST(ReplayCli, BadFilesExitOneWithOneLineNamingTheFile) {
  TempDir dir, scratch;
  for (const std::string& path : record::testing::bad_session_files(dir)) {
    SCOPED_TRACE(path);
    const RunResult r = record::testing::run(tissue() + " session replay " + quote(path) + " --lcm memq://", scratch);
    EXPECT_EQ(r.exit_code, 1) << r.err;
    EXPECT_EQ(r.err.rfind("tissue session replay: '" + path + "': ", 0), 0u) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    EXPECT_EQ(r.err.find("HDF5-DIAG"), std::string::npos) << r.err;
  }
}

// A session with nothing in it is a data problem (exit 1, naming the file),
// not a bad window (exit 2): no option could make it replay.
TEST(ReplayCli, AnEmptySessionExitsOneNamingTheFile) {
  TempDir dir;
  record::testing::TestSession empty;
  empty.haptic = empty.sim = empty.frames = empty.events = 0;
  const std::string path = record::testing::write_test_session(dir / "empty.h5", empty);
  const RunResult r = record::testing::run(tissue() + " session replay " + quote(path) + " --lcm memq://", dir);
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.err.find("'" + path + "': nothing to replay"), std::string::npos) << r.err;
}

TEST(ReplayCli, BadArgumentsExitTwoAndBadTransportsExitThree) {
  TempDir dir;
  const std::string path = testing::write_session(dir / "s.h5", 5);
  const auto replay = [&](const std::string& args) {
    return record::testing::run(tissue() + " session replay " + quote(path) + " " + args, dir);
  };
  RunResult r = replay("");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("--lcm"), std::string::npos) << r.err;
  EXPECT_EQ(replay("--lcm memq:// --speed 0").exit_code, 2);
  // 1e-300 waited for ever for the second item; 1e300 sent everything at
  // once. (`timeout`: a regression fails instead of hanging the suite.)
  for (const char* speed : {"1e-300", "1e300", "0.0009", "1000001"}) {
    r = record::testing::run(
        "timeout 60 " + tissue() + " session replay " + quote(path) + " --lcm memq:// --speed " + speed, dir);
    EXPECT_EQ(r.exit_code, 2) << speed << ": " << r.err;
    EXPECT_NE(r.err.find(std::string("--speed: ") + speed + " is outside 0.001 to 1000000"), std::string::npos)
        << r.err;
  }
  EXPECT_EQ(replay("--lcm memq:// --dds-domain 3").exit_code, 2) << "--dds-domain needs --dds";
  // The DDS mesh limit (publish.dds.max_mesh_bytes, 8 MiB) could not be
  // raised: larger meshes were not sent, said only as "N failures". The
  // daemon's range: 64 KiB to 1 GiB.
  for (const char* bad : {"65535", "1073741825", "0x10000"}) {
    r = replay(std::string("--lcm memq:// --dds --dds-max-mesh-bytes ") + bad);
    EXPECT_EQ(r.exit_code, 2) << bad;
    EXPECT_EQ(r.err.rfind("--dds-max-mesh-bytes: ", 0), 0u) << bad << ": " << r.err;
  }
  r = replay("--lcm memq:// --dds-max-mesh-bytes 65536");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("--dds-max-mesh-bytes requires --dds"), std::string::npos) << r.err;
  r = replay("--lcm memq:// --from 9 --to 10");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("nothing to replay in the window --from 9 --to 10: the session's frames and rows are from t=0 s "
                       "to t="),
            std::string::npos)
      << r.err;
  // NaN passed --from / --to ("nothing to replay") and CLI::Range on
  // --dds-wait (every comparison with NaN is false, so the wait was skipped).
  for (const char* bad : {"--from nan", "--to nan", "--dds --dds-wait nan", "--haptic-rate nan", "--stats-rate inf"}) {
    r = replay(std::string("--lcm memq:// ") + bad);
    EXPECT_EQ(r.exit_code, 2) << bad;
    EXPECT_NE(r.err.find("not a finite number"), std::string::npos) << bad << ": " << r.err;
  }
  // A udpm URL the daemon's config would refuse is refused before LCM opens
  // it. (A loopback, ttl=0 URL: even a regression stays on this host.)
  r = replay("--lcm 'udpm://127.0.0.1:7667?ttl=0'");
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find("the group must be an IPv4 multicast address"), std::string::npos) << r.err;
  r = replay("--lcm nosuchprovider://x");
  EXPECT_EQ(r.exit_code, 3);
  EXPECT_NE(r.err.find("nosuchprovider://x"), std::string::npos) << r.err;
}

TEST(ReplayCli, SigtermStopsALoopCleanlyWithASummary) {
  TempDir dir;
  const std::string path = testing::write_session(dir / "s.h5", 45);
  const auto t0 = std::chrono::steady_clock::now();
  const RunResult r = record::testing::run(
      tissue() + " session replay " + quote(path) + " --lcm memq:// --loop & p=$!; sleep 2; kill -TERM $p; wait $p",
      dir);
  const double took_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.err, "");
  EXPECT_EQ(r.out.rfind("stopped: " + path + ": ", 0), 0u) << r.out;
  // How many passes fit in 2 s depends on the start-up time: only the summary's presence is checked.
  EXPECT_NE(r.out.find(" complete passes\n"), std::string::npos) << r.out;
  EXPECT_LT(took_s, 10.0);
}

// ---------------------------------------------------------------- network (private namespace)

// Arrival of one message at the in-process subscriber.
struct Arrival {
  double wall_s;
  double time_s;
  std::int64_t sequence;
  std::int32_t value;         // mesh: vertex_count; haptic: in_contact
  std::vector<float> strain;  // mesh: per triangle
};

// Filled by the LCM handlers, which run inside handleTimeout on the
// receiving thread.
struct Received {
  std::vector<Arrival> meshes, haptic;
};

double steady_now_s() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

void on_mesh(const lcm::ReceiveBuffer*, const std::string&, const tissue_lcm::tissue::surface_mesh* m, Received* r) {
  r->meshes.push_back(
      {steady_now_s(), m->time_s, m->sequence_number, m->vertex_count, m->triangle_strain_energy_density_J_per_m3});
}

void on_haptic(const lcm::ReceiveBuffer*, const std::string&, const tissue_lcm::tissue::haptic_state* m, Received* r) {
  r->haptic.push_back({steady_now_s(), m->time_s, m->sequence_number, m->in_contact ? 1 : 0, {}});
}

// Runs the replay CLI in the background while this thread receives.
Received replay_into_lcm(const std::string& url, const std::string& path, const std::string& args, RunResult* result) {
  lcm::LCM sub(url);
  EXPECT_TRUE(sub.good());
  Received got;
  sub.subscribeFunction(transport::kSurfaceMeshChannel, &on_mesh, &got);
  sub.subscribeFunction(transport::kHapticStateChannel, &on_haptic, &got);
  TempDir scratch;
  std::atomic<bool> done{false};
  std::thread replay([&] {
    *result = record::testing::run(tissue() + " session replay " + quote(path) + " --lcm " + quote(url) + " " + args,
                                   scratch);
    done = true;
  });
  while (!done) sub.handleTimeout(50);
  for (int i = 0; i < 5; ++i) sub.handleTimeout(50);  // anything still in flight
  replay.join();
  return got;
}

TEST(ReplayNetns, LcmDeliversEveryFrameInOrderAtTheRecordedPace) {
  const char* url = std::getenv("TISSUE_TEST_LCM_URL");
  if (!url) GTEST_SKIP() << "run through tests/transport/in_netns.sh (ctest does)";
  TempDir dir;
  constexpr std::uint64_t kFrames = 45;
  const std::string path = testing::write_session(dir / "s.h5", kFrames);
  const double recorded_span_s =
      record::testing::test_frame(kFrames - 1).time_s - record::testing::test_frame(0).time_s;

  double wall_span_s[2] = {};
  const double speeds[2] = {1.0, 4.0};
  for (int run = 0; run < 2; ++run) {
    SCOPED_TRACE("speed " + std::to_string(speeds[run]));
    RunResult r;
    Received got = replay_into_lcm(url, path, "--speed " + std::to_string(speeds[run]), &r);
    ASSERT_EQ(r.exit_code, 0) << r.err;
    ASSERT_EQ(got.meshes.size(), kFrames) << r.out;
    for (std::size_t k = 0; k < kFrames; ++k) {
      const record::testing::TestFrame f = record::testing::test_frame(k);
      EXPECT_EQ(got.meshes[k].sequence, static_cast<std::int64_t>(k + 1)) << "in order, none lost";
      EXPECT_EQ(got.meshes[k].time_s, f.time_s);
      EXPECT_EQ(got.meshes[k].value, static_cast<std::int32_t>(f.vertices_m.size())) << "frame " << k;
      // The session has strain: each triangle carries its recorded value.
      EXPECT_EQ(got.meshes[k].strain, f.triangle_strain_energy_J_per_m3) << "frame " << k;
    }
    // Haptic states: 100 Hz over the session, in order, contact as recorded.
    EXPECT_GE(got.haptic.size(), 140u);
    for (std::size_t i = 0; i < got.haptic.size(); ++i) {
      EXPECT_EQ(got.haptic[i].sequence, static_cast<std::int64_t>(i + 1));
      const std::uint64_t row = static_cast<std::uint64_t>(std::llround(got.haptic[i].time_s * 1e3));
      EXPECT_EQ(got.haptic[i].value, record::testing::haptic_row(row).contact) << "haptic row " << row;
    }
    wall_span_s[run] = got.meshes.back().wall_s - got.meshes.front().wall_s;
  }
  // Generous bounds: the pacing itself is checked exactly with the fake clock.
  EXPECT_GT(wall_span_s[0] / recorded_span_s, 0.85) << wall_span_s[0];
  EXPECT_LT(wall_span_s[0] / recorded_span_s, 1.4) << wall_span_s[0];
  const double ratio = wall_span_s[1] / wall_span_s[0];
  std::printf("recorded span %.3f s; wall span at speed 1: %.3f s, at speed 4: %.3f s (ratio %.3f)\n", recorded_span_s,
              wall_span_s[0], wall_span_s[1], ratio);
  EXPECT_GT(ratio, 0.15) << "speed 4 vs 1";
  EXPECT_LT(ratio, 0.40) << "speed 4 vs 1";
}

}  // namespace
}  // namespace tissue::replay
