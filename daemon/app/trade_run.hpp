// One timed run of the trade study (NUMERICS.md §4): a simulation stepped
// with only Simulation::step() on the clock, and what the run measured.
// Table 1, the beam-theory statics and every point of the sweep run this way.
#pragma once

#include <atomic>
#include <chrono>
#include <cmath>
#include <functional>
#include <string>

#include "physics/simulation.hpp"

namespace tissue::app {

double seconds_between(std::chrono::steady_clock::time_point a, std::chrono::steady_clock::time_point b);

// CPU time of this thread [s]: the work a step did, whatever else the shared
// machine runs (wall time is what the brief asks for; both are reported).
double thread_cpu_s();

// What one run measured. cost = wall seconds spent inside step()
// (integration, adaptation, refactorisation) per simulated second; building
// the scene and measuring errors are not timed. Thread CPU seconds are
// recorded beside it; --clock cpu makes verdicts, the plot and the per-run
// cap use them (the machine is shared: wall time there measures the
// neighbours too). A refused or failed step ends a run; the refusal is
// recorded here, not hidden.
struct RunStats {
  bool ok = true;
  bool capped = false;     // stopped by the wall-time cap (cost still valid)
  int interrupted_by = 0;  // stopped by this signal (SIGINT, SIGTERM): failed, the error says so
  std::string error;
  double error_time_s = 0.0;
  long steps = 0;
  double wall_s = 0.0, cpu_s = 0.0, sim_s = 0.0;
  long solver_iterations = 0;
  int max_substeps = 0;
  long unconverged_steps = 0;  // solver stopped at cg_max_iterations short of cg_tolerance
  double wall_cost() const { return sim_s > 0.0 ? wall_s / sim_s : NAN; }
  double cpu_cost() const { return sim_s > 0.0 ? cpu_s / sim_s : NAN; }
  // What cost() and the run cap measure: wall time, or thread CPU time with
  // --clock cpu (set where the run is set up, from the options).
  bool cost_uses_cpu = false;
  double cost() const { return cost_uses_cpu ? cpu_cost() : wall_cost(); }
  double mean_iterations() const { return steps > 0 ? static_cast<double>(solver_iterations) / steps : 0.0; }
  double last_adapt_s = NAN;  // time of the last step whose adaptation split or merged
};

// Steps `n` times (timing only step()); `after` runs untimed after each
// successful step. Returns false when a step fails, the cap (on the cost
// clock: wall, or CPU with --clock cpu) is hit or `stop` holds a signal.
bool advance(physics::Simulation& sim, long n, RunStats& st, double cap_s = 0.0,
             const std::function<void(const physics::Simulation&)>& after = {}, const std::atomic<int>* stop = nullptr);

}  // namespace tissue::app
