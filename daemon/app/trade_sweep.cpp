#include "app/trade_sweep.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <string>
#include <vector>

#include "app/trade_plot_svg.hpp"
#include "app/trade_run.hpp"
#include "app/trade_scenes.hpp"
#include "app/trade_sweep_csv.hpp"
#include "app/trade_sweep_point.hpp"
#include "app/trade_sweep_report.hpp"
#include "app/trade_sweep_setup.hpp"
#include "physics/simulation.hpp"
#include "util/stop_signals.hpp"

namespace tissue::app {
namespace {

namespace sc = tissue::scene;
namespace ph = tissue::physics;
using ph::Vec3;
using Clock = std::chrono::steady_clock;

// The mesh and adaptation counters at the end of a run.
void record_mesh(const ph::Simulation& sim, SweepPoint& p) {
  p.nodes = sim.body().mesh().node_count();
  p.tets = sim.body().mesh().tet_count();
  p.springs = sim.body().mesh().edge_count();
  p.peak_nodes = sim.counters().peak_nodes;
  p.peak_tets = sim.counters().peak_tets;
  p.splits = sim.counters().splits;
  p.merges = sim.counters().merges;
  sim.body().mesh().for_each_tet([&](ph::TetId, const tissue::mesh::Tet& t) {
    if (t.depth > p.deepest) p.deepest = t.depth, p.tets_at_deepest = 0;
    if (t.depth == p.deepest) ++p.tets_at_deepest;
  });
}

// One run of the sweep: mesh `m`, integrator `kind`, step dt for the
// setup's duration, recording the tip's path (a bounded sample of the steps:
// is_path_sample) and, if the run finished, its end state for the errors.
SweepPoint run_point(const SweepSetup& s, const MeshChoice& m, sc::IntegratorKind kind, double dt) {
  SweepPoint p;
  p.st.cost_uses_cpu = s.cost_uses_cpu;
  p.integrator = integrator_name(kind);
  p.dt_s = dt;
  p.adaptive = m.adaptive;
  p.level = m.depth;
  p.max_depth = m.max_depth;
  p.th_Pa = m.adaptive ? m.th_Pa : NAN;
  ph::Simulation sim(sweep_scene(s, m, kind, dt));
  const long steps = std::lround(s.duration_s / dt);
  const bool has_tip = sim.probe_count() > 0;
  long steps_done = 0;
  advance(
      sim, steps, p.st, s.run_cap_s,
      [&](const ph::Simulation&) {
        if (!has_tip || !is_path_sample(++steps_done, steps)) return;
        p.tip_t_s.push_back(sim.time_s());
        p.tip_path_m.push_back(sim.probe_displacement_m(0));
      },
      s.stop);
  if (!p.st.ok || p.st.capped) {  // no path error for these (set_path_errors): free the path now
    std::vector<double>().swap(p.tip_t_s);
    std::vector<Vec3>().swap(p.tip_path_m);
  }
  record_mesh(sim, p);
  if (p.st.ok && !p.st.capped) {
    // The first probe is the tip (a scene file without probes has no tip error).
    p.tip = sim.probe_count() > 0 ? sim.probe_displacement_m(0) : Vec3::Constant(NAN);
    p.field = ph::capture_displacement_field(sim.body());
    p.captured = true;
  }
  return p;
}

// Uniform levels base..deepest for one (integrator, dt), run once and
// compared later against each max depth's reference. Once a level failed or
// hit the cap, the finer ones would too: they are not run.
std::vector<SweepPoint> run_uniform_levels(const SweepSetup& s, sc::IntegratorKind kind, double dt, int deepest) {
  std::vector<SweepPoint> uniform;
  std::string stop_reason;  // set once a level failed or hit the cap: finer ones would too
  for (int level = s.base_depth; level <= deepest; ++level) {
    if (s.stopped()) stop_reason = "not run: interrupted by " + util::signal_name(*s.stop);
    if (!stop_reason.empty()) {
      SweepPoint p = not_run_point(kind, dt, stop_reason);
      p.level = level;
      uniform.push_back(p);
      continue;
    }
    const auto t0 = Clock::now();
    uniform.push_back(run_point(s, {false, level, 0.0, level}, kind, dt));
    const SweepPoint& p = uniform.back();
    if (!p.st.ok) stop_reason = "not run: uniform L" + std::to_string(level) + " failed or refused";
    if (p.st.interrupted_by != 0) stop_reason = "not run: interrupted by " + util::signal_name(p.st.interrupted_by);
    if (p.st.capped) stop_reason = "not run: uniform L" + std::to_string(level) + " already hit the wall cap";
    std::fprintf(stderr, "  sweep: %s dt %g uniform L%d: %s, %.1f s wall\n", integrator_name(kind), dt, level,
                 p.status().c_str(), seconds_between(t0, Clock::now()));
  }
  return uniform;
}

// The points of max depth `md`: the uniform levels up to it with their
// errors against its reference, then one adaptive run per Th (not run
// without a reference: the point would only cost time).
void add_max_depth_points(const SweepSetup& s, sc::IntegratorKind kind, double dt, int md,
                          const std::vector<SweepPoint>& uniform, std::vector<SweepPoint>& points) {
  // Uniform level L is uniform[L - base_depth].
  const auto uniform_at = [&](int level) -> const SweepPoint& {
    return uniform[static_cast<std::size_t>(level - s.base_depth)];
  };
  const SweepPoint& ref = uniform_at(md);
  for (int level = s.base_depth; level <= md; ++level) {
    SweepPoint p = uniform_at(level);
    p.max_depth = md;
    fill_errors(p, ref);
    points.push_back(std::move(p));
  }
  for (double th : s.th_Pa) {
    if (!ref.captured || s.stopped()) {  // no reference, no error: the point would only cost time
      SweepPoint p = not_run_point(
          kind, dt,
          s.stopped() ? "not run: interrupted by " + util::signal_name(*s.stop)
                      : "not run: no reference (uniform L" + std::to_string(md) + " " + ref.status() + ")");
      p.adaptive = true;
      p.max_depth = md;
      p.th_Pa = th;
      points.push_back(std::move(p));
      continue;
    }
    const auto t0 = Clock::now();
    SweepPoint p = run_point(s, {true, 0, th, md}, kind, dt);
    fill_errors(p, ref);
    std::fprintf(stderr, "  sweep: %s dt %g max depth %d Th %g: %s, %zu tets, %.1f s wall\n", integrator_name(kind), dt,
                 md, th, p.status().c_str(), p.tets, seconds_between(t0, Clock::now()));
    points.push_back(std::move(p));
  }
}

// Every point of the grid, integrator by integrator and dt by dt.
std::vector<SweepPoint> run_grid(const SweepSetup& s) {
  const int deepest = *std::max_element(s.max_depths.begin(), s.max_depths.end());
  std::vector<SweepPoint> points;
  for (auto kind : s.kinds) {
    for (double dt : s.dts_s) {
      const std::vector<SweepPoint> uniform = run_uniform_levels(s, kind, dt, deepest);
      for (int md : s.max_depths) add_max_depth_points(s, kind, dt, md, uniform, points);
      for (auto& p : points) {  // fields are large; keep only what the table and files need
        if (p.integrator == integrator_name(kind) && p.dt_s == dt) p.field = ph::DisplacementField{};
      }
    }
  }
  return points;
}

void write_files(const TradeOptions& o, const SweepSetup& s, const std::vector<SweepPoint>& points,
                 const std::map<int, std::string>& truth, OutputFile& csv, OutputFile& svg) {
  if (csv.is_open()) {
    if (const std::string why = csv.write(csv_text(s.scene, points, truth)); !why.empty()) throw OutputError(why);
    std::printf("wrote %s\n", o.csv_path.c_str());
  }
  if (svg.is_open()) {
    if (const std::string why = svg.write(svg_text(s, points, o.metric)); !why.empty()) throw OutputError(why);
    std::printf("wrote %s\n", o.svg_path.c_str());
  }
}

}  // namespace

SweepEnd run_sweep(const TradeOptions& o, const SweepSetup& s, OutputFile& csv, OutputFile& svg) {
  print_sweep_header(o, s);
  const auto sweep0 = Clock::now();
  std::vector<SweepPoint> points = run_grid(s);
  const double sweep_wall = seconds_between(sweep0, Clock::now());
  const std::map<int, std::string> truth = set_path_errors(points);
  print_sweep_table(points, truth);
  print_refusals(points);
  print_verdicts(points, o.metric);
  std::printf("\nsweep wall time %.1f s\n", sweep_wall);
  write_files(o, s, points, truth, csv, svg);
  SweepEnd end;
  end.signal = s.stopped() ? s.stop->load() : 0;
  end.any_figures = std::any_of(points.begin(), points.end(), [](const SweepPoint& p) {
    const std::string status = p.status();
    return status == "ok" || status == "capped";
  });
  return end;
}

}  // namespace tissue::app
