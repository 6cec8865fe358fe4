#include "app/batch_record.hpp"

#include <cmath>
#include <cstdio>
#include <exception>
#include <limits>
#include <stdexcept>

namespace tissue::app {

namespace {

// Sim rows go to the file in batches (one HDF5 append per batch, not per
// step) and become visible to readers at each flush.
constexpr std::size_t kRowsPerWrite = 1000;

std::string seconds_text(double s) {
  char buf[48];
  std::snprintf(buf, sizeof buf, "%.6g s", s);
  return buf;
}

}  // namespace

BatchRecorder::BatchRecorder(const std::string& path, const physics::Simulation& sim, const std::string& scene_text,
                             const std::string& command, double frame_interval_s)
    : path_(path), frame_interval_s_(frame_interval_s) {
  if (!(frame_interval_s > 0.0) || !std::isfinite(frame_interval_s))
    throw std::invalid_argument("batch recording: the frame interval must be a finite number of seconds > 0");
  record::SessionMetadata meta;
  meta.scene_name = sim.scene().name;
  meta.scene_text = scene_text;
  meta.config_text = command;
  meta.software_version = TISSUE_VERSION;
  writer_ = record::SessionWriter::create(path, meta);
  start_s_ = last_s_ = sim.time_s();
  rows_.reserve(kRowsPerWrite);
  try {
    event(sim.time_s(), record::EventKind::kSceneLoaded,
          "batch run of scene '" + sim.scene().name + "' (" + sim.integrator().name() + " integrator): " + command);
    frame(sim);
  } catch (const std::exception& e) {
    stop(e);
  }
}

void BatchRecorder::after_step(const physics::Simulation& sim, double step_ms) {
  if (!error_.empty()) return;
  last_s_ = sim.time_s();
  try {
    record::SimRow row;
    row.time_s = row.sim_time_s = sim.time_s();
    row.step_ms = step_ms;
    row.real_time_factor =
        step_ms > 0.0 ? 1e3 * sim.scene().integrator.dt_s / step_ms : std::numeric_limits<double>::quiet_NaN();
    const auto& m = sim.body().mesh();
    row.nodes = m.node_count();
    row.tets = m.tet_count();
    row.springs = m.edge_count();
    row.refines = sim.counters().splits;
    row.merges = sim.counters().merges;
    row.kinetic_J = sim.kinetic_energy_J();
    row.elastic_J = sim.elastic_energy_J();
    rows_.push_back(row);
    // Frames on the grid k·interval of simulated time; a millionth of a step
    // of slack, as the run's own end (2000 steps of 1 ms end a hair below 2 s).
    if (sim.time_s() >= next_frame_s_ - 1e-6 * sim.scene().integrator.dt_s) {
      frame(sim);
    } else if (rows_.size() >= kRowsPerWrite) {
      append_rows();
      writer_->flush(record::SessionWriter::Sync::kNone);
    }
  } catch (const std::exception& e) {
    stop(e);
  }
}

std::string BatchRecorder::finish(const physics::Simulation& sim, const std::string& run_error,
                                  const std::string& interrupted_by) {
  if (!error_.empty() || !writer_) return error_;
  last_s_ = sim.time_s();
  try {
    if (sim.time_s() != last_frame_s_) frame(sim);
    const std::string when =
        "at t = " + seconds_text(sim.time_s()) + " after " + std::to_string(sim.counters().steps) + " steps";
    if (!run_error.empty())
      end(sim.time_s(), record::EventKind::kError, "batch run failed " + when + ": " + run_error);
    else if (!interrupted_by.empty())
      end(sim.time_s(), record::EventKind::kInfo, "batch run interrupted by " + interrupted_by + " " + when);
    else
      end(sim.time_s(), record::EventKind::kInfo, "batch run completed " + when);
  } catch (const std::exception& e) {
    stop(e);
  }
  return error_;
}

void BatchRecorder::frame(const physics::Simulation& sim) {
  append_rows();
  service::build_mesh_snapshot(sim, &scratch_, &snapshot_);
  record::MeshFrameView view;
  view.time_s = sim.time_s();
  view.vertices_m = snapshot_.vertices_m;
  view.triangles = snapshot_.triangles;
  view.vertex_level = snapshot_.vertex_level;
  view.triangle_strain_energy_J_per_m3 = snapshot_.triangle_strain_energy_J_per_m3;
  writer_->append_mesh_frame(view);
  // Readers may follow a batch run; durability waits for the close: a batch
  // run is repeatable, and a sync per frame (every 1/30 s of simulated time)
  // made a recorded 10 s cantilever run take 4.7 s instead of 1.8 s.
  writer_->flush(record::SessionWriter::Sync::kNone);
  last_frame_s_ = sim.time_s();
  const double slack_s = 1e-6 * sim.scene().integrator.dt_s;
  next_frame_s_ = (std::floor((sim.time_s() + slack_s) / frame_interval_s_) + 1.0) * frame_interval_s_;
}

void BatchRecorder::event(double time_s, record::EventKind kind, const std::string& text) {
  const record::Event e = record::Event::make(time_s, kind, text);
  writer_->append_events({&e, 1});
}

// Pending sim rows to the file; readers see them at the next flush.
void BatchRecorder::append_rows() {
  if (rows_.empty()) return;
  writer_->append_sim(rows_);
  rows_.clear();
}

void BatchRecorder::end(double time_s, record::EventKind kind, const std::string& text) {
  event(time_s, kind, text);
  append_rows();
  // Session time is simulated time here, so is the session's duration.
  writer_->close(time_s - start_s_);
}

void BatchRecorder::stop(const std::exception& e) {
  error_ = "recording to " + path_ + " stopped: " + e.what();
  // What was flushed stays; the file reads as not closed cleanly unless the
  // writer can still close it (an invalid frame leaves the file usable, and
  // then the rows not yet written go in too). A failed writer takes nothing
  // more: the rows since the last write (at most a frame interval's) are lost.
  try {
    if (writer_ && !writer_->failed()) end(last_s_, record::EventKind::kRecordingError, error_);
  } catch (const std::exception&) {
    // The destructor closes what is left, swallowing errors.
  }
  rows_.clear();
}

}  // namespace tissue::app
