#include "record/recorder.hpp"

#include <sys/statvfs.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <iterator>
#include <stdexcept>

#include "record/session_writer.hpp"

namespace tissue::record {

namespace {

using Clock = std::chrono::steady_clock;

Clock::duration seconds(double s) {
  return std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(s));
}

}  // namespace

std::unique_ptr<Recorder> Recorder::start(const std::string& state_dir, const std::string& name,
                                          const SessionMetadata& metadata, RecorderOptions options) {
  if (!(options.flush_interval_s > 0.0 && options.flush_interval_s <= 1.0))
    throw RecordError("recorder: flush_interval_s must be in (0, 1] s, got " +
                      std::to_string(options.flush_interval_s));
  if (!(options.poll_interval_s > 0.0 && options.poll_interval_s <= options.flush_interval_s))
    throw RecordError("recorder: poll_interval_s must be in (0, flush_interval_s]");
  if (!(options.mesh_frame_interval_s >= 0.0) || !std::isfinite(options.mesh_frame_interval_s))
    throw RecordError("recorder: mesh_frame_interval_s must be >= 0");
  if (options.mesh_frame_buffers < 2 || options.mesh_frame_buffers > kMaxFrameBuffers)
    throw RecordError("recorder: mesh_frame_buffers must be in [2, 16]");
  auto writer = SessionWriter::open_in(state_dir, name, metadata);
  if (options.write_fault_for_testing) writer->set_write_fault_for_testing(options.write_fault_for_testing);
  if (options.flush_fault_for_testing) writer->set_flush_fault_for_testing(options.flush_fault_for_testing);
  auto recorder = std::unique_ptr<Recorder>(new Recorder(std::move(writer), std::move(options)));
  recorder->thread_ = std::thread([r = recorder.get()] { r->run(); });
  return recorder;
}

Recorder::Recorder(std::unique_ptr<SessionWriter> writer, RecorderOptions options)
    : options_(std::move(options)), writer_(std::move(writer)), path_(writer_->path()), start_(Clock::now()) {
  // Everything the producers touch is allocated here, never later.
  frames_.resize(options_.mesh_frame_buffers);
  for (std::uint32_t i = 0; i < frames_.size(); ++i) {
    frames_[i].vertices_m.resize(options_.mesh_max_vertices);
    frames_[i].triangles.resize(options_.mesh_max_triangles);
    frames_[i].vertex_level.resize(options_.mesh_max_vertices);
    frames_[i].triangle_strain_energy_J_per_m3.resize(options_.mesh_max_triangles);
    free_frames_.try_push(i);
  }
  pending_haptic_.reserve(2 * kHapticRingRows);
  pending_sim_.reserve(2 * kSimRingRows);
  pending_events_.reserve(2 * kEventSourceCount * kEventRingRows);
  next_flush_ = start_ + seconds(options_.flush_interval_s);
  next_space_check_ = start_;
}

Recorder::~Recorder() { stop(); }

// Producer side of the closing phase, around one push (check and ring
// write): raises the ring's busy flag, then reads closing_; clears the flag
// when the push is over. The recorder thread does the mirror image in
// close_to_producers(): sets closing_, then reads every busy flag. With all
// four accesses seq_cst (a store-load pair on each side, as in Dekker's
// algorithm) at least one side sees the other's store: either this push
// sees closing_ and is refused (counted), or the recorder sees the flag
// raised and waits for it to clear. The clearing store (release) follows the
// ring write, and the recorder reads it (seq_cst, so acquire) before its last
// drain, so the drain sees the element. The producer pays two stores to its
// own flag (the seq_cst one is an xchg on x86) and two loads: no lock, no
// wait, no allocation, no system call.
class Recorder::PushGuard {
 public:
  PushGuard(const Recorder& recorder, PushFlag& flag) noexcept : busy_(flag.busy) {
    busy_.store(true, std::memory_order_seq_cst);
    open_ = !recorder.closing_.load(std::memory_order_seq_cst) &&
            recorder.state_.load(std::memory_order_relaxed) == RecorderState::kRecording;
  }
  ~PushGuard() { busy_.store(false, std::memory_order_release); }
  PushGuard(const PushGuard&) = delete;
  PushGuard& operator=(const PushGuard&) = delete;
  // False: recording has stopped, is stopping or has failed; refuse.
  bool open() const noexcept { return open_; }

 private:
  std::atomic<bool>& busy_;
  bool open_ = false;
};

bool Recorder::push_haptic(const HapticRow& row) noexcept {
  const PushGuard push(*this, haptic_push_);
  if (!push.open()) {
    refused_haptic_.fetch_add(1, std::memory_order_relaxed);
    return false;
  }
  // The drop count so far goes with the row: the ring's own counter, which
  // only this thread writes (a relaxed load, no wait).
  return haptic_ring_.try_push(HapticSlot{row, haptic_ring_.drops()});
}

bool Recorder::push_sim(const SimRow& row) noexcept {
  const PushGuard push(*this, sim_push_);
  if (!push.open()) {
    refused_sim_.fetch_add(1, std::memory_order_relaxed);
    return false;
  }
  return sim_ring_.try_push(row);
}

bool Recorder::push_event(EventSource source, const Event& event) noexcept {
  const int s = static_cast<int>(source);
  if (s < 0 || s >= kEventSourceCount) {
    refused_events_.fetch_add(1, std::memory_order_relaxed);
    return false;
  }
  const PushGuard push(*this, event_push_[s]);
  if (!push.open()) {
    refused_events_.fetch_add(1, std::memory_order_relaxed);
    return false;
  }
  return event_rings_[s].try_push(event);
}

bool Recorder::mesh_frame_due(double time_s) const noexcept { return accepting() && time_s >= next_frame_due_s_; }

bool Recorder::push_mesh_frame(const MeshFrameView& frame) noexcept {
  const auto drop = [&] {
    mesh_frame_drops_.fetch_add(1, std::memory_order_relaxed);
    return false;
  };
  // Held until the buffer is handed over in ready_frames_ (the recorder's
  // wait covers the copy).
  const PushGuard push(*this, frame_push_);
  if (!push.open()) return drop();
  if (frame.vertices_m.size() > options_.mesh_max_vertices || frame.triangles.size() > options_.mesh_max_triangles) {
    // The first one's size, for the recorder thread's warning (see
    // too_big_vertices_); this thread is the count's only writer.
    if (mesh_frames_too_big_.load(std::memory_order_relaxed) == 0) {
      too_big_vertices_ = frame.vertices_m.size();
      too_big_triangles_ = frame.triangles.size();
      too_big_time_s_ = frame.time_s;
    }
    mesh_frames_too_big_.fetch_add(1, std::memory_order_release);
    return drop();
  }
  std::uint32_t index = 0;
  if (!free_frames_.try_pop(index)) return drop();
  FrameBuffer& b = frames_[index];
  b.time_s = frame.time_s;
  b.vertex_count = frame.vertices_m.size();
  b.triangle_count = frame.triangles.size();
  b.has_levels = !frame.vertex_level.empty();
  // Refused on the recorder thread, where an event can say why (building
  // the message here would allocate).
  b.levels_mismatch = b.has_levels && frame.vertex_level.size() != b.vertex_count;
  std::copy(frame.vertices_m.begin(), frame.vertices_m.end(), b.vertices_m.begin());
  std::copy(frame.triangles.begin(), frame.triangles.end(), b.triangles.begin());
  if (b.has_levels && !b.levels_mismatch)
    std::copy(frame.vertex_level.begin(), frame.vertex_level.end(), b.vertex_level.begin());
  const auto& strain = frame.triangle_strain_energy_J_per_m3;
  b.has_strain = !strain.empty();
  b.strain_mismatch = b.has_strain && strain.size() != b.triangle_count;
  if (b.has_strain && !b.strain_mismatch)
    std::copy(strain.begin(), strain.end(), b.triangle_strain_energy_J_per_m3.begin());
  // ready_frames_ has as many slots as there are buffers: this cannot fail.
  ready_frames_.try_push(index);
  // Due times sit on a fixed grid (k * interval), so a sim loop ticking at
  // an uneven rate still records the configured frame rate on average
  // instead of drifting below it.
  const double interval = options_.mesh_frame_interval_s;
  next_frame_due_s_ = interval > 0.0 ? (std::floor(frame.time_s / interval) + 1.0) * interval : frame.time_s;
  return true;
}

double Recorder::session_time_s(std::int64_t steady_ns) const noexcept {
  const auto t = Clock::time_point(std::chrono::duration_cast<Clock::duration>(std::chrono::nanoseconds(steady_ns)));
  return std::chrono::duration<double>(t - start_).count();
}

double Recorder::session_time_s_now() const noexcept {
  return std::chrono::duration<double>(Clock::now() - start_).count();
}

std::string Recorder::error() const {
  std::lock_guard lock(mutex_);
  return error_;
}

RecorderStats Recorder::stats() const noexcept {
  RecorderStats s;
  s.haptic_rows_written = haptic_written_.load(std::memory_order_relaxed);
  s.sim_rows_written = sim_written_.load(std::memory_order_relaxed);
  s.mesh_frames_written = frames_written_.load(std::memory_order_relaxed);
  s.events_written = events_written_.load(std::memory_order_relaxed);
  s.haptic_drops_ring_full = haptic_ring_.drops();
  s.haptic_drops = s.haptic_drops_ring_full + refused_haptic_.load(std::memory_order_relaxed);
  s.sim_drops = sim_ring_.drops() + refused_sim_.load(std::memory_order_relaxed);
  s.mesh_frame_drops = mesh_frame_drops_.load(std::memory_order_relaxed);
  s.event_drops = refused_events_.load(std::memory_order_relaxed);
  for (const auto& ring : event_rings_) s.event_drops += ring.drops();
  s.mesh_frames_too_big = mesh_frames_too_big_.load(std::memory_order_relaxed);
  s.mesh_frames_invalid = frames_invalid_.load(std::memory_order_relaxed);
  s.bytes_written = bytes_written_.load(std::memory_order_relaxed);
  s.flushes = flushes_.load(std::memory_order_relaxed);
  return s;
}

void Recorder::set_failed(const std::string& message) {
  {
    std::lock_guard lock(mutex_);
    if (!error_.empty()) return;
    error_ = message;
  }
  state_.store(RecorderState::kFailed, std::memory_order_release);
  if (options_.on_error) {
    try {
      options_.on_error(message);
    } catch (...) {
      // A throwing callback must not take the recorder thread (and with it
      // the daemon) down.
    }
  }
}

// The recorder thread's side of the closing phase (PushGuard says why it is
// airtight). After this returns no push can land in a ring or ready_frames_
// any more, and everything pushed before is visible to this thread, so a
// drain now is the last one that can find anything. Producers never block
// inside a push, so the wait lasts at most one push (a few instructions, or
// one frame copy) unless a producer is preempted mid-push; it must not give
// up early (a push finishing after it would be lost again), so it backs off
// to short sleeps instead.
void Recorder::close_to_producers() noexcept {
  closing_.store(true, std::memory_order_seq_cst);
  const auto busy = [](const PushFlag& f) { return f.busy.load(std::memory_order_seq_cst); };
  const auto any_busy = [&] {
    if (busy(haptic_push_) || busy(sim_push_) || busy(frame_push_)) return true;
    return std::any_of(std::begin(event_push_), std::end(event_push_), busy);
  };
  for (int round = 0; any_busy(); ++round) {
    if (round < 100)
      std::this_thread::yield();
    else
      std::this_thread::sleep_for(std::chrono::microseconds(50));
  }
}

// After a failure, once closed to producers: what was accepted but will
// never be written (still in the rings, drained but not yet written, frames
// not yet written or appended but not flushed) is counted as dropped and the
// frame buffers are released.
// Rows of a batch whose write failed part-way are counted too: the file may
// hold some of them, but none were counted as written.
// A flush succeeded: it wrote and synced every dataset appended so far, the
// mesh frames drained since the last flush among them, so they count as
// written (never as drops if a later flush fails), and the flush as done.
void Recorder::count_flush_done() {
  frames_written_.fetch_add(frames_unflushed_, std::memory_order_relaxed);
  frames_unflushed_ = 0;
  bytes_written_.store(writer_->bytes_written(), std::memory_order_relaxed);
  flushes_.fetch_add(1, std::memory_order_relaxed);
}

void Recorder::count_unwritten_as_drops() {
  std::uint64_t haptic = pending_haptic_.size(), sim = pending_sim_.size(), events = pending_events_.size();
  pending_haptic_.clear();
  pending_sim_.clear();
  pending_events_.clear();
  haptic += haptic_ring_.drain([](const HapticSlot&) {});
  sim += sim_ring_.drain([](const SimRow&) {});
  for (auto& ring : event_rings_) events += ring.drain([](const Event&) {});
  // Frames appended since the last successful flush are not in the file.
  std::uint64_t frames = frames_unflushed_;
  frames_unflushed_ = 0;
  std::uint32_t index = 0;
  while (ready_frames_.try_pop(index)) {
    free_frames_.try_push(index);
    ++frames;
  }
  refused_haptic_.fetch_add(haptic, std::memory_order_relaxed);
  refused_sim_.fetch_add(sim, std::memory_order_relaxed);
  refused_events_.fetch_add(events, std::memory_order_relaxed);
  mesh_frame_drops_.fetch_add(frames, std::memory_order_relaxed);
}

std::string Recorder::free_space_shortfall() {
  if (options_.min_free_bytes == 0) return {};
  const auto now = Clock::now();
  if (now < next_space_check_) return {};
  next_space_check_ = now + std::chrono::seconds(1);
  struct statvfs fs {};
  const std::string dir = std::filesystem::path(path_).parent_path().string();
  if (::statvfs(dir.empty() ? "." : dir.c_str(), &fs) != 0) return {};
  const std::uint64_t free_bytes = static_cast<std::uint64_t>(fs.f_bavail) * fs.f_frsize;
  if (free_bytes >= options_.min_free_bytes) return {};
  return "session file '" + path_ + "': disk almost full (" + std::to_string(free_bytes >> 20) + " MiB free, reserve " +
         std::to_string(options_.min_free_bytes >> 20) + " MiB): recording stopped and the file closed";
}

// A hole's event goes out with the next flush, beside the rows around it.
void Recorder::note_haptic_hole(std::uint64_t drops, const HapticRow* next) {
  HapticHole hole;
  hole.ticks_lost = drops - haptic_drops_in_holes_;
  hole.row_after = haptic_rows_drained_;
  // The ring refuses rows only when it is full, so a row always comes before
  // a hole; the other cases are written all the same, never left out.
  if (haptic_rows_drained_ > 0) hole.time_before_s = last_haptic_time_s_;
  if (next) hole.time_after_s = next->time_s;
  const double time_s = hole.has_row_before()  ? hole.time_before_s
                        : hole.has_row_after() ? hole.time_after_s
                                               : session_time_s_now();
  pending_events_.push_back(Event::make(time_s, EventKind::kWarning, haptic_hole_message(hole)));
  haptic_drops_in_holes_ = drops;
  hole_event_pending_ = true;
}

// Returns false once recording has failed. Mesh frames are written as soon as
// they are drained (their buffers go straight back to the sim thread); rows
// are batched and written with the flush. Frames, like rows, count as
// written once a flush after them succeeds.
bool Recorder::drain_and_write(bool force_flush) {
  haptic_ring_.drain([&](const HapticSlot& s) {
    if (s.drops_before != haptic_drops_in_holes_) note_haptic_hole(s.drops_before, &s.row);
    pending_haptic_.push_back(s.row);
    ++haptic_rows_drained_;
    last_haptic_time_s_ = s.row.time_s;
  });
  // The last drain (closed to producers: no push is under way, so the
  // count is final): rows refused after the last one recorded, which no row
  // follows.
  if (closing_.load(std::memory_order_relaxed)) {
    const std::uint64_t drops = haptic_ring_.drops();
    if (drops != haptic_drops_in_holes_) note_haptic_hole(drops, nullptr);
  }
  sim_ring_.drain([&](const SimRow& r) { pending_sim_.push_back(r); });
  for (auto& ring : event_rings_) ring.drain([&](const Event& e) { pending_events_.push_back(e); });

  std::uint32_t index = 0;
  while (ready_frames_.try_pop(index)) {
    const FrameBuffer& b = frames_[index];
    if (!b.levels_mismatch && !b.strain_mismatch) {
      MeshFrameView view;
      view.time_s = b.time_s;
      view.vertices_m = {b.vertices_m.data(), b.vertex_count};
      view.triangles = {b.triangles.data(), b.triangle_count};
      if (b.has_levels) view.vertex_level = {b.vertex_level.data(), b.vertex_count};
      if (b.has_strain)
        view.triangle_strain_energy_J_per_m3 = {b.triangle_strain_energy_J_per_m3.data(), b.triangle_count};
      try {
        writer_->append_mesh_frame(view);
        // Written once the flush that follows succeeds, like the rows.
        ++frames_unflushed_;
      } catch (const std::invalid_argument& e) {
        frames_invalid_.fetch_add(1, std::memory_order_relaxed);
        pending_events_.push_back(
            Event::make(b.time_s, EventKind::kWarning, std::string("mesh frame not recorded: ") + e.what()));
      } catch (...) {
        // The writer failed on this frame: it is a drop, and its buffer
        // goes back before recording fails (count_unwritten_as_drops sees
        // only the frames still waiting).
        mesh_frame_drops_.fetch_add(1, std::memory_order_relaxed);
        free_frames_.try_push(index);
        throw;
      }
    } else {
      frames_invalid_.fetch_add(1, std::memory_order_relaxed);
      pending_events_.push_back(
          Event::make(b.time_s, EventKind::kWarning,
                      b.levels_mismatch ? "mesh frame not recorded: vertex_level size differs from vertex count"
                                        : "mesh frame not recorded: strain value count differs from triangle count"));
    }
    free_frames_.try_push(index);
  }

  // Oversized frames were only counted (in one drops total of the
  // service's status): a surface over the buffers recorded a session with no
  // frames and no word of why. Once per recording, since every later frame
  // of that surface is over them too.
  if (!too_big_warned_ && mesh_frames_too_big_.load(std::memory_order_acquire) > 0) {
    too_big_warned_ = true;
    pending_events_.push_back(Event::make(
        too_big_time_s_, EventKind::kWarning,
        "mesh frame not recorded: " + std::to_string(too_big_vertices_) + " vertices, " +
            std::to_string(too_big_triangles_) + " triangles is over the recorder's frame buffers (at most " +
            std::to_string(options_.mesh_max_vertices) + " vertices, " + std::to_string(options_.mesh_max_triangles) +
            " triangles); such frames are dropped and counted (mesh_frames_too_big), this warning is given once"));
  }

  const auto now = Clock::now();
  const bool ring_pressure = pending_haptic_.size() >= kHapticRingRows;
  if (!force_flush && !ring_pressure && now < next_flush_) return true;
  // A hole's event goes into the file, synced, before the rows after the
  // hole are handed to HDF5 at all. In one flush the writer flushes /haptic
  // before /events, and HDF5 or the kernel may write either out early, so a
  // crash (or power cut) between the two could leave the rows after a hole
  // without its event: the hole invisible, a jump in /haptic/time_s like the
  // loop skipping ticks. This order leaves at worst the event without those
  // rows, which readers keep (its ticks were lost all the same). Only in a
  // flush that carries a hole (rare: the disk stalled for a ring's worth),
  // so the extra sync costs nothing in steady state. Simpler and exact
  // beside the other option, telling holes from the time stamps at read
  // time: rows carry no tick count, and the loop's own skipped ticks and the
  // tool-sample ring's drops make jumps in /haptic/time_s too.
  if (hole_event_pending_) {
    writer_->append_events(pending_events_);
    writer_->flush();
    events_written_.fetch_add(pending_events_.size(), std::memory_order_relaxed);
    count_flush_done();
    pending_events_.clear();
    hole_event_pending_ = false;
  }
  writer_->append_haptic(pending_haptic_);
  writer_->append_sim(pending_sim_);
  writer_->append_events(pending_events_);
  writer_->flush();
  haptic_written_.fetch_add(pending_haptic_.size(), std::memory_order_relaxed);
  sim_written_.fetch_add(pending_sim_.size(), std::memory_order_relaxed);
  events_written_.fetch_add(pending_events_.size(), std::memory_order_relaxed);
  count_flush_done();
  pending_haptic_.clear();
  pending_sim_.clear();
  pending_events_.clear();
  next_flush_ = now + seconds(options_.flush_interval_s);
  return true;
}

void Recorder::run() {
  const auto poll = seconds(options_.poll_interval_s);
  bool stopping = false;
  // The free-space reserve's message once it trips. The writer is healthy
  // then, so it is a controlled stop: everything accepted goes into the file
  // (it used to be thrown away as drops), then the recording_error event,
  // then the clean close; only then does the state say kFailed.
  std::string reserve_tripped;
  while (true) {
    {
      std::unique_lock lock(mutex_);
      wake_.wait_for(lock, poll, [&] { return stop_requested_; });
      stopping = stop_requested_;
    }
    if (!stopping) {
      reserve_tripped = free_space_shortfall();
      stopping = !reserve_tripped.empty();
    }
    // Before the last drain: nothing may be pushed after it (see PushGuard).
    if (stopping) close_to_producers();
    try {
      drain_and_write(stopping);
    } catch (const RecordError& e) {
      set_failed(e.what());  // names the file and what failed in it
      break;
    } catch (const std::exception& e) {
      // Not the writer's own error (std::bad_alloc, ...): its text alone
      // would not say which recording stopped.
      set_failed("recording '" + path_ + "' stopped: " + e.what());
      break;
    }
    if (stopping) break;
  }

  if (state() == RecorderState::kFailed) {
    // kFailed already refuses pushes; this waits out those that passed the
    // check before it, so the count below is the last word.
    close_to_producers();
    // Record the failure in the file when it still takes writes; a broken
    // file just gets closed.
    if (!writer_->failed()) {
      try {
        const Event e = Event::make(session_time_s_now(), EventKind::kRecordingError, error());
        writer_->append_events({&e, 1});
      } catch (const std::exception&) {
        // Already failed and reported; the close below is still due.
      }
    }
    // Whatever happened above: the close releases the recording lock and the
    // HDF5 handles. Skipped after a failed event write, they stayed until the
    // Recorder was destroyed, and `tissue session repair` refused the file
    // as "being recorded" meanwhile.
    try {
      writer_->close();
    } catch (const std::exception&) {
      // Already failed and reported; closing a broken file may fail too.
    }
    count_unwritten_as_drops();
    return;
  }
  // Every row accepted is in the file now (the last drain flushed it).
  std::string close_error;
  std::uint64_t last_events = 0;
  if (!reserve_tripped.empty()) {
    try {
      const Event e = Event::make(session_time_s_now(), EventKind::kRecordingError, reserve_tripped);
      writer_->append_events({&e, 1});
      last_events = 1;
    } catch (const std::exception& e) {
      close_error = e.what();
    }
  }
  // Tried whatever happened above: it releases the recording lock.
  try {
    writer_->close();
    if (close_error.empty()) events_written_.fetch_add(last_events, std::memory_order_relaxed);
  } catch (const std::exception& e) {
    if (close_error.empty()) close_error = e.what();
  }
  if (!reserve_tripped.empty())
    set_failed(close_error.empty() ? reserve_tripped : reserve_tripped + "; then " + close_error);
  else if (!close_error.empty())
    set_failed(close_error);
  else
    state_.store(RecorderState::kStopped, std::memory_order_release);
}

void Recorder::stop() {
  {
    std::lock_guard lock(mutex_);
    if (joined_) return;
    stop_requested_ = true;
  }
  wake_.notify_all();
  if (thread_.joinable()) thread_.join();
  std::lock_guard lock(mutex_);
  joined_ = true;
}

}  // namespace tissue::record
