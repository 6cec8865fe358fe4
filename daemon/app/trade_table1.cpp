#include "app/trade_table1.hpp"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "app/trade_format.hpp"
#include "app/trade_run.hpp"
#include "app/trade_scenes.hpp"
#include "physics/field_error.hpp"
#include "physics/simulation.hpp"

namespace tissue::app {
namespace {

namespace sc = tissue::scene;
namespace ph = tissue::physics;
using ph::Vec3;
using Clock = std::chrono::steady_clock;

// The coarse mesh's tet count (4^3 cubes x 6 tets): an adaptive run back
// there has merged everything it refined.
constexpr std::size_t kCoarseTets = 384;

// When the table samples: the load is on until t2, released there, and the
// run goes on to t_end.
struct Table1Times {
  double dt_s = 1e-3;
  double t2_s = 0.0;     // release
  double t_end_s = 0.0;  // "after release"
  long steps_t2 = 0;     // last step with the load on
  long steps_end = 0;
};

Table1Times table1_times(bool quick) {
  Table1Times t;
  t.t2_s = quick ? 0.25 : 1.0;
  t.t_end_s = quick ? 0.5 : 2.0;
  t.steps_t2 = std::lround(t.t2_s / t.dt_s) - 1;
  t.steps_end = std::lround(t.t_end_s / t.dt_s);
  return t;
}

struct Row {
  std::string name;
  MeshChoice mesh;
  RunStats st;
  std::size_t nodes_t2 = 0, tets_t2 = 0, springs_t2 = 0, nodes_end = 0, tets_end = 0;
  std::size_t peak_nodes = 0, peak_tets = 0;
  Vec3 tip_bottom = Vec3::Zero(), tip_centre = Vec3::Zero();
  ph::DisplacementField field;
  double energy_t2_J = 0.0, work_t2_J = 0.0, energy_end_J = 0.0, max_rise_J = 0.0, max_rise_t = 0.0;
  long splits = 0, merges = 0, merges_after = 0;
  double wall_cost_total = NAN, cpu_cost_total = NAN;
  double rise_before_J = 0.0;    // E_kin + E_el just before the largest rise
  double last_adapt_t2_s = NAN;  // last mesh change before t2
  double coarse_again_s = NAN;   // from when on the mesh stayed at the 384 coarse tets
};

std::vector<Row> table1_rows() {
  std::vector<Row> rows(3);
  rows[0].name = "low (uniform depth 0)";
  rows[0].mesh = {false, 0, 0.0, 0};
  rows[1].name = "high (uniform depth 3)";
  rows[1].mesh = {false, 3, 0.0, 3};
  rows[2].name = "adaptive (Th 20 Pa, max depth 3)";
  rows[2].mesh = {true, 0, 20.0, 3};
  return rows;
}

// The state at t2, the last step with the load on.
void record_at_t2(ph::Simulation& sim, Row& row) {
  row.nodes_t2 = sim.body().mesh().node_count();
  row.tets_t2 = sim.body().mesh().tet_count();
  row.springs_t2 = sim.body().mesh().edge_count();
  row.tip_bottom = sim.probe_displacement_m(0);
  row.tip_centre = sim.probe_displacement_m(1);
  row.field = ph::capture_displacement_field(sim.body());
  row.last_adapt_t2_s = row.st.last_adapt_s;
  row.energy_t2_J = sim.kinetic_energy_J() + sim.elastic_energy_J();
  row.work_t2_J = sim.counters().external_work_J;
}

// After release no load acts: kinetic + elastic energy must not grow. Runs
// from t2 to the end watching that energy's largest per-step rise and when
// the mesh went back to the coarse tets for good.
RunStats run_after_release(ph::Simulation& sim, const Table1Times& t, Row& row) {
  double previous = row.energy_t2_J;
  RunStats after = row.st;
  if (row.st.ok)
    advance(sim, t.steps_end - t.steps_t2, after, 0.0, [&](const ph::Simulation& s) {
      const double e = s.kinetic_energy_J() + s.elastic_energy_J();
      if (e - previous > row.max_rise_J) {
        row.max_rise_J = e - previous;
        row.max_rise_t = s.time_s();
        row.rise_before_J = previous;
      }
      previous = e;
      if (s.body().mesh().tet_count() == kCoarseTets && !std::isfinite(row.coarse_again_s))
        row.coarse_again_s = s.time_s();
      if (s.body().mesh().tet_count() != kCoarseTets) row.coarse_again_s = NAN;
    });
  return after;
}

// The state and counters at the end; `merges_t2` the merges up to t2.
void record_at_end(const ph::Simulation& sim, long merges_t2, Row& row) {
  row.nodes_end = sim.body().mesh().node_count();
  row.tets_end = sim.body().mesh().tet_count();
  row.energy_end_J = sim.kinetic_energy_J() + sim.elastic_energy_J();
  row.peak_nodes = sim.counters().peak_nodes;
  row.peak_tets = sim.counters().peak_tets;
  row.splits = sim.counters().splits;
  row.merges = sim.counters().merges;
  row.merges_after = sim.counters().merges - merges_t2;
}

void measure_row(const Table1Times& t, Row& row) {
  const auto wall0 = Clock::now();
  ph::Simulation sim(paper_cantilever(row.mesh, sc::IntegratorKind::kImplicit, t.dt_s, t.t2_s));
  advance(sim, t.steps_t2, row.st);
  record_at_t2(sim, row);
  const long merges_t2 = sim.counters().merges;
  const RunStats after = run_after_release(sim, t, row);
  if (!after.ok) row.st = after;
  row.wall_cost_total = after.wall_cost();
  row.cpu_cost_total = after.cpu_cost();
  record_at_end(sim, merges_t2, row);
  std::fprintf(stderr, "  table1: %s done in %.1f s wall\n", row.name.c_str(), seconds_between(wall0, Clock::now()));
}

// Counts, tips, errors against `high` (rows[1]) and cost, one row per mesh,
// and the paper's own figures for comparison.
void print_counts_and_errors(const std::vector<Row>& rows, const Table1Times& t) {
  const Row& high = rows[1];
  const double t2_sample = t.steps_t2 * t.dt_s;
  const double t_end = t.t_end_s;
  std::printf("Counts at t = %.3f s (last step before release) and peak over [0, %.1f s]; tip probes at t = %.3f s.\n",
              t2_sample, t_end, t2_sample);
  std::printf(
      "Errors are against `high` (uniform depth 3, the reference at the same max depth), NUMERICS §4. "
      "Cost = wall s per simulated s inside step() (thread CPU s in brackets).\n\n");
  std::printf(
      "| mesh | nodes t2 | tets t2 | springs t2 | peak nodes | peak tets | tip bottom u_z (mm) | err vs high "
      "| tip centre u_z (mm) | err vs high | node RMS err | node max err | cost [0,t2] | cost [0,%.1f] | "
      "nodes / tets at t=%.1f s |\n",
      t_end, t_end);
  std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  for (const auto& row : rows) {
    const bool is_high = &row == &high;
    const double e_bottom = (row.tip_bottom - high.tip_bottom).norm() / high.tip_bottom.norm();
    const double e_centre = (row.tip_centre - high.tip_centre).norm() / high.tip_centre.norm();
    const ph::FieldError fe = is_high ? ph::FieldError{} : ph::compare_displacement_fields(high.field, row.field);
    std::printf(
        "| %s | %zu | %zu | %zu | %zu | %zu | %.3f | %s | %.3f | %s | %s | %s | %.3f (%.3f) | %.3f (%.3f) | %zu / "
        "%zu |\n",
        row.name.c_str(), row.nodes_t2, row.tets_t2, row.springs_t2, row.peak_nodes, row.peak_tets,
        1e3 * row.tip_bottom[2], is_high ? "—" : percent_text(e_bottom).c_str(), 1e3 * row.tip_centre[2],
        is_high ? "—" : percent_text(e_centre).c_str(), is_high ? "—" : percent_text(fe.rms_rel).c_str(),
        is_high ? "—" : percent_text(fe.max_rel).c_str(), row.st.wall_cost(), row.st.cpu_cost(), row.wall_cost_total,
        row.cpu_cost_total, row.nodes_end, row.tets_end);
    if (!is_high && fe.unlocated > 0)
      std::printf("|  ↳ %zu reference nodes not located in this mesh |\n", fe.unlocated);
  }
  std::printf("| *paper (their 9^3-cell high)* | 125 / 1000 / 299 | 384 / 4374 / 1048 | | | | | | | | | | | | |\n\n");
}

// Adaptation counts, energy balance and solver effort per mesh.
void print_diagnostics(const std::vector<Row>& rows, double t_end) {
  std::printf(
      "Diagnostics:\n\n| mesh | splits | merges (after release) | E_kin+E_el at t2 (mJ) | W_ext to t2 (mJ) | "
      "E at t=%.1f (mJ) | largest per-step rise of E_kin+E_el after release (µJ; at t; E before it) | "
      "last mesh change before t2 (s) | back to the 384 coarse tets from t (s) | mean CG iters | failed |\n",
      t_end);
  std::printf("|---|---|---|---|---|---|---|---|---|---|---|\n");
  for (const auto& row : rows)
    std::printf("| %s | %ld | %ld (%ld) | %.4f | %.4f | %.3g | %.3g; t = %.3f s; %.3g µJ | %s | %s | %.1f | %s |\n",
                row.name.c_str(), row.splits, row.merges, row.merges_after, 1e3 * row.energy_t2_J, 1e3 * row.work_t2_J,
                1e3 * row.energy_end_J, 1e6 * row.max_rise_J, row.max_rise_t, 1e6 * row.rise_before_J,
                row.mesh.adaptive ? format_number("%.3f", row.last_adapt_t2_s).c_str() : "—",
                row.mesh.adaptive
                    ? (std::isfinite(row.coarse_again_s) ? format_number("%.3f", row.coarse_again_s) : "never").c_str()
                    : "—",
                row.st.mean_iterations(), row.st.ok ? "no" : shorten(row.st.error).c_str());
}

}  // namespace

void run_table1(const TradeOptions& o) {
  const Table1Times t = table1_times(o.quick);
  std::printf("\n## Table 1: paper cantilever (seed §4.1), implicit dt = 1 ms, release at t2 = %.2f s%s\n\n", t.t2_s,
              o.quick ? " (--quick: shortened)" : "");
  std::vector<Row> rows = table1_rows();
  for (auto& row : rows) measure_row(t, row);
  print_counts_and_errors(rows, t);
  print_diagnostics(rows, t.t_end_s);
}

}  // namespace tissue::app
