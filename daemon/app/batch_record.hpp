// Recording a batch run (`tissued --batch ... --record FILE`) into the same
// HDF5 session file the service writes (docs/session-format.md), so
// `tissue session info / x3d / render / replay` work on batch runs too.
//
// A batch run is not paced, so the session's clock is simulated time: one
// sim row per step (its step_ms and real_time_factor are the step's own wall
// time and pace), a surface frame every frame_interval_s of simulated time
// from the initial state on, and the last state; events say how the run
// started and how it ended (or why it failed). No haptic rows: a batch run
// has no device. Recording does not touch the simulation, so the report is
// the same with or without it.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "physics/simulation.hpp"
#include "record/record_types.hpp"
#include "record/session_writer.hpp"
#include "service/mesh_snapshot.hpp"

namespace tissue::app {

class BatchRecorder {
 public:
  // Creates `path` (never over an existing file; record::RecordError
  // otherwise, naming it) and records the initial state of `sim`.
  // `command` says how the run was made (the scene file, the duration, the
  // overrides); it is stored as the session's config_text. A frame interval
  // that is not a finite number > 0 is std::invalid_argument.
  BatchRecorder(const std::string& path, const physics::Simulation& sim, const std::string& scene_text,
                const std::string& command, double frame_interval_s = 1.0 / 30.0);

  // After each successful step: its sim row, and a frame when one is due.
  // A write error stops the recording (error() says why); the run goes on
  // and what was flushed stays readable.
  void after_step(const physics::Simulation& sim, double step_ms);

  // The last state as a frame (unless it was just written), an event saying
  // how the run ended (`run_error` empty and `interrupted_by` empty: it
  // completed; `interrupted_by`: the signal that stopped it), every row
  // flushed, the file closed cleanly. Returns error(): empty when the whole
  // session was written.
  std::string finish(const physics::Simulation& sim, const std::string& run_error,
                     const std::string& interrupted_by = {});

  const std::string& path() const { return path_; }
  const std::string& error() const { return error_; }
  // Rows written: sim rows, mesh frames, events (tests, the done line).
  std::uint64_t sim_rows() const { return writer_ ? writer_->group_rows()[1] : 0; }
  std::uint64_t mesh_frames() const { return writer_ ? writer_->group_rows()[2] : 0; }
  // Test seam: see record::SessionWriter::set_sync_for_testing.
  void set_sync_for_testing(record::SessionWriter::SyncFile sync) { writer_->set_sync_for_testing(std::move(sync)); }

 private:
  void frame(const physics::Simulation& sim);
  void event(double time_s, record::EventKind kind, const std::string& text);
  void append_rows();
  // The closing event at simulated time `time_s`, then the file closed with
  // the simulated seconds recorded as its duration.
  void end(double time_s, record::EventKind kind, const std::string& text);
  void stop(const std::exception& e);

  std::string path_;
  std::unique_ptr<record::SessionWriter> writer_;
  double frame_interval_s_;
  double start_s_ = 0.0;  // simulated time of the first state
  double last_s_ = 0.0;   // simulated time of the last state seen
  double next_frame_s_ = 0.0;
  double last_frame_s_ = -1.0;
  std::vector<record::SimRow> rows_;  // written in batches of kRowsPerWrite
  service::SnapshotScratch scratch_;
  service::MeshSnapshot snapshot_;
  std::string error_;
};

}  // namespace tissue::app
