// LiveFrameSource (daemon/export/live_source) over a scripted subscriber:
// what is collected, in what order, and the timeout error.
#include "export/live_source.hpp"

#include <gtest/gtest.h>

#include <chrono>
#include <deque>
#include <thread>

#include "export/export_test_support.hpp"

namespace tissue::x3d {
namespace {

// Hands out scripted frames, one per next_frame() call; after the script,
// waits out the timeout like a quiet network.
class ScriptedSubscriber final : public transport::MeshSubscriber {
 public:
  explicit ScriptedSubscriber(std::deque<SurfaceFrame> script) : script_(std::move(script)) {}
  std::string name() const override { return "scripted topic"; }
  std::optional<SurfaceFrame> next_frame(double timeout_s) override {
    if (script_.empty()) {
      std::this_thread::sleep_for(std::chrono::duration<double>(timeout_s));
      return std::nullopt;
    }
    SurfaceFrame f = std::move(script_.front());
    script_.pop_front();
    return f;
  }
  const transport::MeshReceiveCounts& counts() const override { return counts_; }
  transport::MeshReceiveCounts counts_;

 private:
  std::deque<SurfaceFrame> script_;
};

SurfaceFrame empty_frame(double t) {
  SurfaceFrame f;
  f.time_s = t;
  return f;
}

TEST(LiveFrameSource, SnapshotIsTheFirstDrawableFrame) {
  ScriptedSubscriber sub(
      {empty_frame(0.1), testing::box_frame(0.2, {0, 0, 0}, {1, 1, 1}), testing::tetra_frame(0.3, 1.0)});
  LiveCollectOptions o;
  o.max_frames = 1;
  LiveFrameSource src(sub, o);
  ASSERT_EQ(src.frame_count(), 1u);
  EXPECT_EQ(src.frame_time_s(0), 0.2);
  EXPECT_EQ(src.read_frame(0).vertices_m.size(), 8u);
  EXPECT_EQ(src.skipped_empty(), 1u);
  EXPECT_EQ(src.dropped_note(), "");
  EXPECT_EQ(src.name(), "scripted topic");
  EXPECT_THROW(src.read_frame(1), std::out_of_range);
}

TEST(LiveFrameSource, WindowCollectsInTimeOrderDroppingFramesThatGoBack) {
  ScriptedSubscriber sub({testing::box_frame(1.0, {0, 0, 0}, {1, 1, 1}), testing::box_frame(1.5, {0, 0, 0}, {1, 1, 2}),
                          testing::tetra_frame(0.5, 1.0),  // a reset / replay loop: back in time
                          testing::tetra_frame(2.0, 1.0)});
  LiveCollectOptions o;
  o.window_s = 0.5;  // the script runs out long before; the rest is waiting
  LiveFrameSource src(sub, o);
  ASSERT_EQ(src.frame_count(), 3u);
  EXPECT_EQ(src.frame_time_s(0), 1.0);
  EXPECT_EQ(src.frame_time_s(1), 1.5);
  EXPECT_EQ(src.frame_time_s(2), 2.0);
  EXPECT_EQ(src.dropped_backwards(), 1u);
  EXPECT_EQ(src.dropped_note(),
            "1 frames dropped: their time was before the last frame kept (the daemon reset or a replay looped)");
  EXPECT_EQ(frames_in_window(src, 1.2, 2.0), (std::vector<std::size_t>{1, 2}));
}

// What the transport lost, dropped or refused while collecting is said
// beside the frames, so a gap in an animation is explained.
TEST(LiveFrameSource, TheNoteSaysWhatTheSubscriberLostDroppedOrRefused) {
  ScriptedSubscriber sub({testing::box_frame(1.0, {0, 0, 0}, {1, 1, 1}), testing::tetra_frame(2.0, 1.0)});
  sub.counts_.missed = 3;
  sub.counts_.overflow = 2;
  sub.counts_.rejected = 1;
  sub.counts_.last_rejection = "triangle 1 uses vertex 9 of 4";
  LiveCollectOptions o;
  o.window_s = 10.0;
  o.max_frames = 2;  // ends the window as soon as both are in
  LiveFrameSource src(sub, o);
  ASSERT_EQ(src.frame_count(), 2u);
  EXPECT_EQ(src.dropped_note(),
            "3 messages the publisher sent never arrived (gaps in its sequence numbers: lost on the network, or this "
            "reader fell behind); 2 frames dropped: this reader fell behind; 1 malformed messages dropped, the last: "
            "triangle 1 uses vertex 9 of 4");
}

TEST(LiveFrameSource, StrainIsReportedOnlyWhenEveryFrameHasIt) {
  SurfaceFrame a = testing::box_frame(1.0, {0, 0, 0}, {1, 1, 1});
  a.vertex_strain_energy_Pa.assign(a.vertices_m.size(), 1.0f);
  SurfaceFrame b = a;
  b.time_s = 2.0;
  LiveCollectOptions o;
  o.max_frames = 2;
  o.window_s = 10.0;
  {
    ScriptedSubscriber sub({a, b});
    EXPECT_TRUE(LiveFrameSource(sub, o).has_strain());
  }
  b.vertex_strain_energy_Pa.clear();
  ScriptedSubscriber sub({a, b});
  const LiveFrameSource without(sub, o);
  EXPECT_FALSE(without.has_strain());
  // Said in a live source's terms: no session format to blame.
  const std::string message = no_strain_message(without);
  EXPECT_NE(message.find("scripted topic sent frames without a finite, non-negative strain energy"), std::string::npos)
      << message;
  EXPECT_EQ(message.find("session"), std::string::npos) << message;
  EXPECT_NE(message.find("use --colour level"), std::string::npos) << message;
}

// A publisher that never pauses: frame k at k / 30 s, every call. After
// `limit` frames it asks the collection to stop (as Ctrl-C would), so a
// collection that ignores its byte budget ends rather than hangs.
class EndlessSubscriber final : public transport::MeshSubscriber {
 public:
  EndlessSubscriber(std::size_t limit, std::atomic<bool>* stop) : limit_(limit), stop_(stop) {}
  std::string name() const override { return "endless topic"; }
  std::optional<SurfaceFrame> next_frame(double) override {
    if (sent_ == limit_) {
      *stop_ = true;
      return std::nullopt;
    }
    return testing::box_frame(static_cast<double>(sent_++) / 30.0, {0, 0, 0}, {1, 1, 1});
  }
  const transport::MeshReceiveCounts& counts() const override { return counts_; }
  std::size_t sent() const { return sent_; }

 private:
  std::size_t limit_, sent_ = 0;
  std::atomic<bool>* stop_;
  transport::MeshReceiveCounts counts_;
};

// --animate --seconds 600 against a large surface at 30 Hz kept every frame
// (tens of GB): the window alone bounded nothing.
TEST(LiveFrameSource, CollectionStopsAtTheByteBudgetAndSaysSo) {
  const std::size_t one = frame_bytes(testing::box_frame(0.0, {0, 0, 0}, {1, 1, 1}));
  ASSERT_EQ(one, 8 * 24 + 12 * 12 + 8 + 8 * 4u) << "8 vertices, 12 triangles, 8 levels, 8 strain values";
  std::atomic<bool> stop{false};
  EndlessSubscriber sub(100, &stop);
  LiveCollectOptions o;
  o.window_s = 1e9;
  o.max_bytes = 3 * one + one / 2;
  const LiveFrameSource src(sub, o, &stop);
  EXPECT_EQ(src.frame_count(), 3u);
  EXPECT_TRUE(src.stopped_at_budget());
  EXPECT_FALSE(stop) << "the budget ended the collection, not the stop request";
  EXPECT_EQ(sub.sent(), 4u) << "the frame over the budget was received, not kept, and nothing after it";
  const std::string note = src.dropped_note();
  EXPECT_EQ(note.rfind("collection stopped after 3 frames (", 0), 0u) << note;
  EXPECT_NE(note.find(" s of the 1e+09 s window): the next would take the frames kept past 1.28516 KiB"),
            std::string::npos)
      << note;
  // The first frame is kept whatever its size: a snapshot of a large surface works.
  std::atomic<bool> stop2{false};
  EndlessSubscriber sub2(100, &stop2);
  o.max_bytes = one / 2;
  const LiveFrameSource first_only(sub2, o, &stop2);
  EXPECT_EQ(first_only.frame_count(), 1u);
  EXPECT_TRUE(first_only.stopped_at_budget());
  // Within the budget nothing is said.
  std::atomic<bool> stop3{false};
  EndlessSubscriber sub3(5, &stop3);
  o.max_bytes = 5 * one;
  const LiveFrameSource all(sub3, o, &stop3);
  EXPECT_EQ(all.frame_count(), 5u);
  EXPECT_FALSE(all.stopped_at_budget());
  EXPECT_EQ(all.dropped_note(), "");
}

// Whether the stop request ended the collection, not whether the flag is
// up by now: a signal that lands after the collection ended on its own (the
// window, max_frames) made the client call a complete take "cut short".
TEST(LiveFrameSource, ItSaysWhetherTheStopRequestEndedTheCollection) {
  std::atomic<bool> stop{false};
  EndlessSubscriber asks_to_stop(5, &stop);  // raises the flag after 5 frames
  LiveCollectOptions o;
  o.window_s = 1e9;
  const LiveFrameSource stopped(asks_to_stop, o, &stop);
  EXPECT_EQ(stopped.frame_count(), 5u);
  EXPECT_TRUE(stopped.stopped_by_request());

  std::atomic<bool> later{false};
  EndlessSubscriber endless(100, &later);
  o.max_frames = 3;
  const LiveFrameSource complete(endless, o, &later);
  later = true;  // the signal after the collection ended
  EXPECT_EQ(complete.frame_count(), 3u);
  EXPECT_FALSE(complete.stopped_by_request());
}

TEST(LiveFrameSource, NothingWithinTheTimeoutIsANamedError) {
  ScriptedSubscriber sub({empty_frame(0.1)});
  sub.counts_.rejected = 2;
  sub.counts_.last_rejection = "triangle 1 uses vertex 9 of 4";
  LiveCollectOptions o;
  o.first_timeout_s = 0.3;
  try {
    LiveFrameSource src(sub, o);
    FAIL() << "no error";
  } catch (const NoLiveFrameError& e) {
    const std::string what = e.what();
    EXPECT_EQ(what.rfind("no surface_mesh on scripted topic within 0.3 s", 0), 0u) << what;
    EXPECT_NE(what.find("2 malformed messages dropped, the last: triangle 1 uses vertex 9 of 4"), std::string::npos)
        << what;
  }
  std::atomic<bool> stop{true};  // stopped before anything came: no error, no frames
  ScriptedSubscriber quiet({});
  EXPECT_EQ(LiveFrameSource(quiet, o, &stop).frame_count(), 0u);
}

}  // namespace
}  // namespace tissue::x3d
