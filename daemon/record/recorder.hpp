// Recorder: records one session on its own thread.
//
// Producers (the haptic thread, the sim thread, the control/io thread) call
// the push_* functions: they copy into preallocated lock-free rings and
// return at once. They never allocate, lock, block or do I/O; when a ring is
// full or the recording has failed or stopped, the push returns false and is
// counted as a drop. Each push function has exactly ONE producer thread (the
// rings are single-producer): haptic rows from the haptic thread, sim rows
// and mesh frames from the sim thread, events from the thread named by
// EventSource.
//
// The recorder thread drains the rings every poll interval, writes mesh
// frames as they arrive and the row groups in batches, and flushes the file
// at least every flush_interval_s, so a concurrent SWMR reader sees the
// session grow and a crash loses at most about one flush interval (a power
// cut too: each flush ends with an fdatasync of the file).
//
// Haptic rows the ring refuses (it is full: the disk stalled longer than the
// ring holds) are also written into the file, as a hole: a warning event
// naming the recorded rows on either side and how many ticks are missing
// (HapticHole, docs/session-format.md). Each row carries the ring's drop
// count into the ring (one load of a counter its own thread writes), so the
// recorder thread knows exactly which two rows a run of drops fell between.
// A hole's event is flushed and synced before the rows after the hole are
// written, so no crash leaves those rows without it.
//
// Every push is either written or counted as a drop, also when producers
// keep pushing while the recorder stops or fails (a retired recorder whose
// sim thread has not let go of it yet): a push that returned true is in the
// file, unless recording failed (then it is counted as a drop) or the writer
// refused the frame (mesh_frames_invalid, with a warning event). The recorder
// thread closes the rings to producers before its last drain: it sets
// closing_ (pushes are refused and counted from then on) and waits for any
// push already past that check to finish (each ring's producer flags its
// push in progress; the wait is a few instructions long, or one frame copy),
// so nothing can land in a ring after the last drain.
//
// Failure (disk full, file too large, I/O error, disk space below the
// reserve): recording stops, state() becomes kFailed, error() says which file
// and why, on_error is called once (from the recorder thread) so the daemon
// can log it and publish it as an event; producers keep running, and their
// pushes become counted drops. After a write failure so do the rows, events
// and frames accepted earlier that were not written. The free-space reserve
// is a controlled stop instead (the file still takes writes): closed to
// producers, everything accepted written, a recording_error event, a clean
// close, and only then kFailed.
//
// HDF5 is used only from the recorder thread (start() creates the file on the
// calling thread, before the recorder thread exists).
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "concurrency/spsc_ring.hpp"
#include "record/record_types.hpp"

namespace tissue::record {

class SessionWriter;

struct RecorderOptions {
  // Longest time between file flushes: bounds what a crash loses. (0, 1].
  double flush_interval_s = 0.25;
  // How often the recorder thread drains the rings (mesh frames are written
  // when drained, so this also bounds how long a frame buffer stays busy).
  double poll_interval_s = 0.01;
  // mesh_frame_due() says yes once per interval on average (0: always). 1/30 s = 30 Hz.
  double mesh_frame_interval_s = 1.0 / 30.0;
  // Frame buffers are allocated once at start() with these capacities; a
  // bigger frame is refused (counted in mesh_frames_too_big).
  std::size_t mesh_max_vertices = 100'000;
  std::size_t mesh_max_triangles = 200'000;
  // (The first such frame gets a warning event in the session naming its
  // size and these capacities, once per recording: every later frame of
  // the same surface would be over them too.)
  std::size_t mesh_frame_buffers = 4;  // 2..16
  // Stop recording (everything accepted written, then a recording_error
  // event and a clean close; state kFailed with the reason) when the file
  // system has less free space than this, rather than writing until ENOSPC.
  // 0 disables the check.
  std::uint64_t min_free_bytes = 64ull << 20;
  // Called once from the recorder thread when recording fails (message =
  // error()). Must not block for long.
  std::function<void(const std::string& message)> on_error;
  // Test seam (never set in the daemon): given to the session's writer, see
  // SessionWriter::set_write_fault_for_testing. Called on the recorder
  // thread only.
  std::function<void(const char* dataset_path)> write_fault_for_testing;
  // Likewise, SessionWriter::set_flush_fault_for_testing.
  std::function<void(const char* dataset_path)> flush_fault_for_testing;
};

enum class RecorderState : int { kRecording, kFailed, kStopped };

// Which thread pushes an event: one ring per source keeps every ring
// single-producer.
enum class EventSource : int { kControl = 0, kSim = 1, kHaptic = 2 };
inline constexpr int kEventSourceCount = 3;

struct RecorderStats {
  std::uint64_t haptic_rows_written = 0, sim_rows_written = 0, mesh_frames_written = 0, events_written = 0;
  std::uint64_t haptic_drops = 0, sim_drops = 0, mesh_frame_drops = 0, event_drops = 0;
  // Of haptic_drops, the rows the haptic ring refused because it was full
  // (the rest were pushed after the recording closed): once stopped, exactly
  // the ticks the file's hole events name (HapticHole).
  std::uint64_t haptic_drops_ring_full = 0;
  std::uint64_t mesh_frames_too_big = 0;  // refused at push: over the buffer capacity (also in drops)
  std::uint64_t mesh_frames_invalid = 0;  // refused by the writer: bad indices, levels, strain, coordinates
  std::uint64_t bytes_written = 0;        // payload bytes handed to HDF5
  std::uint64_t flushes = 0;
};

class Recorder {
 public:
  static constexpr std::size_t kHapticRingRows = 8192;  // 8 s at 1 kHz: rides out slow disk writes
  static constexpr std::size_t kSimRingRows = 1024;
  static constexpr std::size_t kEventRingRows = 256;

  // Creates `state_dir/name` (SessionWriter::open_in rules: plain file name,
  // existing directory, never overwrites) and starts the recorder thread.
  // Throws RecordError naming the file and the reason. Call from a non-real-
  // time thread.
  static std::unique_ptr<Recorder> start(const std::string& state_dir, const std::string& name,
                                         const SessionMetadata& metadata, RecorderOptions options = {});

  // stop().
  ~Recorder();
  Recorder(const Recorder&) = delete;
  Recorder& operator=(const Recorder&) = delete;

  // ---- producer side: wait-free, no allocation, no lock ----------------
  // One producer thread each. In the daemon both are the sim thread: it
  // drains the haptic loop's tool samples and pushes them as haptic rows.
  bool push_haptic(const HapticRow& row) noexcept;
  bool push_sim(const SimRow& row) noexcept;
  bool push_event(EventSource source, const Event& event) noexcept;
  // Sim thread only: true when a frame is wanted at `time_s` (session time),
  // so the surface is extracted only when it will be recorded.
  bool mesh_frame_due(double time_s) const noexcept;
  // Sim thread only: copies the frame into a free preallocated buffer.
  // False (a drop) when no buffer is free, the frame is over capacity, or
  // recording is not running.
  bool push_mesh_frame(const MeshFrameView& frame) noexcept;

  // Session time: seconds since start() on the steady clock. ToolSample's
  // time_ns is steady_clock nanoseconds, so session_time_s(sample.time_ns).
  double session_time_s(std::int64_t steady_ns) const noexcept;
  double session_time_s_now() const noexcept;

  // ---- control side -----------------------------------------------------
  // Refuses further pushes (counted as drops), drains what was pushed,
  // writes it, flushes and closes the file cleanly (closed_cleanly = 1).
  // Idempotent. After a failure it only joins the thread. Never throws: see
  // state() / error().
  void stop();

  RecorderState state() const noexcept { return state_.load(std::memory_order_acquire); }
  // Empty unless state() == kFailed (or the final close failed).
  std::string error() const;
  RecorderStats stats() const noexcept;
  const std::string& path() const { return path_; }

 private:
  struct FrameBuffer {
    double time_s = 0.0;
    std::size_t vertex_count = 0, triangle_count = 0;
    bool has_levels = false;
    bool levels_mismatch = false;
    bool has_strain = false;
    bool strain_mismatch = false;
    std::vector<std::array<double, 3>> vertices_m;
    std::vector<std::array<std::uint32_t, 3>> triangles;
    std::vector<std::uint8_t> vertex_level;
    std::vector<float> triangle_strain_energy_J_per_m3;
  };
  static constexpr std::size_t kMaxFrameBuffers = 16;

  // A producer's push in progress: one flag per ring (one producer each), on
  // its own cache line. See PushGuard in recorder.cpp.
  struct alignas(concurrency::kCacheLineBytes) PushFlag {
    std::atomic<bool> busy{false};
  };
  class PushGuard;

  Recorder(std::unique_ptr<SessionWriter> writer, RecorderOptions options);
  void run();
  bool drain_and_write(bool force_flush);
  // "" or why recording stops: less free space than min_free_bytes (checked
  // at most once a second).
  std::string free_space_shortfall();
  void set_failed(const std::string& message);
  void close_to_producers() noexcept;
  void count_unwritten_as_drops();
  void count_flush_done();
  bool accepting() const noexcept {
    return !closing_.load(std::memory_order_relaxed) &&
           state_.load(std::memory_order_relaxed) == RecorderState::kRecording;
  }

  RecorderOptions options_;
  std::unique_ptr<SessionWriter> writer_;  // recorder thread only (after start)
  std::string path_;
  std::chrono::steady_clock::time_point start_;

  // A haptic row in its ring, with the ring's drop count when it was
  // pushed: a count above the row before's means the ring refused rows
  // between the two, a hole the recorder thread writes into the file
  // (HapticHole) so a reader does not take it for the haptic loop skipping
  // ticks or the device sending nothing.
  struct HapticSlot {
    HapticRow row;
    std::uint64_t drops_before = 0;
  };
  concurrency::SpscRing<HapticSlot, kHapticRingRows> haptic_ring_;
  concurrency::SpscRing<SimRow, kSimRingRows> sim_ring_;
  concurrency::SpscRing<Event, kEventRingRows> event_rings_[kEventSourceCount];
  // Frame buffers move between the sim thread and the recorder thread by
  // index: free_frames_ (recorder → sim) and ready_frames_ (sim → recorder).
  std::vector<FrameBuffer> frames_;
  concurrency::SpscRing<std::uint32_t, kMaxFrameBuffers> free_frames_;
  concurrency::SpscRing<std::uint32_t, kMaxFrameBuffers> ready_frames_;
  double next_frame_due_s_ = -1e300;  // sim thread only
  std::atomic<std::uint64_t> mesh_frames_too_big_{0};
  // The first oversized frame's size and time, for the recorder thread's
  // warning (building it on the sim thread would allocate). Written by the
  // sim thread only before mesh_frames_too_big_ first becomes nonzero (a
  // release increment), never again, so the recorder thread reads them
  // whole once it sees the count.
  std::size_t too_big_vertices_ = 0, too_big_triangles_ = 0;
  double too_big_time_s_ = 0.0;
  bool too_big_warned_ = false;  // recorder thread only
  std::atomic<std::uint64_t> mesh_frame_drops_{0};
  // Refused at push, or accepted and then not written because recording
  // failed.
  std::atomic<std::uint64_t> refused_haptic_{0}, refused_sim_{0}, refused_events_{0};
  // Closing phase (see the top of this file): closing_ is set once, by the
  // recorder thread, before its last drain.
  std::atomic<bool> closing_{false};
  PushFlag haptic_push_, sim_push_, frame_push_, event_push_[kEventSourceCount];

  // Recorder thread only: the haptic rows drained so far (so the next one's
  // row in /haptic: every row drained is written, or recording fails), the
  // last one's session time, and the ring drops already written as holes.
  std::uint64_t haptic_rows_drained_ = 0;
  double last_haptic_time_s_ = 0.0;
  std::uint64_t haptic_drops_in_holes_ = 0;
  // pending_events_ holds a hole's event: the next flush writes the events
  // first (drain_and_write says why).
  bool hole_event_pending_ = false;
  // Queues the hole event for the rows the ring refused since the last hole
  // (its drop count is now `drops`), before `next` (nullptr: none follows,
  // the recording stops).
  void note_haptic_hole(std::uint64_t drops, const HapticRow* next);

  // Recorder-thread batch buffers (reserved at start).
  std::vector<HapticRow> pending_haptic_;
  std::vector<SimRow> pending_sim_;
  std::vector<Event> pending_events_;
  // Frames appended to the file since the last successful flush: written
  // after the next one, dropped if recording fails first.
  std::uint64_t frames_unflushed_ = 0;
  std::chrono::steady_clock::time_point next_flush_;
  std::chrono::steady_clock::time_point next_space_check_;

  std::atomic<RecorderState> state_{RecorderState::kRecording};
  std::atomic<std::uint64_t> haptic_written_{0}, sim_written_{0}, frames_written_{0}, events_written_{0};
  std::atomic<std::uint64_t> frames_invalid_{0}, bytes_written_{0}, flushes_{0};

  mutable std::mutex mutex_;  // control side only: stop flag, error text
  std::condition_variable wake_;
  bool stop_requested_ = false;
  std::string error_;
  std::thread thread_;
  bool joined_ = false;
};

}  // namespace tissue::record
