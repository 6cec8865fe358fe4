// Shared by the replay suites: a fake clock and a sink that records what was
// sent when, an in-memory FrameSource, deterministic rows, good session
// files (record_test_support writes them, and the bad ones).
#pragma once

#include <atomic>
#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "export/frame_source.hpp"
#include "record_test_support.hpp"
#include "replay/session_replay.hpp"

namespace tissue::replay::testing {

// Time moves only when the replay waits (jumps to the due time) or a sink
// says publishing took time. No sleeping.
class FakeClock final : public ReplayClock {
 public:
  explicit FakeClock(double start_s) : now_(start_s) {}
  double now_s() override { return now_; }
  bool wait_until(double t_s, const std::atomic<bool>& stop) override {
    if (stop.load()) return false;
    if (t_s > now_) now_ = t_s;
    return true;
  }
  void advance(double dt_s) { now_ += dt_s; }

 private:
  double now_;
};

class RecordingSink final : public ReplaySink {
 public:
  explicit RecordingSink(FakeClock* clock) : clock_(clock) {}
  struct Sent {
    StreamKind kind;
    double time_s;               // the message's time (session time)
    double wall_s;               // the fake clock when the sink got it
    std::uint64_t sequence = 0;  // mesh only
    std::size_t vertices = 0;    // mesh only
  };
  std::vector<Sent> sent;
  // Holes the replay announced, and how many items had been sent then.
  struct Hole {
    record::HapticHole hole;
    std::size_t after_sent = 0;
  };
  std::vector<Hole> holes;
  std::map<std::uint64_t, double> mesh_cost_s;  // mesh sequence -> time its publish takes
  std::uint64_t stop_after = 0;                 // meshes; 0: never
  std::atomic<bool>* stop = nullptr;

  void mesh(const service::MeshSnapshot& s) override;
  void haptic(const service::SimStatus& s) override;
  void stats(const service::SimStatus& s) override;
  void haptic_hole(const record::HapticHole& hole) override;

 private:
  FakeClock* clock_;
  std::uint64_t meshes_ = 0;
};

class VectorFrameSource final : public x3d::FrameSource {
 public:
  explicit VectorFrameSource(std::vector<x3d::SurfaceFrame> frames) : frames_(std::move(frames)) {}
  std::string name() const override { return "'test frames'"; }
  std::size_t frame_count() const override { return frames_.size(); }
  double frame_time_s(std::size_t k) const override { return frames_.at(k).time_s; }
  x3d::SurfaceFrame read_frame(std::size_t k) override { return frames_.at(k); }
  bool has_strain() const override { return false; }
  const x3d::SurfaceFrame& frame(std::size_t k) const { return frames_.at(k); }

 private:
  std::vector<x3d::SurfaceFrame> frames_;
};

// n frames at k * dt: record_test_support's test_frame(k) geometry (sizes
// vary with k), at the given times.
std::vector<x3d::SurfaceFrame> moving_frames(std::size_t n, double dt_s);
// haptic_row(i) / sim_row(i) of record_test_support, re-timed to i * dt.
SessionRows rows(std::size_t haptic, double haptic_dt_s, std::size_t sim, double sim_dt_s);

// A closed session (record::testing::write_test_session): test_frame(0 ..
// frames-1) (30 Hz), haptic rows for the same span at 1 kHz (frames * 1000 /
// 30 rows), sim rows at 50 Hz, no events. Returns path. Files no reader
// accepts: record::testing::bad_session_files.
std::string write_session(const std::string& path, std::uint64_t frames);

}  // namespace tissue::replay::testing
