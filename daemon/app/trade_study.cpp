// The trade study: what adaptivity buys, measured honestly (NUMERICS.md §4).
// Run as `tissue trade` (installed) or `bench/trade/trade_bench` (build tree);
// both call run_trade_study with the same arguments.
//
//   --table1       the seed paper's Table 1 for this implementation (cantilever
//                  §4.1): low / high / adaptive node and tet counts at t2 and
//                  at peak, plus what the paper leaves out: tip and node error
//                  of low and adaptive against high, and cost.
//   --sweep        cost vs error: Th x max depth x integrator x dt, against the
//                  uniform reference at the same max depth and integrator
//                  settings; uniform levels 0..max depth are the baseline curve.
//                  --csv FILE, --svg FILE (log-log, one panel per setting).
//                  --scene-file FILE [--set key.path=value ...]: the sweep
//                  on a scene file of your own (its loads, boundary
//                  conditions, material and probes; the sweep sets the mesh,
//                  the integrator and dt of each run, and refines by
//                  strain-energy density whatever criterion the scene names).
//   --beam-theory  model error: static tip of the PERFORMANCE.md beam against
//                  Euler-Bernoulli and Timoshenko, uniform depths, both laws.
//   --quick        shrinks everything (short runs, fewer points).
// With no mode flag all three run.
//
// Conventions (they matter when reading the numbers), each stated in full
// beside the code that implements it:
// - cost = seconds inside Simulation::step() per simulated second, wall time
//   or (--clock cpu) thread CPU time; both are recorded (trade_run.hpp).
// - sweep: the state at --duration, default 0.5 s (quick 0.2 s), where the
//   damped cantilever is static; the beams' ramp, damping and 1 s default
//   (trade_sweep_setup.hpp).
// - a run over the per-run cap (--run-cap; quick 3 s, full 30 s) keeps its
//   cost, not its error (trade_sweep.hpp).
// - errors of a run vs a reference run: tip, node RMS / max
//   (trade_sweep_point.hpp); the tip path against the truth run (set_path_errors).
// - a refused or failed step ends a run; the refusal is recorded, not hidden.
//
// The pipeline, one file per step (daemon/app/):
//   trade_options      the command line: TradeOptions, parse_trade_options, the usage text
//   trade_scenes       the built-in scenes (paper cantilever, PERFORMANCE.md beams), mesh choice
//   trade_run          one timed run: advance() timing only step(), RunStats, the cost clocks
//   trade_table1       --table1
//   trade_beam_theory  --beam-theory
//   trade_sweep_setup  --sweep: what it runs (scene, grid, defaults), each run's scene
//   trade_sweep_point  a point of the sweep, its errors against the reference and the path truth
//   trade_sweep        running the grid (uniform levels, then adaptive runs per max depth)
//   trade_sweep_report the sweep's tables and the adaptive-vs-uniform verdicts
//   trade_sweep_csv    --csv
//   trade_plot_svg     --svg
//   trade_format       number and message formatting shared by the tables
#include "app/trade_study.hpp"

#include <chrono>
#include <cstdio>
#include <exception>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "app/output_file.hpp"
#include "app/trade_beam_theory.hpp"
#include "app/trade_options.hpp"
#include "app/trade_run.hpp"
#include "app/trade_sweep.hpp"
#include "app/trade_sweep_setup.hpp"
#include "app/trade_table1.hpp"
#include "util/stop_signals.hpp"

namespace tissue::app {
namespace {

using Clock = std::chrono::steady_clock;

// The reason on stderr after what stdout holds so far; returns `code`.
int fail(const std::string& program, int code, const std::string& why) {
  std::fflush(stdout);
  std::fprintf(stderr, "%s: %s\n", program.c_str(), why.c_str());
  return code;
}

// The sweep's end as an exit: interrupted (128 + N, naming the files that
// hold the runs done), no figure at all (3), or 0 to go on.
int sweep_exit(const std::string& program, const TradeOptions& o, const SweepEnd& end) {
  if (const int signo = end.signal; signo != 0) {
    std::string files;
    for (const std::string* path : {&o.csv_path, &o.svg_path})
      if (!path->empty()) files += (files.empty() ? "; " : ", ") + *path;
    return fail(program, util::exit_code_for_signal(signo),
                "interrupted by " + util::signal_name(signo) + ": the tables" + (files.empty() ? "" : " and files") +
                    " hold the runs done (the rest say \"not run\")" + files);
  }
  if (!end.any_figures)
    return fail(program, kTradeExitNoRun,
                "every run failed or was refused (the table says why for each); no figure came out of the sweep");
  return kTradeExitOk;
}

// Runs the modes `o` asks for in order (Table 1, beam theory, the sweep
// `sweep` if asked for) into the opened files; returns the exit code.
int run_modes(const std::string& program, const TradeOptions& o, std::optional<SweepSetup> sweep, OutputFile& csv,
              OutputFile& svg) {
  const auto t0 = Clock::now();
  if (o.table1) {
    const auto t = Clock::now();
    run_table1(o);
    std::printf("\n(table1 wall time %.1f s)\n", seconds_between(t, Clock::now()));
  }
  if (o.beam_theory) {
    const auto t = Clock::now();
    run_beam_theory(o);
    std::printf("\n(beam-theory wall time %.1f s)\n", seconds_between(t, Clock::now()));
  }
  if (sweep) {
    // Ctrl-C (or SIGTERM) during the sweep, which can take hours, ends it
    // after the step in progress and keeps what it measured.
    const util::StopOnSignals stop;
    sweep->stop = &stop.signal();
    if (const int code = sweep_exit(program, o, run_sweep(o, *sweep, csv, svg)); code != kTradeExitOk) return code;
  }
  std::printf("\ntotal wall time %.1f s\n", seconds_between(t0, Clock::now()));
  return kTradeExitOk;
}

}  // namespace

int run_trade_study(const std::string& program, const std::vector<std::string>& args) {
  TradeOptions o;
  try {
    o = parse_trade_options(args);
  } catch (const std::exception& e) {
    const int code = fail(program, kTradeExitUsage, e.what());
    print_trade_usage(program, stderr);
    return code;
  }
  if (o.help) {
    print_trade_usage(program, stdout);
    return kTradeExitOk;
  }
  try {
    // The sweep's setup (its scene file, integrators, depths, every run's
    // scene) and files before anything runs: a bad one fails now, not after
    // Table 1 and beam theory (minutes) or an hour of runs.
    std::optional<SweepSetup> sweep;
    if (o.sweep) sweep = make_sweep_setup(o, nullptr);  // the stop flag is set when the sweep starts
    OutputFile csv, svg;
    if (!o.csv_path.empty())
      if (const std::string why = csv.open(o.csv_path, "--csv"); !why.empty())
        return fail(program, kTradeExitOutput, why);
    if (!o.svg_path.empty())
      if (const std::string why = svg.open(o.svg_path, "--svg"); !why.empty())
        return fail(program, kTradeExitOutput, why);
    return run_modes(program, o, std::move(sweep), csv, svg);
  } catch (const OutputError& e) {
    return fail(program, kTradeExitOutput, e.what());
  } catch (const std::exception& e) {
    return fail(program, kTradeExitUsage, e.what());
  }
}

}  // namespace tissue::app
