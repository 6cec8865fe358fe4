// Replays a recorded session as live data (docs/replay-and-live.md): the
// session's mesh frames, haptic rows and sim rows, merged into one timeline
// in session time, handed to a sink at the recorded pace (or `speed` times
// faster). The sink the `tissue session replay` client uses wraps the
// daemon's own LcmPublisher / DdsPublisher, so a replay is on the wire
// exactly what the daemon sends. The clock is injected: tests pace against a
// fake clock without sleeping.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "export/frame_source.hpp"
#include "record/record_types.hpp"
#include "record/session_tools.hpp"
#include "service/sim_thread.hpp"

namespace tissue::transport {
class LcmPublisher;
class DdsPublisher;
}  // namespace tissue::transport

namespace tissue::replay {

// Bad input (file, options): the message names the file or option and why.
class ReplayError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// The haptic and sim groups of a session: record::read_session_rows (every
// column, complete rows, times finite and non-decreasing), its RecordError
// turned into ReplayError (same message: the file and what is wrong).
using SessionRows = record::SessionRows;
SessionRows read_session_rows(const std::string& path);

// ---------------------------------------------------------------- conversions
// What the publishers take. The message `time_s` of replayed data is the
// session time of the row or frame (one clock for all three streams; the
// session stores no sim time per mesh frame).
//
// Strain: the snapshot carries one value per triangle. A frame with the
// recorded per-triangle values (triangle_strain_energy_J_per_m3, as the
// session source gives) sends them unchanged; a frame with only per-vertex
// values gives each triangle the mean of its three vertices; a frame without
// strain gives an empty vector (the encoders then send what they send for
// "not computed").
service::MeshSnapshot to_snapshot(const x3d::SurfaceFrame& frame, std::uint64_t sequence);
// The fields LcmPublisher::publish_haptic / DdsPublisher::publish_haptic read.
service::SimStatus haptic_status(const record::HapticRow& row);
// The fields publish_stats reads.
service::SimStatus sim_status(const record::SimRow& row);

// ---------------------------------------------------------------- timeline
enum class StreamKind : std::uint8_t { kMesh, kHaptic, kStats };

struct TimelineItem {
  double time_s = 0.0;  // session time
  StreamKind kind = StreamKind::kMesh;
  std::size_t index = 0;  // frame number, haptic row or sim row
  bool operator==(const TimelineItem&) const = default;
};

struct TimelineOptions {
  std::optional<double> from_s, to_s;  // window, session time, inclusive
  // Haptic rows are recorded at the loop rate (1 kHz) and sim rows at the
  // sim thread's status rate; the daemon publishes them decimated to
  // publish.haptic_rate_hz / publish.stats_rate_hz, and so does a replay by
  // default. A row is kept when at least 1/rate has passed since the last
  // kept one. 0: every recorded row. Mesh frames are all sent.
  double haptic_rate_hz = 100.0;
  double stats_rate_hz = 5.0;
};

// The three streams (each in time order) merged by time; at equal times mesh
// before haptic before stats. Throws ReplayError for a window whose start is
// after its end or a negative rate.
std::vector<TimelineItem> build_timeline(const std::vector<double>& frame_times_s,
                                         const std::vector<double>& haptic_times_s,
                                         const std::vector<double>& sim_times_s, const TimelineOptions& options);

// ---------------------------------------------------------------- pacing
// Where replayed items go.
class ReplaySink {
 public:
  virtual ~ReplaySink() = default;
  virtual void mesh(const service::MeshSnapshot& snapshot) = 0;
  virtual void haptic(const service::SimStatus& status) = 0;
  virtual void stats(const service::SimStatus& status) = 0;
  // A hole the recorder left in /haptic (record::HapticHole) starts: no
  // haptic state comes until its row_after. Nothing goes on the wire (no
  // message says "no data"); the CLI prints it.
  virtual void haptic_hole(const record::HapticHole& /*hole*/) {}
};

// The daemon's publishers as a sink (either may be null).
class PublisherSink final : public ReplaySink {
 public:
  PublisherSink(transport::LcmPublisher* lcm, transport::DdsPublisher* dds) : lcm_(lcm), dds_(dds) {}
  void mesh(const service::MeshSnapshot& snapshot) override;
  void haptic(const service::SimStatus& status) override;
  void stats(const service::SimStatus& status) override;

 private:
  transport::LcmPublisher* lcm_;
  transport::DdsPublisher* dds_;
};

class ReplayClock {
 public:
  virtual ~ReplayClock() = default;
  virtual double now_s() = 0;
  // Returns true once now_s() >= t_s, false as soon as `stop` is set.
  virtual bool wait_until(double t_s, const std::atomic<bool>& stop) = 0;
};

// steady_clock; sleeps in slices of at most 20 ms so a stop request (Ctrl-C)
// is seen promptly even before a long gap in the recording.
class SteadyReplayClock final : public ReplayClock {
 public:
  double now_s() override;
  bool wait_until(double t_s, const std::atomic<bool>& stop) override;
};

// Speeds a replay accepts: below, a recording's next item can be due after
// longer than anyone waits; above, there is no pace left to keep.
constexpr double kMinSpeed = 1e-3, kMaxSpeed = 1e6;
// A looped pass must last this much wall time (span / speed): shorter ones
// publish as fast as the transport takes them, for ever.
constexpr double kMinLoopPass_s = 1e-3;

struct ReplayOptions {
  double speed = 1.0;  // session seconds per wall second, kMinSpeed to kMaxSpeed
  TimelineOptions timeline;
  // Start over after the last item, for ever (until stop). The next pass
  // starts as soon as the previous one has ended. The window's span / speed
  // must be at least kMinLoopPass_s.
  bool loop = false;
};

struct ReplaySummary {
  std::uint64_t frames = 0, haptic_rows = 0, stats = 0;  // items handed to the sink
  std::uint64_t passes = 0;                              // passes completed
  bool stopped = false;                                  // ended by `stop`
  double session_span_s = 0.0;  // session time covered: first to last item sent, summed over passes
  double wall_s = 0.0;          // from the start to the last item sent
  // Items sent more than 10 ms after their due time (a publish or a frame
  // read slower than the pace) and the worst lag. The schedule stays anchored
  // at the start, so a slow item delays only itself and those right after it.
  std::uint64_t late_items = 0;
  double max_lag_s = 0.0;
  // Recorder holes crossed (announced to the sink), summed over passes, and
  // the session time between the rows on either side of them.
  std::uint64_t haptic_holes = 0;
  double haptic_hole_time_s = 0.0;
  // Session seconds per wall second achieved (≈ speed when on time).
  double pace() const { return wall_s > 0.0 ? session_span_s / wall_s : 0.0; }
};

// The items of build_timeline(options.timeline) from `frames` and `rows`,
// item i of pass p (from 0) due at start + (p · span + time_s[i] - time_s[0])
// / speed on `clock`, span the last item's time minus the first's. Mesh
// frames are read from the source before their due time, so reading does not
// delay sending. Mesh snapshots get sequences 1, 2, … over all passes.
// Returns when done or as soon as `stop` is set. Throws ReplayError for bad
// options, x3d::SourceError when a frame cannot be read.
ReplaySummary replay_session(x3d::FrameSource& frames, const SessionRows& rows, const ReplayOptions& options,
                             ReplaySink& sink, ReplayClock& clock, const std::atomic<bool>& stop);

}  // namespace tissue::replay
