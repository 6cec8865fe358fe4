#include "app/trade_run.hpp"

#include <algorithm>
#include <ctime>

#include "util/stop_signals.hpp"

namespace tissue::app {

namespace ph = tissue::physics;
using Clock = std::chrono::steady_clock;

double seconds_between(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double>(b - a).count();
}

double thread_cpu_s() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

bool advance(ph::Simulation& sim, long n, RunStats& st, double cap_s,
             const std::function<void(const ph::Simulation&)>& after, const std::atomic<int>* stop) {
  const double dt = sim.scene().integrator.dt_s;
  for (long i = 0; i < n; ++i) {
    if (stop && *stop != 0) {
      st.ok = false;
      st.interrupted_by = *stop;
      st.error = "interrupted by " + util::signal_name(st.interrupted_by);
      st.error_time_s = sim.time_s();
      return false;
    }
    const auto t0 = Clock::now();
    const double c0 = thread_cpu_s();
    const ph::StepResult r = sim.step();
    st.cpu_s += thread_cpu_s() - c0;
    st.wall_s += seconds_between(t0, Clock::now());
    if (!r.ok) {
      st.ok = false;
      st.error = r.error;
      st.error_time_s = sim.time_s() + dt;
      return false;
    }
    ++st.steps;
    st.sim_s += dt;
    st.solver_iterations += r.solver_iterations;
    st.max_substeps = std::max(st.max_substeps, r.substeps);
    st.unconverged_steps += r.solver_converged ? 0 : 1;
    if (r.adapted.splits + r.adapted.merges > 0) st.last_adapt_s = sim.time_s();
    if (after) after(sim);
    if (cap_s > 0.0 && (st.cost_uses_cpu ? st.cpu_s : st.wall_s) > cap_s && i + 1 < n) {
      st.capped = true;
      return false;
    }
  }
  return true;
}

}  // namespace tissue::app
