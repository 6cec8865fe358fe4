// Batch mode: run a scene for a fixed simulated duration as fast as the
// machine allows (no wall-clock pacing), print live figures, write a JSON
// report.
//
//   tissued --batch --scene FILE --duration SECONDS [--set key.path=value ...]
//           [--report out.json] [--no-timing] [--progress SECONDS] [--record session.h5]
//
// The report (keys sorted, doubles printed so they round-trip; every field:
// docs/batch-report.md):
//   scene   {source, name, overrides, integrator, dt_s, adaptivity}
//   result  {sim_time_s, steps, nodes/tets/springs {final, peak}, refines,
//            merges, refine_ceiling_passes, energy_J {kinetic, elastic}, external_work_J (loads,
//            gravity), prescribed_work_J (drivers of prescribed nodes),
//            adaptation_energy_J {net, added} (what splits and merges
//            changed the kinetic + elastic energy by; see SimCounters),
//            energy_audit {worst_excess, at_t_s} (the most the body held
//            beyond E0 + work + adaptation net, physics/diagnostics.hpp),
//            inverted_tets {final, peak, peak_at_t_s},
//            nonfinite_events, rejected_steps, error (null | message),
//            interrupted_by (null | "SIGINT" | "SIGTERM"),
//            solver {substeps {mean, max}, iterations {mean, max},
//                    unconverged_steps, offset_layout_steps,
//                    verified_substep_steps, rerun_steps,
//                    energy_limited {steps, removed_J}},
//            probes {NAME: {final_displacement_m [x,y,z], peak_magnitude_m}}}
//   timing  {wall_s, step_ms {p50, p99, max}, real_time_factor}
// Everything except `timing` depends only on the scene and the overrides, so
// it is bit-identical from run to run; with timing off (--no-timing) the
// whole file is.
//
// --record writes the run as an HDF5 session (batch_record.hpp) for the
// session tools (info, x3d, render, replay); the report is the same with or
// without it.
//
// A step that fails (the integrator refused it, or the state went
// non-finite; the simulation keeps its previous state) ends the run: the
// report is still written, with result.error set.
//
// SIGINT (Ctrl-C) or SIGTERM ends the run after the step in progress: the
// report and the session cover the run so far (result.interrupted_by names
// the signal) and the exit code is 128 + the signal's number, as a shell
// reports a process the signal killed. Asked again a second later, it kills;
// a SIGINT the process was started ignoring (a background job `&` of a
// script) stays ignored, a SIGTERM is honoured even then
// (util/stop_signals.hpp).
#pragma once

#include <atomic>
#include <cstdio>
#include <functional>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "physics/simulation.hpp"
#include "scene/scene.hpp"

namespace tissue::app {

struct BatchOptions {
  std::string scene_path;
  std::vector<std::string> overrides;           // "key.path=value", applied in order
  double duration_s = 0.0;                      // simulated seconds
  std::string report_path;                      // empty: no report file
  bool timing = true;                           // include the wall-clock `timing` object
  double progress_every_s = 0.1;                // simulated seconds between live lines; 0 = quiet
  std::string record_path;                      // empty: no session file (batch_record.hpp)
  double record_frame_interval_s = 1.0 / 30.0;  // simulated seconds between recorded surface frames
};

// Process exit codes of `tissued --batch`.
enum ExitCode : int {
  kExitOk = 0,
  kExitInternal = 1,   // an unexpected exception (out of memory, a bug)
  kExitUsage = 2,      // bad command line or bad scene
  kExitSimFailed = 3,  // a step failed; the report says why
  kExitReport = 4,     // the report file cannot be written
  kExitRecord = 5,     // the session file (--record) cannot be created or written
  // 128 + N: stopped by signal N (SIGINT 130, SIGTERM 143; util/stop_signals.hpp);
  // the report and the session are written.
};

// Steps `sim` until its time reaches options.duration_s (to within a
// millionth of a step, so 2 s at 1 ms is 2000 steps) and returns the report.
// Live lines go to `progress` every options.progress_every_s simulated
// seconds (nothing when it is null or the interval is 0). A failed step ends
// the run early; the report's result.error then holds the reason. Only
// options.duration_s, .timing and .progress_every_s are read.
// `after_step`, when given, sees the simulation after every successful step
// with that step's wall time in ms (the session recorder).
// `stop_signal`, when given, is read before every step: once it holds a
// signal number (SIGINT or SIGTERM; set by util::StopOnSignals) the run ends there and
// result.interrupted_by names it.
nlohmann::json run_batch(physics::Simulation& sim, const BatchOptions& options, std::FILE* progress,
                         const std::function<void(const physics::Simulation&, double step_ms)>& after_step = {},
                         const std::atomic<int>* stop_signal = nullptr);

// The same on a fresh Simulation of `scene`. Throws std::invalid_argument when
// the simulation cannot be built from it (mesh limits, a probe outside the
// object).
nlohmann::json run_batch(const scene::Scene& scene, const BatchOptions& options, std::FILE* progress);

// The report as written to the file: two-space indentation, newline at the end.
std::string report_text(const nlohmann::json& report);

// The warnings batch_command prints to `err` (stderr) after a run that
// succeeded, from its report's `result` and the simulation's counters:
// solver steps short of their tolerance, energy-limited steps, more energy
// than the body was given, adaptation at its ceiling, tets inside out.
// Nothing for a run that passes the stability bar.
void warn_of_health(const scene::Scene& scene, const physics::SimCounters& counters, const nlohmann::json& result,
                    std::FILE* err);

// The whole batch command: loads the scene with the overrides, runs it, writes
// the report, prints a one-line reason on stderr for every failure and
// returns the exit code. Never throws.
int batch_command(const BatchOptions& options);

}  // namespace tissue::app
