#include "app/batch_run.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <functional>
#include <memory>
#include <stdexcept>

#include "app/batch_record.hpp"
#include "app/output_file.hpp"
#include "physics/diagnostics.hpp"
#include "physics/forces.hpp"
#include "record/record_types.hpp"
#include "scene/scene_yaml.hpp"
#include "util/output_file.hpp"
#include "util/stop_signals.hpp"

namespace tissue::app {

namespace {

using Clock = std::chrono::steady_clock;

double seconds_between(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double>(b - a).count();
}

// Per-step wall times are kept for the percentiles; reserve them up front so
// the loop does not reallocate, but never more than this many at once (a
// huge duration grows the vector instead of failing before the first step).
constexpr std::size_t kMaxReservedSteps = std::size_t{1} << 25;  // 256 MiB of doubles
// The longest run: its step times (kept for the percentiles) stay under 1 GB.
constexpr double kMaxBatchSteps = 1e8;

// Nearest-rank percentile of sorted values, p in (0, 1].
double percentile(const std::vector<double>& sorted, double p) {
  const auto rank = static_cast<std::size_t>(std::ceil(p * static_cast<double>(sorted.size())));
  return sorted[std::clamp<std::size_t>(rank, 1, sorted.size()) - 1];
}

bool says_nonfinite(const std::string& error) { return error.find("non-finite") != std::string::npos; }

// The energy excess (result.energy_audit.worst_excess) a run is warned of:
// above rounding, below anything a user could see.
constexpr double kReportedEnergyExcess = 1e-6;

// What the integrator spent per step and what accuracy it gave up (steps
// whose solver stopped at cg_max_iterations short of cg_tolerance).
nlohmann::json solver_json(const physics::SimCounters& c) {
  return {{"substeps", {{"mean", c.substeps_per_step()}, {"max", c.max_substeps}}},
          {"iterations", {{"mean", c.solver_iterations_per_step()}, {"max", c.max_solver_iterations}}},
          {"unconverged_steps", c.unconverged_steps},
          {"offset_layout_steps", c.offset_layout_steps},
          {"verified_substep_steps", c.verified_substep_steps},
          {"rerun_steps", c.rerun_steps},
          {"energy_limited", {{"steps", c.energy_limited_steps}, {"removed_J", c.energy_limited_J}}}};
}

struct Tally {
  std::size_t nodes, tets, springs;
};

Tally tally(const physics::Simulation& sim) {
  const auto& m = sim.body().mesh();
  return {m.node_count(), m.tet_count(), m.edge_count()};
}

void print_header(std::FILE* out, const physics::Simulation& sim, double duration_s) {
  const auto& s = sim.scene();
  std::fprintf(out, "tissued batch: scene '%s' (%s), %s integrator, dt %g s, adaptivity %s, %g s simulated\n",
               s.name.c_str(), s.source.c_str(), sim.integrator().name(), s.integrator.dt_s,
               s.adaptivity.enabled ? "on" : "off", duration_s);
  std::fflush(out);
}

void print_progress(std::FILE* out, physics::Simulation& sim, double wall_s) {
  const Tally t = tally(sim);
  const auto& c = sim.counters();
  std::string probes;
  for (std::size_t i = 0; i < sim.probe_count(); ++i) {
    char buf[160];
    std::snprintf(buf, sizeof buf, "  %s %.3f mm", sim.probe_name(i).c_str(), 1e3 * sim.probe_displacement_m(i).norm());
    probes += buf;
  }
  char rtf[32];
  if (wall_s > 0.0)
    std::snprintf(rtf, sizeof rtf, "%.2fx", sim.time_s() / wall_s);
  else
    std::snprintf(rtf, sizeof rtf, "-");
  std::fprintf(out,
               "t %8.3f s | nodes %6zu  tets %7zu  springs %7zu | refines %6lld  merges %6lld |%s | E kin %.3e + el "
               "%.3e J | %s real time\n",
               sim.time_s(), t.nodes, t.tets, t.springs, static_cast<long long>(c.splits),
               static_cast<long long>(c.merges), probes.c_str(), sim.kinetic_energy_J(), sim.elastic_energy_J(), rtf);
  std::fflush(out);
}

// How the run was made, for the session's config_text.
std::string command_text(const BatchOptions& options) {
  std::string text = "tissued --batch --scene " + options.scene_path;
  char duration[48];
  std::snprintf(duration, sizeof duration, " --duration %.17g", options.duration_s);
  text += duration;
  for (const std::string& o : options.overrides) text.append(" --set '").append(o).append("'");
  return text;
}

}  // namespace

nlohmann::json run_batch(physics::Simulation& sim, const BatchOptions& options, std::FILE* progress,
                         const std::function<void(const physics::Simulation&, double step_ms)>& after_step,
                         const std::atomic<int>* stop_signal) {
  const scene::Scene& scene = sim.scene();
  const double dt = scene.integrator.dt_s;
  if (!(dt > 0.0) || !std::isfinite(dt)) throw std::invalid_argument("integrator.dt_s must be a positive number");
  if (!(options.duration_s >= 0.0) || !std::isfinite(options.duration_s))
    throw std::invalid_argument("the duration must be a finite number >= 0");
  // Summed steps round: 2000 steps of 1 ms end a hair below 2 s. Stop within a
  // millionth of a step of the end instead of taking one more step.
  const double slack_s = 1e-6 * dt;
  const double end_s = options.duration_s - slack_s;
  const double every_s = progress ? options.progress_every_s : 0.0;

  std::vector<double> peak_m(sim.probe_count(), 0.0);
  auto track_probes = [&] {
    for (std::size_t i = 0; i < peak_m.size(); ++i) peak_m[i] = std::max(peak_m[i], sim.probe_displacement_m(i).norm());
  };
  track_probes();

  // The run's health, checked after every step outside its timing: the
  // energy held against what was put in (diagnostics.hpp) and the tets
  // turned inside out (springs cannot see inversion; NUMERICS.md §3).
  const physics::EnergyBudget budget(sim);
  double worst_excess = 0.0, worst_excess_at_s = NAN;
  std::size_t inverted_peak = physics::inverted_tet_count(sim.body());
  double inverted_peak_at_s = inverted_peak > 0 ? sim.time_s() : NAN;
  auto track_health = [&] {
    // !(<=): a NaN excess would be kept as the worst, never dropped as `>` does.
    if (const double excess = budget.excess(sim); !(excess <= worst_excess)) {
      worst_excess = excess;
      worst_excess_at_s = sim.time_s();
    }
    if (const std::size_t inverted = physics::inverted_tet_count(sim.body()); inverted > inverted_peak) {
      inverted_peak = inverted;
      inverted_peak_at_s = sim.time_s();
    }
  };

  const double expected_steps = std::ceil(std::max(0.0, options.duration_s - sim.time_s()) / dt) + 1.0;
  std::vector<double> step_ms;
  step_ms.reserve(static_cast<std::size_t>(std::min(expected_steps, static_cast<double>(kMaxReservedSteps))));

  if (every_s > 0.0) print_header(progress, sim, options.duration_s);
  std::string error;
  int interrupted_by = 0;   // the signal that ended the run early, 0 if none
  long long next_line = 1;  // index of the next progress line: printed at next_line * every_s
  const Clock::time_point start = Clock::now();
  while (sim.time_s() < end_s) {
    if (stop_signal && *stop_signal != 0) {
      interrupted_by = *stop_signal;
      break;
    }
    const double before_s = sim.time_s();
    const Clock::time_point t0 = Clock::now();
    const physics::StepResult r = sim.step();
    const Clock::time_point t1 = Clock::now();
    step_ms.push_back(1e3 * seconds_between(t0, t1));
    if (!r.ok) {
      error = r.error.empty() ? std::string("step failed without a reason") : r.error;
      break;
    }
    if (!(sim.time_s() > before_s)) {  // dt lost in rounding against a huge time
      error = "simulation time stopped advancing at t = " + std::to_string(before_s) + " s";
      break;
    }
    track_probes();
    track_health();
    if (after_step) after_step(sim, step_ms.back());
    if (every_s > 0.0 && sim.time_s() >= static_cast<double>(next_line) * every_s - slack_s) {
      print_progress(progress, sim, seconds_between(start, Clock::now()));
      next_line = static_cast<long long>(std::floor((sim.time_s() + slack_s) / every_s)) + 1;
    }
  }
  const double wall_s = seconds_between(start, Clock::now());

  const Tally final_tally = tally(sim);
  const physics::SimCounters& c = sim.counters();
  nlohmann::json probes = nlohmann::json::object();
  for (std::size_t i = 0; i < sim.probe_count(); ++i) {
    const physics::Vec3 d = sim.probe_displacement_m(i);
    probes[sim.probe_name(i)] = {{"final_displacement_m", {d.x(), d.y(), d.z()}}, {"peak_magnitude_m", peak_m[i]}};
  }

  nlohmann::json report;
  report["scene"] = {{"source", scene.source},
                     {"name", scene.name},
                     {"integrator", sim.integrator().name()},
                     {"dt_s", dt},
                     {"adaptivity", scene.adaptivity.enabled},
                     {"overrides", scene.overrides}};
  const auto time_or_null = [](double t_s) { return std::isnan(t_s) ? nlohmann::json(nullptr) : nlohmann::json(t_s); };
  report["result"] = {
      {"sim_time_s", sim.time_s()},
      {"steps", c.steps},
      {"nodes", {{"final", final_tally.nodes}, {"peak", std::max(c.peak_nodes, final_tally.nodes)}}},
      {"tets", {{"final", final_tally.tets}, {"peak", std::max(c.peak_tets, final_tally.tets)}}},
      {"springs", {{"final", final_tally.springs}, {"peak", std::max(c.peak_springs, final_tally.springs)}}},
      {"refines", c.splits},
      {"merges", c.merges},
      {"refine_ceiling_passes", c.refine_ceiling_passes},
      {"energy_J", {{"kinetic", sim.kinetic_energy_J()}, {"elastic", sim.elastic_energy_J()}}},
      {"external_work_J", c.external_work_J},
      {"prescribed_work_J", c.prescribed_work_J},
      {"adaptation_energy_J", {{"net", c.adaptation_energy_J}, {"added", c.adaptation_energy_added_J}}},
      {"energy_audit", {{"worst_excess", worst_excess}, {"at_t_s", time_or_null(worst_excess_at_s)}}},
      {"inverted_tets",
       {{"final", physics::inverted_tet_count(sim.body())},
        {"peak", inverted_peak},
        {"peak_at_t_s", time_or_null(inverted_peak_at_s)}}},
      {"nonfinite_events", says_nonfinite(error) ? 1 : 0},
      {"rejected_steps", c.rejected_steps},
      {"solver", solver_json(c)},
      {"error", error.empty() ? nlohmann::json(nullptr) : nlohmann::json(error)},
      {"interrupted_by",
       interrupted_by == 0 ? nlohmann::json(nullptr) : nlohmann::json(util::signal_name(interrupted_by))},
      {"probes", std::move(probes)},
  };
  if (options.timing) {
    nlohmann::json step = {{"p50", nullptr}, {"p99", nullptr}, {"max", nullptr}};
    if (!step_ms.empty()) {
      std::sort(step_ms.begin(), step_ms.end());
      step = {{"p50", percentile(step_ms, 0.50)}, {"p99", percentile(step_ms, 0.99)}, {"max", step_ms.back()}};
    }
    report["timing"] = {{"wall_s", wall_s},
                        {"step_ms", std::move(step)},
                        {"real_time_factor", wall_s > 0.0 ? nlohmann::json(sim.time_s() / wall_s) : nullptr}};
  }
  return report;
}

nlohmann::json run_batch(const scene::Scene& scene, const BatchOptions& options, std::FILE* progress) {
  physics::Simulation sim(scene);
  return run_batch(sim, options, progress);
}

// Strings in the report are checked where they come in (a scene's name must
// be UTF-8), but the report must come out whatever: a byte that is not UTF-8
// is written as U+FFFD rather than throwing after the run, with the session
// still to be finished.
std::string report_text(const nlohmann::json& report) {
  return report.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) + "\n";
}

// What the report's health figures say, said once more where a user looks
// (stderr, after the run): a run that passes the stability bar
// prints none of it.
void warn_of_health(const scene::Scene& scene, const physics::SimCounters& c, const nlohmann::json& result,
                    std::FILE* err) {
  if (c.unconverged_steps > 0) {
    // The run succeeded, but part of it is less accurate than the scene asked.
    std::fflush(stdout);
    // The two-level hint only for the implicit rung (the preconditioner is
    // its CG's; projective has none) and where it is not what ran already.
    const bool hint_two_level = scene.integrator.kind == scene::IntegratorKind::kImplicit &&
                                scene.integrator.cg_preconditioner != scene::CgPreconditioner::kTwoLevel;
    std::fprintf(err,
                 "tissued: warning: %lld of %lld steps stopped at integrator.cg_max_iterations = %d short of "
                 "integrator.cg_tolerance = %g; raise cg_max_iterations%s lower dt_s%s\n",
                 static_cast<long long>(c.unconverged_steps), static_cast<long long>(c.steps),
                 scene.integrator.cg_max_iterations, scene.integrator.cg_tolerance, hint_two_level ? "," : " or",
                 hint_two_level ? ", or (slender or heavily damped objects) try cg_preconditioner: two_level" : "");
  }
  if (c.energy_limited_steps > 0) {
    std::fflush(stdout);
    std::fprintf(err,
                 "tissued: warning: %lld of %lld implicit steps ended with more energy than the body was given and "
                 "were slowed (%.3g J taken out): the springs turned far within a step; lower dt_s for a faithful "
                 "trajectory\n",
                 static_cast<long long>(c.energy_limited_steps), static_cast<long long>(c.steps), c.energy_limited_J);
  }
  // An energy or budget that is not a finite number is an infinite excess
  // (EnergyBudget::excess; null in the written report): said as what it is,
  // not as "held inf % more energy".
  if (const auto& audit = result["energy_audit"];
      audit["worst_excess"].is_null() || !std::isfinite(audit["worst_excess"].get<double>())) {
    std::fflush(stdout);
    std::fprintf(err,
                 "tissued: warning: the body's energy or its budget (the energy it started with plus the work done "
                 "on it) was not a finite number at t = %.6g s: the energy audit could not judge the run "
                 "(energy_audit.worst_excess is null in the report)\n",
                 audit["at_t_s"].is_null() ? NAN : audit["at_t_s"].get<double>());
  } else if (audit["worst_excess"].get<double>() > kReportedEnergyExcess) {
    std::fflush(stdout);
    std::fprintf(err,
                 "tissued: warning: the body held %.3g %% more energy than it started with plus the work done on it "
                 "(at t = %.6g s)%s\n",
                 100.0 * audit["worst_excess"].get<double>(), audit["at_t_s"].get<double>(),
                 scene.integrator.kind == scene::IntegratorKind::kExplicit
                     ? "; explicit steps swing in energy by O(h omega): lower integrator.substep_safety or add "
                       "damping"
                     : "");
  }
  if (c.refine_ceiling_passes > 0) {
    std::fflush(stdout);
    std::fprintf(err,
                 "tissued: warning: %lld adaptation passes stopped refining at adaptivity.max_tets = %d; raise it "
                 "or the threshold (adaptivity.refine_threshold_Pa)\n",
                 static_cast<long long>(c.refine_ceiling_passes), scene.adaptivity.max_tets);
  }
  if (const auto& inverted = result["inverted_tets"]; inverted["peak"].get<std::size_t>() > 0) {
    std::fflush(stdout);
    std::fprintf(err,
                 "tissued: warning: %zu tets were inside out at the worst (t = %.6g s), %zu at the end: springs do "
                 "not resist inversion (NUMERICS.md section 3)\n",
                 inverted["peak"].get<std::size_t>(),
                 inverted["peak_at_t_s"].is_null() ? 0.0 : inverted["peak_at_t_s"].get<double>(),
                 inverted["final"].get<std::size_t>());
  }
}

int batch_command(const BatchOptions& options) {
  // stdout carries the live figures; flush it before each stderr line so the
  // two read in order on a terminal.
  auto fail = [](int code, const std::string& message) {
    std::fflush(stdout);
    std::fprintf(stderr, "tissued: %s\n", message.c_str());
    return code;
  };
  try {
    scene::Scene scene;
    try {
      scene = scene::load_scene_file_with_overrides(options.scene_path, options.overrides);
    } catch (const scene::SceneError& e) {
      return fail(kExitUsage, e.what());
    }
    if (!(options.duration_s >= 0.0) || !std::isfinite(options.duration_s))
      return fail(kExitUsage, "--duration must be a finite number of seconds >= 0");
    // A run keeps every step's time for its percentiles: 1e9 s at 1e-7 s
    // per step was accepted and grew by 11 MB/s for centuries.
    if (const double steps = std::ceil(options.duration_s / scene.integrator.dt_s); steps > kMaxBatchSteps) {
      char why[256];
      std::snprintf(why, sizeof why,
                    "--duration %g s at integrator.dt_s %g s is %.3g steps, more than a batch run takes (%.0e): "
                    "shorten --duration or raise integrator.dt_s",
                    options.duration_s, scene.integrator.dt_s, steps, kMaxBatchSteps);
      return fail(kExitUsage, why);
    }

    std::unique_ptr<physics::Simulation> sim;
    try {
      sim = std::make_unique<physics::Simulation>(scene);
    } catch (const scene::SceneModelError& e) {
      return fail(kExitUsage, scene::model_error(scene, e).what());  // file: key: reason (set by the override ...)
    } catch (const std::invalid_argument& e) {
      return fail(kExitUsage, scene.source + ": " + e.what());
    }

    // The report replaces its path when the run ends: it must be neither the
    // scene it ran nor the session it recorded (written beside it, then
    // renamed over it: the session was gone and the run said "done").
    if (!options.report_path.empty()) {
      const auto same_path = [](const std::string& a, const std::string& b) {
        std::error_code ec_a, ec_b;
        const std::filesystem::path pa = std::filesystem::weakly_canonical(a, ec_a);
        const std::filesystem::path pb = std::filesystem::weakly_canonical(b, ec_b);
        return util::same_file(a, b) || (!ec_a && !ec_b && pa == pb) || a == b;
      };
      if (same_path(options.report_path, options.scene_path))
        return fail(kExitUsage,
                    "--report " + options.report_path + " is the scene file (--scene): the report would replace it");
      if (!options.record_path.empty() && same_path(options.report_path, options.record_path))
        return fail(kExitUsage,
                    "--report " + options.report_path + " is the session file (--record): the report would replace it");
    }

    OutputFile file;
    if (!options.report_path.empty()) {
      const std::string why = file.open(options.report_path, "report");
      if (!why.empty()) return fail(kExitReport, why);
    }

    // The session file, like the report, is created before the run: a path
    // that cannot be written fails now, not after minutes of simulation.
    std::unique_ptr<BatchRecorder> recorder;
    if (!options.record_path.empty()) {
      try {
        recorder = std::make_unique<BatchRecorder>(options.record_path, *sim, scene.source_text, command_text(options),
                                                   options.record_frame_interval_s);
      } catch (const record::RecordError& e) {
        return fail(kExitRecord, e.what());
      }
    }

    const bool talk = options.progress_every_s > 0.0;
    // `--report /dev/stdout` prints the report alone: the live lines and the
    // closing line go to stderr then.
    std::FILE* const talk_to = util::is_standard_output(options.report_path) ? stderr : stdout;
    // A recording that stops mid-run (disk full, a file-size limit) is said
    // at once: the run goes on, and a long run should not hide it to the end.
    bool told = false;
    const auto record_step = [&](const physics::Simulation& s, double step_ms) {
      recorder->after_step(s, step_ms);
      if (told || recorder->error().empty()) return;
      told = true;
      std::fflush(stdout);
      std::fprintf(stderr, "tissued: %s (the run goes on)\n", recorder->error().c_str());
    };
    // Until the report and the session are written: a signal during the
    // run ends it there; one after it (while writing) changes nothing.
    const util::StopOnSignals stop;
    const nlohmann::json report =
        run_batch(*sim, options, talk ? talk_to : nullptr,
                  recorder ? record_step : std::function<void(const physics::Simulation&, double)>(), &stop.signal());
    const nlohmann::json& result = report["result"];
    const std::string interrupted_by =
        result["interrupted_by"].is_null() ? std::string() : result["interrupted_by"].get<std::string>();

    std::string write_error;
    if (!options.report_path.empty()) write_error = file.write(report_text(report));
    std::string record_error =
        recorder
            ? recorder->finish(*sim, result["error"].is_null() ? std::string() : result["error"].get<std::string>(),
                               interrupted_by)
            : std::string();
    if (told) record_error = "session " + options.record_path + " is incomplete: its recording stopped (above)";

    if (!interrupted_by.empty()) {
      // Not a failure of the run: what it reached is written, and the exit
      // code says which signal stopped it.
      char where[160];
      std::snprintf(where, sizeof where, "interrupted by %s at t = %.6g s after %lld steps", interrupted_by.c_str(),
                    sim->time_s(), static_cast<long long>(sim->counters().steps));
      std::string message = where;
      if (!options.report_path.empty() && write_error.empty()) message += "; report " + options.report_path;
      if (recorder && record_error.empty()) message += "; session " + options.record_path;
      if (!options.report_path.empty() || recorder) message += " (the run so far)";
      // The flag keeps the first signal, the one that ended the run.
      const int code = fail(util::exit_code_for_signal(stop.signal()), message);
      if (!write_error.empty()) fail(kExitReport, write_error);
      if (!record_error.empty()) fail(kExitRecord, record_error);
      return code;
    }

    if (!result["error"].is_null()) {
      char where[96];
      std::snprintf(where, sizeof where, "simulation failed at t = %.6g s after %lld steps: ", sim->time_s(),
                    static_cast<long long>(sim->counters().steps));
      const int code = fail(kExitSimFailed, where + result["error"].get<std::string>());
      if (!write_error.empty()) fail(kExitReport, write_error);
      if (!record_error.empty()) fail(kExitRecord, record_error);
      return code;
    }
    if (!write_error.empty()) {
      if (!record_error.empty()) fail(kExitRecord, record_error);
      return fail(kExitReport, write_error);
    }
    if (!record_error.empty()) return fail(kExitRecord, record_error);
    warn_of_health(scene, sim->counters(), result, stderr);
    if (talk) {
      std::fprintf(talk_to, "done: %.6g s simulated in %lld steps", sim->time_s(),
                   static_cast<long long>(sim->counters().steps));
      if (report.contains("timing")) {
        const auto& timing = report["timing"];
        std::fprintf(talk_to, ", %.3f s wall", timing["wall_s"].get<double>());
        if (!timing["real_time_factor"].is_null())
          std::fprintf(talk_to, " (%.2fx real time)", timing["real_time_factor"].get<double>());
      }
      if (!options.report_path.empty()) std::fprintf(talk_to, "; report %s", options.report_path.c_str());
      if (recorder)
        std::fprintf(talk_to, "; session %s (%llu mesh frames)", recorder->path().c_str(),
                     static_cast<unsigned long long>(recorder->mesh_frames()));
      std::fprintf(talk_to, "\n");
      std::fflush(talk_to);
    }
    return kExitOk;
  } catch (const std::exception& e) {
    return fail(kExitInternal, std::string("internal error: ") + e.what());
  } catch (...) {
    return fail(kExitInternal, "internal error: unknown exception");
  }
}

}  // namespace tissue::app
