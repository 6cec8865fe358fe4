// Recorder in-process: producer threads push, the recorder thread writes;
// everything pushed is in the file, pushes never block, failures are
// reported and turn pushes into counted drops.
#include "record/recorder.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <filesystem>
#include <functional>
#include <limits>
#include <stdexcept>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "record/recording_lock.hpp"
#include "record/session_tools.hpp"
#include "record_test_support.hpp"

namespace tissue::record {
namespace {

using testing::TempDir;

SessionMetadata meta() {
  SessionMetadata m;
  m.scene_name = "recorder-test";
  m.software_version = "test";
  return m;
}

RecorderOptions fast_options() {
  RecorderOptions o;
  o.flush_interval_s = 0.1;
  o.poll_interval_s = 0.005;
  o.mesh_max_vertices = 64;
  o.mesh_max_triangles = 64;
  o.min_free_bytes = 0;
  return o;
}

// Retries a refused push the way a test producer may (the real ones drop).
template <typename Push>
void push_until_accepted(Push&& push) {
  while (!push()) std::this_thread::sleep_for(std::chrono::microseconds(200));
}

TEST(Recorder, ThreeProducerThreadsEverythingPushedIsInTheFile) {
  TempDir dir;
  auto rec = Recorder::start(dir.path(), "s.h5", meta(), fast_options());
  constexpr std::uint64_t kHaptic = 20000, kSim = 200, kFrames = 12, kEvents = 20;
  std::thread haptic([&] {
    for (std::uint64_t i = 0; i < kHaptic; ++i) {
      // A real producer drops a refused row; this one retries it, so its
      // ring must not overflow: the recorder records every refusal as a hole
      // in /haptic (HapticHole), which here would be none. Half a ring ahead
      // of what is written at most, it never fills.
      while (i - rec->stats().haptic_rows_written >= Recorder::kHapticRingRows / 2)
        std::this_thread::sleep_for(std::chrono::microseconds(200));
      push_until_accepted([&] { return rec->push_haptic(testing::haptic_row(i)); });
    }
  });
  std::thread sim([&] {
    for (std::uint64_t i = 0; i < kSim; ++i) push_until_accepted([&] { return rec->push_sim(testing::sim_row(i)); });
    for (std::uint64_t f = 0; f < kFrames; ++f) {
      const testing::TestFrame frame = testing::test_frame(f);
      push_until_accepted([&] { return rec->push_mesh_frame(frame.view()); });
    }
  });
  std::thread control([&] {
    for (std::uint64_t i = 0; i < kEvents; ++i)
      push_until_accepted([&] { return rec->push_event(EventSource::kControl, testing::event_row(i)); });
  });
  haptic.join();
  sim.join();
  control.join();
  rec->stop();
  EXPECT_EQ(rec->state(), RecorderState::kStopped) << rec->error();
  EXPECT_EQ(rec->error(), "");
  const RecorderStats s = rec->stats();
  EXPECT_EQ(s.haptic_rows_written, kHaptic);
  EXPECT_EQ(s.sim_rows_written, kSim);
  EXPECT_EQ(s.mesh_frames_written, kFrames);
  EXPECT_EQ(s.events_written, kEvents);
  EXPECT_GT(s.bytes_written, kHaptic * 80);
  EXPECT_GE(s.flushes, 1u);

  const hid_t file = H5Fopen((dir / "s.h5").c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  ASSERT_GE(file, 0);
  EXPECT_EQ(testing::expect_session_content(file, kHaptic, kSim, kFrames, kEvents), 0);
  H5Fclose(file);
  EXPECT_TRUE(read_session_info(dir / "s.h5").closed_cleanly);
}

TEST(Recorder, FlushesWhileRunningWithoutBeingStopped) {
  TempDir dir;
  auto rec = Recorder::start(dir.path(), "s.h5", meta(), fast_options());
  for (std::uint64_t i = 0; i < 700; ++i) ASSERT_TRUE(rec->push_haptic(testing::haptic_row(i)));
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  while (rec->stats().haptic_rows_written < 700 && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  EXPECT_EQ(rec->stats().haptic_rows_written, 700u);
  EXPECT_EQ(rec->state(), RecorderState::kRecording);
}

TEST(Recorder, MeshFrameDueFollowsTheConfiguredRate) {
  TempDir dir;
  RecorderOptions o = fast_options();
  o.mesh_frame_interval_s = 0.1;
  auto rec = Recorder::start(dir.path(), "s.h5", meta(), o);
  EXPECT_TRUE(rec->mesh_frame_due(0.0));
  testing::TestFrame f = testing::test_frame(0);
  f.time_s = 0.0;
  ASSERT_TRUE(rec->push_mesh_frame(f.view()));
  EXPECT_FALSE(rec->mesh_frame_due(0.05));
  EXPECT_TRUE(rec->mesh_frame_due(0.1));
}

TEST(Recorder, OversizedAndInvalidFramesAreCountedNotWritten) {
  TempDir dir;
  RecorderOptions o = fast_options();
  o.mesh_frame_buffers = 8;  // every frame below gets a buffer, however slow the recorder thread
  auto rec = Recorder::start(dir.path(), "s.h5", meta(), o);
  testing::TestFrame big;
  big.time_s = 0.25;
  big.vertices_m.resize(65);
  EXPECT_FALSE(rec->push_mesh_frame(big.view()));
  testing::TestFrame big_triangles = testing::test_frame(0);
  big_triangles.triangles.resize(65);
  EXPECT_FALSE(rec->push_mesh_frame(big_triangles.view()));
  testing::TestFrame bad = testing::test_frame(0);
  bad.triangles[0][0] = 1000;
  EXPECT_TRUE(rec->push_mesh_frame(bad.view()));  // found on the recorder thread
  testing::TestFrame bad_levels = testing::test_frame(0);
  bad_levels.vertex_level.resize(2);
  EXPECT_TRUE(rec->push_mesh_frame(bad_levels.view()));
  testing::TestFrame bad_strain_count = testing::test_frame(0);
  bad_strain_count.triangle_strain_energy_J_per_m3.resize(2);
  EXPECT_TRUE(rec->push_mesh_frame(bad_strain_count.view()));
  testing::TestFrame nan_strain = testing::test_frame(0);
  nan_strain.triangle_strain_energy_J_per_m3[1] = std::numeric_limits<float>::quiet_NaN();
  EXPECT_TRUE(rec->push_mesh_frame(nan_strain.view()));
  ASSERT_TRUE(rec->push_mesh_frame(testing::test_frame(0).view()));
  rec->stop();
  const RecorderStats s = rec->stats();
  EXPECT_EQ(s.mesh_frames_too_big, 2u);
  EXPECT_EQ(s.mesh_frame_drops, 2u);
  EXPECT_EQ(s.mesh_frames_invalid, 4u);
  EXPECT_EQ(s.mesh_frames_written, 1u);
  const SessionInfo info = read_session_info(dir / "s.h5");
  EXPECT_EQ(info.rows.mesh_frames, 1u);
  // One warning per invalid frame, saying why, and one for the oversized
  // frames (every frame of a surface over the buffers is, so once per
  // recording), naming the first one's size and the buffers' capacity: a
  // session recorded with no frames otherwise says nothing of why.
  EXPECT_EQ(info.rows.events, 5u);
  const std::vector<std::string> messages = testing::event_messages(dir / "s.h5");
  const auto too_big = std::count_if(messages.begin(), messages.end(), [](const std::string& m) {
    return m.find("65 vertices, 0 triangles") != std::string::npos &&
           m.find("64 vertices, 64 triangles") != std::string::npos;
  });
  EXPECT_EQ(too_big, 1) << ::testing::PrintToString(messages);
}

TEST(Recorder, StartRejectsBadNamesAndDirectoriesWithTheReason) {
  TempDir dir;
  EXPECT_THROW(Recorder::start(dir.path(), "../escape.h5", meta()), RecordError);
  EXPECT_THROW(Recorder::start(dir.path(), "", meta()), RecordError);
  try {
    Recorder::start(dir / "nope", "s.h5", meta());
    ADD_FAILURE() << "started in a missing directory";
  } catch (const RecordError& e) {
    EXPECT_NE(std::string(e.what()).find(dir / "nope"), std::string::npos) << e.what();
  }
  RecorderOptions o;
  o.flush_interval_s = 5.0;
  EXPECT_THROW(Recorder::start(dir.path(), "s.h5", meta(), o), RecordError);
  // A frame interval that is not a number >= 0 would make mesh_frame_due()
  // never (NaN) or always true: refused naming the option.
  for (const double bad : {std::numeric_limits<double>::quiet_NaN(), -0.5, std::numeric_limits<double>::infinity()}) {
    RecorderOptions bad_interval;
    bad_interval.mesh_frame_interval_s = bad;
    try {
      Recorder::start(dir.path(), "s.h5", meta(), bad_interval);
      ADD_FAILURE() << "started with mesh_frame_interval_s " << bad;
    } catch (const RecordError& e) {
      EXPECT_NE(std::string(e.what()).find("mesh_frame_interval_s"), std::string::npos) << e.what();
    }
  }
  EXPECT_FALSE(std::filesystem::exists(dir / "s.h5")) << "nothing is created for refused options";
}

// The capacities are maxima: a frame of exactly mesh_max_vertices vertices
// and mesh_max_triangles triangles fits its buffer and is recorded.
TEST(Recorder, AFrameOfExactlyTheBufferCapacityIsRecorded) {
  TempDir dir;
  const RecorderOptions o = fast_options();
  auto rec = Recorder::start(dir.path(), "s.h5", meta(), o);
  testing::TestFrame full;
  full.time_s = 0.5;
  for (std::size_t v = 0; v < o.mesh_max_vertices; ++v) full.vertices_m.push_back({0.001 * v, 0.0, 0.0});
  for (std::uint32_t t = 0; t < o.mesh_max_triangles; ++t) {
    const auto n = static_cast<std::uint32_t>(o.mesh_max_vertices);
    full.triangles.push_back({t % n, (t + 1) % n, (t + 2) % n});
  }
  EXPECT_TRUE(rec->push_mesh_frame(full.view()));
  rec->stop();
  EXPECT_EQ(rec->stats().mesh_frames_too_big, 0u);
  EXPECT_EQ(rec->stats().mesh_frames_written, 1u);
  const SessionInfo info = read_session_info(dir / "s.h5");
  EXPECT_EQ(info.rows.mesh_vertices, o.mesh_max_vertices);
  EXPECT_EQ(info.rows.mesh_triangles, o.mesh_max_triangles);
}

TEST(Recorder, PushesAfterStopAreRefusedAndCounted) {
  TempDir dir;
  auto rec = Recorder::start(dir.path(), "s.h5", meta(), fast_options());
  rec->stop();
  EXPECT_FALSE(rec->push_haptic(testing::haptic_row(0)));
  EXPECT_FALSE(rec->push_sim(testing::sim_row(0)));
  EXPECT_FALSE(rec->push_event(EventSource::kSim, testing::event_row(0)));
  EXPECT_FALSE(rec->push_mesh_frame(testing::test_frame(0).view()));
  EXPECT_FALSE(rec->mesh_frame_due(100.0));
  const RecorderStats s = rec->stats();
  EXPECT_EQ(s.haptic_drops, 1u);
  EXPECT_EQ(s.sim_drops, 1u);
  EXPECT_EQ(s.event_drops, 1u);
  EXPECT_EQ(s.mesh_frame_drops, 1u);
  rec->stop();  // idempotent
}

// Producers still pushing while the recorder is stopped (a retired recorder
// whose sim thread has not let go of it yet): every push that returned true
// is in the file, and every attempt is either written or counted as a drop.
// Before the closing phase, pushes landing between the final drain and the
// close were accepted (true), then neither written nor counted.
TEST(Recorder, PushesRacingStopAreWrittenOrCountedNeverLost) {
  struct Tally {
    std::uint64_t attempts = 0, accepted = 0;
    void count(bool ok) {
      ++attempts;
      accepted += ok ? 1 : 0;
    }
  };
  for (int round = 0; round < 3; ++round) {
    TempDir dir;
    auto rec = Recorder::start(dir.path(), "s.h5", meta(), fast_options());
    std::atomic<bool> done{false};
    Tally haptic, sim, frames, events[kEventSourceCount];
    const testing::TestFrame frame = testing::test_frame(1);
    // One thread per ring (single-producer), pushing until told to stop:
    // through the whole stop() and beyond it.
    std::thread haptic_thread([&] {
      for (std::uint64_t i = 0; !done.load(std::memory_order_relaxed); ++i) {
        haptic.count(rec->push_haptic(testing::haptic_row(i)));
        if (i % 8 == 0) events[2].count(rec->push_event(EventSource::kHaptic, testing::event_row(i)));
        std::this_thread::yield();
      }
    });
    std::thread sim_thread([&] {
      for (std::uint64_t i = 0; !done.load(std::memory_order_relaxed); ++i) {
        sim.count(rec->push_sim(testing::sim_row(i)));
        if (i % 4 == 0) frames.count(rec->push_mesh_frame(frame.view()));
        if (i % 8 == 0) events[1].count(rec->push_event(EventSource::kSim, testing::event_row(i)));
        std::this_thread::yield();
      }
    });
    std::thread control_thread([&] {
      for (std::uint64_t i = 0; !done.load(std::memory_order_relaxed); ++i) {
        events[0].count(rec->push_event(EventSource::kControl, testing::event_row(i)));
        std::this_thread::yield();
      }
    });
    std::this_thread::sleep_for(std::chrono::milliseconds(30));
    rec->stop();
    // Keep pushing a little after the stop: those are refused and counted.
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
    done.store(true);
    haptic_thread.join();
    sim_thread.join();
    control_thread.join();

    ASSERT_EQ(rec->state(), RecorderState::kStopped) << rec->error();
    const RecorderStats s = rec->stats();
    std::uint64_t event_attempts = 0, events_accepted = 0;
    for (const Tally& t : events) {
      event_attempts += t.attempts;
      events_accepted += t.accepted;
    }
    SCOPED_TRACE("round " + std::to_string(round));
    EXPECT_GT(haptic.accepted, 0u);
    EXPECT_GT(frames.accepted, 0u);
    EXPECT_EQ(s.haptic_rows_written, haptic.accepted) << "accepted haptic rows lost";
    EXPECT_EQ(s.sim_rows_written, sim.accepted) << "accepted sim rows lost";
    EXPECT_EQ(s.mesh_frames_written, frames.accepted) << "accepted mesh frames lost";
    // The haptic ring may overflow at this push rate: each run of rows it
    // refused is recorded as a hole, an event of the recorder's own.
    const SessionInfo info = read_session_info(dir / "s.h5");
    const std::uint64_t holes = info.haptic_holes;
    // Exactly the rows the ring refused while open: a hole missed or
    // miscounted shows here (the rest were refused after the close).
    EXPECT_EQ(info.haptic_ticks_lost, s.haptic_drops_ring_full);
    EXPECT_LE(s.haptic_drops_ring_full, s.haptic_drops);
    EXPECT_EQ(s.events_written, events_accepted + holes) << "accepted events lost";
    EXPECT_EQ(s.haptic_rows_written + s.haptic_drops, haptic.attempts);
    EXPECT_EQ(s.sim_rows_written + s.sim_drops, sim.attempts);
    EXPECT_EQ(s.mesh_frames_written + s.mesh_frame_drops, frames.attempts);
    EXPECT_EQ(s.events_written - holes + s.event_drops, event_attempts);
    EXPECT_TRUE(info.closed_cleanly);
    EXPECT_EQ(info.rows.haptic_rows, haptic.accepted);
    EXPECT_EQ(info.rows.sim_rows, sim.accepted);
    EXPECT_EQ(info.rows.mesh_frames, frames.accepted);
    EXPECT_EQ(info.rows.events, events_accepted + holes);
  }
}

// The recorder's haptic ring overflows (the disk stalls longer than the ring
// holds; here the recorder thread's first poll is a second away): the rows
// refused are dropped, and the file says so. Each run of them is a hole, a
// warning event naming the recorded rows on either side, their times and the
// ticks lost; a run that nothing follows (the recording stopped during it)
// names the last row. Before, the drops were counted only in memory (the
// status's `drops`): in the file a hole was a jump in /haptic/time_s, like
// the haptic loop skipping ticks, and a replay took it for a lost device.
TEST(Recorder, RowsDroppedWhenTheHapticRingOverflowsLeaveAHoleInTheFile) {
  TempDir dir;
  RecorderOptions o = fast_options();
  o.flush_interval_s = 1.0;
  o.poll_interval_s = 1.0;
  auto rec = Recorder::start(dir.path(), "s.h5", meta(), o);
  constexpr std::uint64_t kRing = Recorder::kHapticRingRows;
  // Row i is haptic_row(i) (time i ms); accepted[i]: the push returned true.
  std::vector<bool> accepted;
  const auto push = [&](std::uint64_t n) {
    for (std::uint64_t k = 0; k < n; ++k) accepted.push_back(rec->push_haptic(testing::haptic_row(accepted.size())));
  };
  push(kRing + 50);  // the ring holds kRing: 50 dropped
  ASSERT_EQ(std::count(accepted.begin(), accepted.end(), true), static_cast<std::ptrdiff_t>(kRing))
      << "the recorder drained before the ring was full: no overflow to check";
  // The first poll drains the ring and writes at once (a ring's worth).
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(30);
  while (rec->stats().haptic_rows_written < kRing && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  ASSERT_EQ(rec->stats().haptic_rows_written, kRing);
  push(kRing + 7);  // full again: 7 dropped, and the recording stops before another row
  ASSERT_EQ(std::count(accepted.begin() + kRing + 50, accepted.end(), true), static_cast<std::ptrdiff_t>(kRing))
      << "the recorder drained again before the ring was full: no second overflow to check";
  rec->stop();
  ASSERT_EQ(rec->state(), RecorderState::kStopped) << rec->error();
  // Pushes after the stop are refused and counted, but are no hole: the
  // recording had ended.
  for (std::uint64_t k = 0; k < 3; ++k) EXPECT_FALSE(rec->push_haptic(testing::haptic_row(2 * kRing + 57 + k)));
  EXPECT_EQ(rec->stats().haptic_drops, 60u);
  EXPECT_EQ(rec->stats().haptic_drops_ring_full, 57u);
  EXPECT_EQ(rec->stats().haptic_rows_written, 2 * kRing);

  const std::string path = dir / "s.h5";
  const SessionFile f(path);
  const std::vector<HapticHole> holes = read_haptic_holes(f);
  ASSERT_EQ(holes.size(), 2u);
  // Rows 0 .. kRing-1 recorded, pushes kRing .. kRing+49 dropped, then push
  // kRing+50 recorded as row kRing.
  EXPECT_EQ(holes[0].ticks_lost, 50u);
  EXPECT_EQ(holes[0].row_after, kRing);
  EXPECT_EQ(holes[0].time_before_s, testing::haptic_row(kRing - 1).time_s);
  EXPECT_EQ(holes[0].time_after_s, testing::haptic_row(kRing + 50).time_s);
  // The last kRing rows recorded, then 7 dropped and nothing after them.
  EXPECT_EQ(holes[1].ticks_lost, 7u);
  EXPECT_EQ(holes[1].row_after, 2 * kRing);
  EXPECT_EQ(holes[1].time_before_s, testing::haptic_row(2 * kRing + 50 - 1).time_s);
  EXPECT_FALSE(holes[1].has_row_after());
  // As warning events, in words a person reads too.
  const std::vector<std::string> messages = testing::event_messages(path);
  const std::vector<std::int32_t> kinds = f.rows<std::int32_t>(kEventKind, 0, f.info().rows.events);
  ASSERT_EQ(messages.size(), 2u) << ::testing::PrintToString(messages);
  EXPECT_EQ(messages[0],
            "haptic rows dropped by the recorder (ring full): 50 ticks between /haptic rows 8191 (8.191000000 s) and "
            "8192 (8.242000000 s)");
  EXPECT_EQ(messages[1],
            "haptic rows dropped by the recorder (ring full): 7 ticks after /haptic row 16383 (16.433000000 s), the "
            "last recorded");
  EXPECT_EQ(kinds, (std::vector<std::int32_t>(2, static_cast<std::int32_t>(EventKind::kWarning))));
  const std::vector<double> event_times = f.rows<double>(kEventTime, 0, 2);
  EXPECT_EQ(event_times[0], holes[0].time_before_s);
  EXPECT_EQ(event_times[1], holes[1].time_before_s);

  // `tissue session info` reports them; the replay device gets the hole
  // between two rows (the last one ends the track: nothing to play there).
  const SessionInfo info = read_session_info(path);
  EXPECT_EQ(info.haptic_holes, 2u);
  EXPECT_EQ(info.haptic_ticks_lost, 57u);
  // Every row the ring refused is in a hole, and nothing else is.
  EXPECT_EQ(info.haptic_ticks_lost, rec->stats().haptic_drops_ring_full);
  const std::string text = format_session_info(info);
  EXPECT_NE(text.find("haptic holes:     2 holes, 57 ticks the recorder dropped"), std::string::npos) << text;
  EXPECT_EQ(read_haptic_track(path).rows_after_holes, (std::vector<std::size_t>{kRing}));
}

// A recording whose next flush carries a hole: the haptic ring filled past
// full (it takes kHapticRingRows, 50 are dropped) and what it took written,
// so rows pushed now come after the hole. Once `armed`, the flush of the
// dataset `failing` throws, as a crash there would.
struct HolePending {
  TempDir dir;
  std::atomic<bool> armed{false};
  std::string failing;
  std::unique_ptr<Recorder> rec;
  std::uint64_t pushed = 0, accepted = 0;
  void push(std::uint64_t n) {
    for (std::uint64_t k = 0; k < n; ++k) accepted += rec->push_haptic(testing::haptic_row(pushed++)) ? 1 : 0;
  }
  void start(const std::string& failing_dataset) {
    failing = failing_dataset;
    RecorderOptions o = fast_options();
    o.flush_interval_s = 1.0;
    o.poll_interval_s = 1.0;
    o.flush_fault_for_testing = [this](const char* dataset) {
      if (armed.load() && dataset == failing) throw RecordError("injected crash");
    };
    rec = Recorder::start(dir.path(), "s.h5", meta(), o);
    constexpr std::uint64_t kRing = Recorder::kHapticRingRows;
    push(kRing + 50);
    ASSERT_EQ(accepted, kRing) << "the recorder drained before the ring was full: no hole to check";
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(30);
    while (rec->stats().haptic_rows_written < kRing && std::chrono::steady_clock::now() < deadline)
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    ASSERT_EQ(rec->stats().haptic_rows_written, kRing);
  }
};

// A crash in the middle of the flush that carries a hole (here: that flush
// failing at one dataset, which leaves the file as of the datasets flushed
// before it, as a crash there would) never leaves the rows after the hole
// in the file without the hole's event: a hole without its event is
// invisible, a jump in /haptic/time_s like the loop skipping ticks. The
// writer flushes /haptic before /events, so before, a crash between the two
// did just that. Now the event is flushed first, so a crash while the rows
// are flushed finds it there.
class RecorderCrashInTheHolesFlush : public ::testing::TestWithParam<const char*> {};

TEST_P(RecorderCrashInTheHolesFlush, TheRowsAfterAHoleAreNeverInTheFileWithoutItsEvent) {
  const std::string failing = GetParam();
  HolePending h;
  ASSERT_NO_FATAL_FAILURE(h.start(failing));
  TempDir& dir = h.dir;
  const auto& rec = h.rec;
  std::atomic<bool>& armed = h.armed;
  std::uint64_t& accepted = h.accepted;
  constexpr std::uint64_t kRing = Recorder::kHapticRingRows;
  const auto push = [&h](std::uint64_t n) { h.push(n); };
  // The next flush is the hole's: the first of these rows comes after it.
  armed.store(true);
  push(10);
  ASSERT_EQ(accepted, kRing + 10);
  rec->stop();
  ASSERT_EQ(rec->state(), RecorderState::kFailed) << "the injected crash never happened: " << failing;
  const SessionInfo info = read_session_info(dir / "s.h5");
  ASSERT_GE(info.rows.haptic_rows, kRing);
  if (info.rows.haptic_rows > kRing) {
    EXPECT_EQ(info.haptic_holes, 1u) << "the crash at " << failing << " left " << info.rows.haptic_rows - kRing
                                     << " rows after the hole in the file, and no event of the hole";
  }
  // The event goes first: a crash while the rows after it are being flushed
  // finds it in the file already.
  if (failing.rfind("/haptic/", 0) == 0) {
    EXPECT_EQ(info.haptic_holes, 1u) << "the crash at " << failing << " left no event of the hole";
  }
  // When the event is there, it is the hole's.
  EXPECT_EQ(info.haptic_ticks_lost, info.haptic_holes == 0 ? 0u : 50u);
  EXPECT_TRUE(info.damaged_hole_events.empty());
}

INSTANTIATE_TEST_SUITE_P(Recorder, RecorderCrashInTheHolesFlush,
                         ::testing::Values("/haptic/time_s", "/events/kind", "/events/message", "/events/time_s"),
                         [](const ::testing::TestParamInfo<const char*>& p) {
                           std::string name = p.param;
                           std::string out;
                           for (char c : name)
                             if (std::isalnum(static_cast<unsigned char>(c))) out += c;
                           return out;
                         });

// The hole's first flush (its event, written and synced before the rows
// after the hole) flushes every dataset written so far, a mesh frame drained
// with those rows included: once it succeeds, that frame is in the file for
// good. So it counts as written then, and the flush as done. Before, frames
// moved to written only after the second flush; when that one failed,
// count_unwritten_as_drops counted a frame the file holds as a drop, and the
// status said one frame fewer than the file has (and one flush fewer).
TEST(Recorder, AFrameTheHolesFirstFlushWroteIsWrittenWhenTheNextFlushFails) {
  HolePending h;
  ASSERT_NO_FATAL_FAILURE(h.start("/haptic/time_s"));
  TempDir& dir = h.dir;
  const auto& rec = h.rec;
  std::atomic<bool>& armed = h.armed;
  std::uint64_t& accepted = h.accepted;
  constexpr std::uint64_t kRing = Recorder::kHapticRingRows;
  const auto push = [&h](std::uint64_t n) { h.push(n); };
  const std::uint64_t flushes_before = rec->stats().flushes;
  // The next flush is the hole's: the frame and the rows after the hole go
  // in the same drain; the hole's first flush succeeds, the second fails.
  armed.store(true);
  ASSERT_TRUE(rec->push_mesh_frame(testing::test_frame(0).view()));
  push(10);
  ASSERT_EQ(accepted, kRing + 10);
  rec->stop();
  ASSERT_EQ(rec->state(), RecorderState::kFailed) << "the injected crash never happened";
  const SessionInfo info = read_session_info(dir / "s.h5");
  ASSERT_EQ(info.haptic_holes, 1u) << "the hole's first flush did not reach the file";
  ASSERT_EQ(info.rows.mesh_frames, 1u) << "the hole's first flush did not flush the frame drained with it";
  const RecorderStats s = rec->stats();
  EXPECT_EQ(s.mesh_frames_written, info.rows.mesh_frames) << "a frame the file holds, not counted as written";
  EXPECT_EQ(s.mesh_frame_drops, 0u) << "a frame the file holds, counted as dropped";
  EXPECT_EQ(s.events_written, info.rows.events);
  // The hole's first flush was done (and synced): it counts.
  EXPECT_GE(s.flushes, flushes_before + 1);
}

// What a recording's on_error said: how often, and the last message (read
// after stop(), which joins the recorder thread that calls it).
struct ErrorsHeard {
  std::atomic<int> calls{0};
  std::string last;
  std::function<void(const std::string&)> callback() {
    return [this](const std::string& m) {
      last = m;
      calls.fetch_add(1);
    };
  }
};

// The free-space reserve trips (here: a reserve no disk has): recording
// stops with a message naming the file, the callback hears it, the file is
// closed properly and holds a recording_error event; producers are unharmed,
// and every push is written or counted as a drop. The writer is healthy, so
// the reserve is a controlled stop: the rows accepted before it go into the
// file (they were thrown away as drops, though the file still took writes).
TEST(Recorder, FreeSpaceReserveStopsRecordingCleanlyAndReports) {
  TempDir dir;
  RecorderOptions o = fast_options();
  // The first poll checks the free space: a second after start, so the
  // pushes below come before it (and before any flush).
  o.flush_interval_s = 1.0;
  o.poll_interval_s = 1.0;
  o.min_free_bytes = std::uint64_t{1} << 62;
  ErrorsHeard errors;
  o.on_error = errors.callback();
  auto rec = Recorder::start(dir.path(), "s.h5", meta(), o);
  std::uint64_t accepted = 0;
  for (int k = 0; k < 100; ++k) accepted += rec->push_haptic(testing::haptic_row(accepted));
  ASSERT_GT(accepted, 0u) << "the reserve tripped before the first push: nothing to check";
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(30);
  while (rec->state() == RecorderState::kRecording && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  ASSERT_EQ(rec->state(), RecorderState::kFailed);
  // Failed means closed: nothing holds the file any more.
  EXPECT_FALSE(being_recorded(dir / "s.h5"));
  for (int k = 0; k < 1000; ++k) EXPECT_FALSE(rec->push_haptic(testing::haptic_row(k)));
  rec->stop();
  EXPECT_EQ(errors.calls.load(), 1);
  EXPECT_EQ(errors.last, rec->error());
  EXPECT_NE(rec->error().find(dir / "s.h5"), std::string::npos) << rec->error();
  EXPECT_NE(rec->error().find("disk almost full"), std::string::npos) << rec->error();
  EXPECT_EQ(rec->stats().haptic_rows_written, accepted);
  EXPECT_EQ(rec->stats().haptic_drops, 1000u + (100u - accepted));
  const SessionInfo info = read_session_info(dir / "s.h5");
  EXPECT_FALSE(info.open_for_write_flag);
  EXPECT_TRUE(info.closed_cleanly);
  EXPECT_EQ(info.rows.haptic_rows, accepted);
  ASSERT_EQ(info.rows.events, 1u);
  const hid_t file = H5Fopen((dir / "s.h5").c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  ASSERT_GE(file, 0);
  EXPECT_EQ(testing::read_i32(file, "/events/kind").at(0), static_cast<int>(EventKind::kRecordingError));
  const std::vector<double> times = testing::read_f64(file, "/haptic/time_s");
  for (std::size_t r = 0; r < times.size(); ++r) EXPECT_EQ(times[r], testing::haptic_row(r).time_s) << r;
  H5Fclose(file);
}

// An append of rows, events or a mesh frame that throws an I/O error
// (injected at one dataset: HDF5 buffers real appends, so a full disk shows
// at the flush, which RecordProcess.FileSizeLimitStops... covers) fails the
// recording as a failed flush does: the error names the file and the
// dataset, on_error hears it once, nothing counts as written, every row,
// event and frame pushed is a drop (the frame whose own append threw
// counted once), no recording_error event goes into the broken file, and the
// file is closed: no longer being recorded.
class RecorderAppendThrows : public ::testing::TestWithParam<const char*> {};

TEST_P(RecorderAppendThrows, RecordingFailsEveryPushIsADropAndTheFileIsClosed) {
  TempDir dir;
  const std::string failing = GetParam();
  RecorderOptions o = fast_options();
  o.write_fault_for_testing = [failing](const char* dataset) {
    if (dataset == failing) throw RecordError("injected write error");
  };
  ErrorsHeard errors;
  o.on_error = errors.callback();
  auto rec = Recorder::start(dir.path(), "s.h5", meta(), o);
  // The failing kind is pushed first, so no write that comes before it can
  // succeed, whenever the recorder thread polls or flushes (frames are
  // appended at each poll, before the rows' flush). Refused pushes (once the
  // recording has failed) are drops too: every push ends up as one.
  constexpr std::uint64_t kHaptic = 50, kSim = 10, kEvents = 5, kFrames = 2;
  std::vector<std::function<void()>> pushes = {
      [&] {
        for (std::uint64_t k = 0; k < kHaptic; ++k) rec->push_haptic(testing::haptic_row(k));
        for (std::uint64_t k = 0; k < kSim; ++k) rec->push_sim(testing::sim_row(k));
      },
      [&] {
        for (std::uint64_t k = 0; k < kEvents; ++k) rec->push_event(EventSource::kControl, testing::event_row(k));
      },
      [&] {
        for (std::uint64_t k = 0; k < kFrames; ++k) rec->push_mesh_frame(testing::test_frame(k).view());
      },
  };
  const std::size_t first = failing.rfind("/haptic/", 0) == 0 ? 0 : failing.rfind("/events/", 0) == 0 ? 1 : 2;
  std::rotate(pushes.begin(), pushes.begin() + static_cast<std::ptrdiff_t>(first), pushes.end());
  for (const auto& push : pushes) push();
  rec->stop();

  ASSERT_EQ(rec->state(), RecorderState::kFailed);
  EXPECT_NE(rec->error().find(dir / "s.h5"), std::string::npos) << rec->error();
  EXPECT_NE(rec->error().find(std::string("cannot write ") + failing), std::string::npos) << rec->error();
  EXPECT_EQ(errors.calls.load(), 1);
  EXPECT_EQ(errors.last, rec->error());
  const RecorderStats s = rec->stats();
  EXPECT_EQ(s.haptic_rows_written, 0u);
  EXPECT_EQ(s.sim_rows_written, 0u);
  EXPECT_EQ(s.events_written, 0u);
  EXPECT_EQ(s.mesh_frames_written, 0u);
  EXPECT_EQ(s.mesh_frames_invalid, 0u);
  EXPECT_EQ(s.haptic_drops, kHaptic);
  EXPECT_EQ(s.sim_drops, kSim);
  EXPECT_EQ(s.event_drops, kEvents);
  EXPECT_EQ(s.mesh_frame_drops, kFrames);
  EXPECT_FALSE(being_recorded(dir / "s.h5")) << "the failed recording still holds its file";
  // The file stays as of its last successful flush (none here), like after
  // a crash: no rows, and no recording_error event.
  const SessionInfo info = read_session_info(dir / "s.h5");
  EXPECT_FALSE(info.closed_cleanly);
  EXPECT_EQ(info.rows.haptic_rows, 0u);
  EXPECT_EQ(info.rows.mesh_frames, 0u);
  EXPECT_EQ(info.rows.events, 0u);
}

INSTANTIATE_TEST_SUITE_P(Recorder, RecorderAppendThrows,
                         ::testing::Values("/haptic/device_position_m", "/events/kind", "/mesh/vertices_m"),
                         [](const ::testing::TestParamInfo<const char*>& p) {
                           const std::string dataset = p.param;
                           return dataset == "/haptic/device_position_m" ? std::string("HapticRows")
                                  : dataset == "/events/kind"            ? std::string("Events")
                                                                         : std::string("MeshFrame");
                         });

// A failed recording closes its file (the recording lock and the HDF5
// handles go) when the recorder thread stops, also when the recording_error
// event cannot be written into it: the event and the close are tried
// separately. Here the writer stays healthy (an exception that is no I/O
// error, as std::bad_alloc from a scratch column would be), so after the
// failed row write the recorder does try the event, and that write fails
// too. The close used to be skipped then, and the file stayed "being
// recorded" until the Recorder was destroyed.
TEST(Recorder, AFailedRecordingClosesItsFileAlsoWhenTheErrorEventCannotBeWritten) {
  TempDir dir;
  RecorderOptions o = fast_options();
  std::atomic<int> event_writes{0};
  o.write_fault_for_testing = [&](const char* dataset) {
    const std::string_view d = dataset;
    if (d == "/events/kind") event_writes.fetch_add(1);
    if (d == "/haptic/device_position_m" || d == "/events/kind") throw std::runtime_error("injected failure");
  };
  auto rec = Recorder::start(dir.path(), "s.h5", meta(), o);
  ASSERT_TRUE(being_recorded(dir / "s.h5")) << "no recording lock on this file system: nothing to check";
  for (int k = 0; k < 20; ++k) rec->push_haptic(testing::haptic_row(k));
  rec->stop();
  ASSERT_EQ(rec->state(), RecorderState::kFailed);
  EXPECT_NE(rec->error().find("injected failure"), std::string::npos) << rec->error();
  // Not the writer's own error: the recorder names the file.
  EXPECT_NE(rec->error().find(dir / "s.h5"), std::string::npos) << rec->error();
  ASSERT_EQ(event_writes.load(), 1) << "the recording_error event was not tried: the test misses its path";
  // The Recorder still exists: only the close can have released the file.
  EXPECT_FALSE(being_recorded(dir / "s.h5")) << "the failed recording still holds its file after the stop";
  const SessionInfo info = read_session_info(dir / "s.h5");
  EXPECT_TRUE(info.closed_cleanly);
  EXPECT_EQ(info.rows.haptic_rows, 0u);
  EXPECT_EQ(info.rows.events, 0u);
  EXPECT_EQ(rec->stats().haptic_drops, 20u);
}

}  // namespace
}  // namespace tissue::record
