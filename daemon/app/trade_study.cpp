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
// Conventions (they matter when reading the numbers):
// - cost = wall seconds spent inside Simulation::step() (integration,
//   adaptation, refactorisation) per simulated second. Building the scene and
//   measuring errors are not timed. Thread CPU seconds are recorded beside it;
//   --clock cpu makes verdicts, the plot and the per-run cap use them (the
//   machine is shared: wall time there measures the neighbours too).
// - sweep: the state at --duration (default 0.5 s, quick 0.2 s). The damped
//   cantilever is static from ~0.3 s on (errors at 0.3, 0.5 and 1.0 s agree to
//   5 digits), so this is the paper's "at t2" state at half the cost.
//   --scene beam: load ramped over the first quarter of the run, mass damping
//   alpha = 30/s (first mode about critical), default 1 s (quick 0.5 s).
// - a run that exceeds the per-run cap (--run-cap; quick 3 s, full 30 s) stops:
//   its cost is still valid, its error is not; finer uniform levels are then
//   not run, nor adaptive runs whose reference did not finish.
// - error of a run vs a reference run: tip = |u_tip - u_tip,ref| / |u_tip,ref|;
//   node RMS / max = |u(p_i) - u_ref,i| over the reference's free nodes p_i,
//   u(p_i) interpolated barycentrically inside the run's leaf tet that
//   contains p_i at rest, divided by max_i |u_ref,i|.
// - a refused or failed step ends a run; the refusal is recorded, not hidden.
#include "app/trade_study.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <functional>
#include <limits>
#include <map>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "app/output_file.hpp"
#include "app/stop_signals.hpp"
#include "physics/boundary.hpp"
#include "physics/field_error.hpp"
#include "physics/forces.hpp"
#include "physics/probes.hpp"
#include "physics/simulation.hpp"
#include "scene/scene.hpp"
#include "scene/scene_yaml.hpp"
#include "util/output_file.hpp"
#include "util/text.hpp"
#include "util/xml.hpp"

namespace tissue::app {
namespace {

namespace sc = tissue::scene;
namespace ph = tissue::physics;
using ph::Vec3;
using Clock = std::chrono::steady_clock;

double seconds_between(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double>(b - a).count();
}

// CPU time of this thread [s]: the work a step did, whatever else the shared
// machine runs (wall time is what the brief asks for; both are reported).
double thread_cpu_s() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

// ---------------------------------------------------------------------------
// Options

struct Options {
  bool table1 = false, sweep = false, beam_theory = false, quick = false;
  std::string csv_path, svg_path;
  std::string sweep_scene = "cantilever";    // or "beam", "beam-r"
  std::string scene_file;                    // --scene-file: a user's scene instead
  std::vector<std::string> scene_overrides;  // --set key.path=value, applied to the scene file
  std::string preconditioner;      // implicit CG: jacobi | two_level | auto; empty: jacobi (a scene file: its own)
  std::string explicit_precision;  // explicit rung: double | float; empty: double (a scene file: its own)
  std::string metric = "rms";      // plotted error: rms | max | tip | path
  std::vector<double> th_Pa;       // empty: the scene's default list
  std::vector<int> max_depths;     // empty: {3, 6} (quick: {3})
  std::vector<std::string> integrators;  // empty: all three
  std::vector<double> dts_s;             // empty: {1 ms, 5 ms}
  double sweep_duration_s = 0.0;         // 0: the scene's default
  double run_wall_cap_s = 0.0;           // 0: default (quick 3 s, full 30 s)
  int beam_max_depth = -1;               // -1: 6 (quick: 4)
  bool cpu_clock = false;                // --clock cpu: verdicts and plot use thread CPU time
  bool help = false;                     // -h / --help: print the usage, run nothing
};

std::vector<std::string> split_list(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, ',')) out.push_back(item);
  return out;
}

void usage(const std::string& program, std::FILE* to) {
  std::fprintf(to, "usage: %s", program.c_str());
  std::fputs(
      " [--table1] [--sweep] [--beam-theory] [--quick]\n"
      "  sweep: [--csv FILE] [--svg FILE] [--scene cantilever|beam|beam-r] [--th 2,20,...]\n"
      "         [--scene-file FILE [--set key.path=value ...]]   (a scene of your own; defaults from it:\n"
      "          Th x 1/4, 1, 4, its max depth, its dt; uniform levels from its min depth)\n"
      "         [--depths 3,6] [--integrators implicit,explicit,projective] [--dts 0.001,0.005]\n"
      "         [--duration S] [--metric rms|max|tip|path] [--run-cap S] [--clock wall|cpu]\n"
      "         [--preconditioner jacobi|two_level|auto]   (default jacobi, as the README's tables;\n"
      "          a scene file: its own)\n"
      "         [--explicit-precision double|float]   (the explicit rung's arithmetic, default double;\n"
      "          a scene file: its own)\n"
      "  beam-theory: [--beam-depth D]\n"
      "no mode flag: all three modes (with --scene-file: the sweep)\n"
      "--quick: shorter runs and fewer points everywhere (the defaults in brackets below)\n"
      "--scene: cantilever (the paper's, 5 N tip load), beam (PERFORMANCE.md's 0.4 m beam, 8x2x2 cubes),\n"
      "  beam-r (the same beam as 12x3x3 cubes, whose uniform depths 0, 3, 6, 9 are PERFORMANCE.md's R1..R4)\n"
      "defaults: --duration 0.5 s for the cantilever and a scene file, 1 s for the beams [0.2 / 0.5];\n"
      "  --metric rms; --run-cap 30 s of wall (or CPU) time per run [3]; --depths 3,6 [3];\n"
      "  --dts 0.001,0.005; --integrators all three; --beam-depth 6 [4]\n"
      "--csv / --svg are created before any run. Ctrl-C (or SIGTERM) during the sweep stops it after the\n"
      "step in progress and still prints its tables and writes its files for the runs done; Ctrl-C again kills.\n"
      "exit codes: 0 done, 2 bad option or scene, 3 every run of the sweep failed or was refused, 4 --csv/--svg not\n"
      "writable, 128+N sweep stopped by signal N\n",
      to);
}

namespace {

// The whole of `text` as a finite number > 0 (or an integer in [0, 30] for
// depths); anything else is the option's error, naming the value. std::stod
// alone took "20abc" as 20, "nan" as NaN and said only "stod" for ",".
double positive_number(const std::string& option, const std::string& text) {
  const std::optional<double> read = util::whole_number(text);
  if (!read) throw std::invalid_argument(option + ": '" + text + "' is not a number");
  const double v = *read;
  if (!(std::isfinite(v) && v > 0.0))
    throw std::invalid_argument(option + ": " + text + " must be a finite number > 0");
  return v;
}

int depth(const std::string& option, const std::string& text) {
  std::size_t used = 0;
  long v = -1;
  try {
    v = std::stol(text, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used == 0 || used != text.size()) throw std::invalid_argument(option + ": '" + text + "' is not an integer");
  if (v < 0 || v > 30) throw std::invalid_argument(option + ": " + text + " must be a depth in [0, 30]");
  return static_cast<int>(v);
}

}  // namespace

Options parse(const std::vector<std::string>& args) {
  Options o;
  auto value = [&](std::size_t& i) -> std::string {
    if (i + 1 >= args.size()) throw std::invalid_argument("missing value after " + args[i]);
    return args[++i];
  };
  for (std::size_t i = 0; i < args.size(); ++i) {
    const std::string& a = args[i];
    if (a == "--table1")
      o.table1 = true;
    else if (a == "--sweep")
      o.sweep = true;
    else if (a == "--beam-theory")
      o.beam_theory = true;
    else if (a == "--quick")
      o.quick = true;
    else if (a == "--csv")
      o.csv_path = value(i);
    else if (a == "--svg")
      o.svg_path = value(i);
    else if (a == "--scene")
      o.sweep_scene = value(i);
    else if (a == "--scene-file")
      o.scene_file = value(i);
    else if (a == "--set")
      o.scene_overrides.push_back(value(i));
    else if (a == "--metric")
      o.metric = value(i);
    else if (a == "--th") {
      for (const auto& t : split_list(value(i))) o.th_Pa.push_back(positive_number("--th", t));
    } else if (a == "--depths") {
      for (const auto& t : split_list(value(i))) o.max_depths.push_back(depth("--depths", t));
    } else if (a == "--integrators") {
      o.integrators = split_list(value(i));
    } else if (a == "--dts") {
      for (const auto& t : split_list(value(i))) o.dts_s.push_back(positive_number("--dts", t));
    } else if (a == "--duration") {
      o.sweep_duration_s = positive_number("--duration", value(i));
    } else if (a == "--run-cap") {
      o.run_wall_cap_s = positive_number("--run-cap", value(i));
    } else if (a == "--clock") {
      const std::string c = value(i);
      if (c != "wall" && c != "cpu") throw std::invalid_argument("--clock must be wall or cpu");
      o.cpu_clock = c == "cpu";
    } else if (a == "--preconditioner") {
      o.preconditioner = value(i);
      if (o.preconditioner != "jacobi" && o.preconditioner != "two_level" && o.preconditioner != "auto")
        throw std::invalid_argument("--preconditioner must be jacobi, two_level or auto");
    } else if (a == "--explicit-precision") {
      o.explicit_precision = value(i);
      if (o.explicit_precision != "double" && o.explicit_precision != "float")
        throw std::invalid_argument("--explicit-precision must be double or float");
    } else if (a == "--beam-depth") {
      o.beam_max_depth = depth("--beam-depth", value(i));
    } else if (a == "-h" || a == "--help") {
      o.help = true;
      return o;
    } else {
      throw std::invalid_argument("unknown argument " + a);
    }
  }
  if (!o.table1 && !o.sweep && !o.beam_theory) {
    if (o.scene_file.empty())
      o.table1 = o.sweep = o.beam_theory = true;
    else
      o.sweep = true;  // a scene file is for the sweep
  }
  if (o.sweep_scene != "cantilever" && o.sweep_scene != "beam" && o.sweep_scene != "beam-r")
    throw std::invalid_argument("--scene must be cantilever, beam or beam-r");
  if (!o.scene_overrides.empty() && o.scene_file.empty())
    throw std::invalid_argument("--set applies to --scene-file; the built-in scenes take none");
  if (!o.sweep && (!o.csv_path.empty() || !o.svg_path.empty()))
    throw std::invalid_argument("--csv and --svg are the sweep's files: add --sweep");
  if (!o.csv_path.empty() && !o.svg_path.empty() &&
      (o.csv_path == o.svg_path || util::same_file(o.csv_path, o.svg_path)))
    throw std::invalid_argument("--csv and --svg name the same file '" + o.csv_path +
                                "': the plot would replace the table");
  if (o.metric != "rms" && o.metric != "max" && o.metric != "tip" && o.metric != "path")
    throw std::invalid_argument("--metric must be rms, max, tip or path");
  return o;
}

// ---------------------------------------------------------------------------
// Scenes (built in code, SI units)

sc::Region box(sc::Vec3 lo, sc::Vec3 hi) {
  sc::Region r;
  r.kind = sc::Region::Kind::kBox;
  r.min_m = lo;
  r.max_m = hi;
  return r;
}

// How the mesh is chosen: uniform at `depth`, or adaptive from depth 0 with
// threshold th_Pa up to max_depth.
struct MeshChoice {
  bool adaptive = false;
  int depth = 0;
  double th_Pa = 20.0;
  int max_depth = 3;
};

void apply_mesh(sc::Scene& s, const MeshChoice& m) {
  s.adaptivity.enabled = m.adaptive;
  s.adaptivity.criterion = sc::RefineCriterion::kStrainEnergy;
  s.adaptivity.refine_threshold_Pa = m.th_Pa;
  s.adaptivity.min_depth = m.adaptive ? 0 : m.depth;
  s.adaptivity.max_depth = m.adaptive ? m.max_depth : m.depth;
}

const char* kind_name(sc::IntegratorKind k) {
  switch (k) {
    case sc::IntegratorKind::kExplicit:
      return "explicit";
    case sc::IntegratorKind::kImplicit:
      return "implicit";
    case sc::IntegratorKind::kProjective:
      return "projective";
  }
  return "?";
}

sc::IntegratorKind kind_of(const std::string& s) {
  if (s == "explicit") return sc::IntegratorKind::kExplicit;
  if (s == "implicit") return sc::IntegratorKind::kImplicit;
  if (s == "projective") return sc::IntegratorKind::kProjective;
  throw std::invalid_argument("unknown integrator " + s);
}

// Seed paper §4.1: 4^3 cubes of 2.5 cm, x = 0 fixed, 5 N down on x = 0.1,
// released at release_s. Probe 0 = tip (bottom edge centre), 1 = face centre.
sc::Scene paper_cantilever(const MeshChoice& m, sc::IntegratorKind kind, double dt_s, double release_s) {
  sc::Scene s;
  s.name = "paper cantilever";
  s.object.cubes = {4, 4, 4};
  s.object.cube_size_m = 0.025;
  s.material.youngs_modulus_Pa = 5.0e4;
  s.material.density_kg_per_m3 = 100.0;
  s.material.rayleigh_beta_s = 0.003;
  s.fixed.push_back({box({0.0, 0.0, 0.0}, {0.0, 0.1, 0.1})});
  sc::LoadSpec load;
  load.name = "tip";
  load.region = box({0.1, 0.0, 0.0}, {0.1, 0.1, 0.1});
  load.total_force_N = {0.0, 0.0, -5.0};
  load.profile.release_s = release_s;
  s.loads.push_back(load);
  apply_mesh(s, m);
  s.integrator.kind = kind;
  s.integrator.dt_s = dt_s;
  s.probes = {{"tip_bottom", {0.1, 0.05, 0.0}}, {"tip_centre", {0.1, 0.05, 0.05}}};
  return s;
}

// PERFORMANCE.md beam: 8x2x2 cubes of 5 cm, x = 0 fixed, 0.05 N down on
// x = 0.4, gravity off. Probe 0 = tip (free face centre: the neutral axis).
// r_ladder: 12x3x3 cubes of 1/30 m instead, whose uniform depths 0, 3, 6, 9
// are PERFORMANCE.md's R1..R4 (cube edges 33, 17, 8.3, 4.2 mm).
sc::Scene beam(const MeshChoice& m, sc::IntegratorKind kind, double dt_s, double ramp_s, bool r_ladder = false) {
  sc::Scene s;
  s.name = r_ladder ? "beam-r" : "beam";
  s.object.cubes = r_ladder ? std::array<int, 3>{12, 3, 3} : std::array<int, 3>{8, 2, 2};
  s.object.cube_size_m = r_ladder ? 0.4 / 12 : 0.05;
  s.material.youngs_modulus_Pa = 5.0e4;
  s.material.density_kg_per_m3 = 100.0;
  s.fixed.push_back({box({0.0, 0.0, 0.0}, {0.0, 0.1, 0.1})});
  sc::LoadSpec load;
  load.name = "tip";
  load.region = box({0.4, 0.0, 0.0}, {0.4, 0.1, 0.1});
  load.total_force_N = {0.0, 0.0, -0.05};
  load.profile.ramp_s = ramp_s;
  s.loads.push_back(load);
  apply_mesh(s, m);
  s.integrator.kind = kind;
  s.integrator.dt_s = dt_s;
  s.probes = {{"tip_centre", {0.4, 0.05, 0.05}}, {"tip_bottom", {0.4, 0.05, 0.0}}};
  return s;
}

// ---------------------------------------------------------------------------
// Running

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
bool advance(ph::Simulation& sim, long n, RunStats& st, double cap_s = 0.0,
             const std::function<void(const ph::Simulation&)>& after = {},
             const volatile std::sig_atomic_t* stop = nullptr) {
  const double dt = sim.scene().integrator.dt_s;
  for (long i = 0; i < n; ++i) {
    if (stop && *stop != 0) {
      st.ok = false;
      st.interrupted_by = *stop;
      st.error = "interrupted by " + signal_name(st.interrupted_by);
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

std::string fmt(const char* f, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, f, v);
  return buf;
}

std::string pct(double rel) { return std::isfinite(rel) ? fmt("%.2f %%", 100.0 * rel) : "n/a"; }

// Short one-line form of a library error message.
std::string shorten(const std::string& s, std::size_t n = 110) { return s.size() <= n ? s : s.substr(0, n) + "..."; }

// ---------------------------------------------------------------------------
// --table1

void run_table1(const Options& o) {
  const double dt = 1e-3;
  const double t2 = o.quick ? 0.25 : 1.0;          // release
  const double t_end = o.quick ? 0.5 : 2.0;        // "after release"
  const long steps_t2 = std::lround(t2 / dt) - 1;  // last step with the load on
  const long steps_end = std::lround(t_end / dt);
  std::printf("\n## Table 1: paper cantilever (seed §4.1), implicit dt = 1 ms, release at t2 = %.2f s%s\n\n", t2,
              o.quick ? " (--quick: shortened)" : "");

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
  std::vector<Row> rows(3);
  rows[0].name = "low (uniform depth 0)";
  rows[0].mesh = {false, 0, 0.0, 0};
  rows[1].name = "high (uniform depth 3)";
  rows[1].mesh = {false, 3, 0.0, 3};
  rows[2].name = "adaptive (Th 20 Pa, max depth 3)";
  rows[2].mesh = {true, 0, 20.0, 3};

  for (auto& row : rows) {
    const auto wall0 = Clock::now();
    ph::Simulation sim(paper_cantilever(row.mesh, sc::IntegratorKind::kImplicit, dt, t2));
    advance(sim, steps_t2, row.st);
    row.nodes_t2 = sim.body().mesh().node_count();
    row.tets_t2 = sim.body().mesh().tet_count();
    row.springs_t2 = sim.body().mesh().edge_count();
    row.tip_bottom = sim.probe_displacement_m(0);
    row.tip_centre = sim.probe_displacement_m(1);
    row.field = ph::capture_displacement_field(sim.body());
    row.last_adapt_t2_s = row.st.last_adapt_s;
    row.energy_t2_J = sim.kinetic_energy_J() + sim.elastic_energy_J();
    row.work_t2_J = sim.counters().external_work_J;
    const long merges_t2 = sim.counters().merges;
    // After release no load acts: kinetic + elastic energy must not grow.
    double previous = row.energy_t2_J;
    RunStats after = row.st;
    if (row.st.ok)
      advance(sim, steps_end - steps_t2, after, 0.0, [&](const ph::Simulation& s) {
        const double e = s.kinetic_energy_J() + s.elastic_energy_J();
        if (e - previous > row.max_rise_J) {
          row.max_rise_J = e - previous;
          row.max_rise_t = s.time_s();
          row.rise_before_J = previous;
        }
        previous = e;
        if (s.body().mesh().tet_count() == 384 && !std::isfinite(row.coarse_again_s)) row.coarse_again_s = s.time_s();
        if (s.body().mesh().tet_count() != 384) row.coarse_again_s = NAN;
      });
    if (!after.ok) row.st = after;
    row.wall_cost_total = after.wall_cost();
    row.cpu_cost_total = after.cpu_cost();
    row.nodes_end = sim.body().mesh().node_count();
    row.tets_end = sim.body().mesh().tet_count();
    row.energy_end_J = sim.kinetic_energy_J() + sim.elastic_energy_J();
    row.peak_nodes = sim.counters().peak_nodes;
    row.peak_tets = sim.counters().peak_tets;
    row.splits = sim.counters().splits;
    row.merges = sim.counters().merges;
    row.merges_after = sim.counters().merges - merges_t2;
    std::fprintf(stderr, "  table1: %s done in %.1f s wall\n", row.name.c_str(), seconds_between(wall0, Clock::now()));
  }

  const Row& high = rows[1];
  const double t2_sample = steps_t2 * dt;
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
        1e3 * row.tip_bottom[2], is_high ? "—" : pct(e_bottom).c_str(), 1e3 * row.tip_centre[2],
        is_high ? "—" : pct(e_centre).c_str(), is_high ? "—" : pct(fe.rms_rel).c_str(),
        is_high ? "—" : pct(fe.max_rel).c_str(), row.st.wall_cost(), row.st.cpu_cost(), row.wall_cost_total,
        row.cpu_cost_total, row.nodes_end, row.tets_end);
    if (!is_high && fe.unlocated > 0)
      std::printf("|  ↳ %zu reference nodes not located in this mesh |\n", fe.unlocated);
  }
  std::printf("| *paper (their 9^3-cell high)* | 125 / 1000 / 299 | 384 / 4374 / 1048 | | | | | | | | | | | | |\n\n");

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
                row.mesh.adaptive ? fmt("%.3f", row.last_adapt_t2_s).c_str() : "—",
                row.mesh.adaptive
                    ? (std::isfinite(row.coarse_again_s) ? fmt("%.3f", row.coarse_again_s) : "never").c_str()
                    : "—",
                row.st.mean_iterations(), row.st.ok ? "no" : shorten(row.st.error).c_str());
}

// ---------------------------------------------------------------------------
// --beam-theory

struct BeamTheory {
  double euler_bernoulli_m, timoshenko_m;
};

BeamTheory beam_theory_tip() {
  const double F = 0.05, L = 0.4, b = 0.1, h = 0.1, E = 5.0e4, nu = 0.25;  // nu = 1/4 for eq. (3) springs
  const double I = b * h * h * h / 12.0, A = b * h, G = E / (2.0 * (1.0 + nu));
  const double kappa = 10.0 * (1.0 + nu) / (12.0 + 11.0 * nu);  // rectangular section (Cowper)
  const double eb = F * L * L * L / (3.0 * E * I);
  return {eb, eb + F * L / (kappa * G * A)};
}

// Static equilibrium by implicit Euler at a large step, until the force
// residual over the free nodes is below tol_rel of the load.
struct StaticResult {
  Vec3 tip_centre = Vec3::Zero(), tip_bottom = Vec3::Zero();
  double residual_rel = NAN;
  long steps = 0;
  double wall_s = 0.0;
  std::size_t nodes = 0, tets = 0;
  bool ok = true;
  std::string error;
};

double force_residual_N(const ph::Simulation& sim) {
  const ph::Body& body = sim.body();
  ph::LoadDistribution loads;
  loads.rebuild(body);
  std::vector<Vec3> f;
  loads.external_forces(body, sim.time_s(), f);
  ph::add_spring_forces(body, f, false);
  double sum2 = 0.0;
  body.mesh().for_each_node([&](ph::NodeId n, const tissue::mesh::Node&) {
    if (body.kind[n] == ph::NodeKind::kFree) sum2 += f[n].squaredNorm();
  });
  return std::sqrt(sum2);
}

StaticResult solve_static(sc::Scene s, long max_steps, double tol_rel) {
  s.integrator.kind = sc::IntegratorKind::kImplicit;
  s.integrator.dt_s = 0.05;
  s.integrator.cg_max_iterations = 2000;
  s.integrator.cg_tolerance = 1e-10;
  StaticResult r;
  const auto t0 = Clock::now();
  ph::Simulation sim(s);
  const auto& f = s.loads[0].total_force_N;
  const double load = std::sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2]);
  RunStats st;
  while (r.steps < max_steps) {
    if (!advance(sim, 10, st)) {
      r.ok = false;
      r.error = st.error;
      break;
    }
    r.steps += 10;
    r.residual_rel = force_residual_N(sim) / load;
    if (r.residual_rel < tol_rel) break;
  }
  r.tip_centre = sim.probe_displacement_m(0);
  r.tip_bottom = sim.probe_displacement_m(1);
  r.nodes = sim.body().mesh().node_count();
  r.tets = sim.body().mesh().tet_count();
  r.wall_s = seconds_between(t0, Clock::now());
  return r;
}

void run_beam_theory(const Options& o) {
  const int max_depth = o.beam_max_depth >= 0 ? o.beam_max_depth : (o.quick ? 4 : 6);
  const long max_steps = o.quick ? 200 : 600;
  const double tol_rel = 1e-6;
  const BeamTheory bt = beam_theory_tip();
  const double axial_m = 0.05 * 0.4 / (5.0e4 * 0.01);  // F L / (E A)
  std::printf("\n## Beam theory: static tip of the 0.4 x 0.1 x 0.1 m beam, E = 5e4 Pa, 0.05 N (linear regime)\n\n");
  std::printf(
      "Bending: 0.05 N down on the free face; Euler-Bernoulli %.3f mm, Timoshenko (nu = 1/4, kappa = "
      "10(1+nu)/(12+11nu)) %.3f mm. Tip = free-face centre {0.4, 0.05, 0.05} (neutral axis). Axial check (separates "
      "lattice anisotropy from bending error): 0.05 N along +x, tip u_x vs F L / (E A) = %.1f um -> effective E_x "
      "(clamped end, so slightly stiff). Statics by implicit Euler dt 0.05 s, CG tol 1e-10, until the free-node "
      "force residual < %.0e of the load (max %ld steps).\n\n",
      1e3 * bt.euler_bernoulli_m, 1e3 * bt.timoshenko_m, 1e6 * axial_m, tol_rel, max_steps);
  std::printf(
      "| law | depth | nodes | tets | tip u_z (mm) | vs Euler-Bernoulli | vs Timoshenko | vs depth %d, same law | "
      "bottom-edge u_z (mm) | axial u_x (um) | E_x,eff / E | steps bend / axial | residual / load | wall s |\n",
      max_depth);
  std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  for (const auto law : {sc::StiffnessLaw::kIsotropic, sc::StiffnessLaw::kPaper}) {
    std::vector<StaticResult> bend, axial;
    for (int d = 0; d <= max_depth; ++d) {
      sc::Scene s = beam({false, d, 0.0, d}, sc::IntegratorKind::kImplicit, 0.05, 0.0);
      s.material.stiffness = law;
      bend.push_back(solve_static(s, max_steps, tol_rel));
      s.loads[0].total_force_N = {0.05, 0.0, 0.0};
      axial.push_back(solve_static(s, max_steps, tol_rel));
      std::fprintf(stderr, "  beam-theory: %s depth %d: %.1f + %.1f s wall\n",
                   law == sc::StiffnessLaw::kIsotropic ? "isotropic" : "paper", d, bend.back().wall_s,
                   axial.back().wall_s);
    }
    const double finest = -bend.back().tip_centre[2];
    for (int d = 0; d <= max_depth; ++d) {
      const StaticResult& r = bend[static_cast<std::size_t>(d)];
      const StaticResult& a = axial[static_cast<std::size_t>(d)];
      const double w = -r.tip_centre[2];
      const double ux = a.tip_centre[0];
      std::string failed;
      if (!r.ok) failed += " bending failed: " + shorten(r.error);
      if (!a.ok) failed += " axial failed: " + shorten(a.error);
      std::printf(
          "| %s | %d | %zu | %zu | %.3f | %+.1f %% | %+.1f %% | %+.1f %% | %.3f | %.2f | %.3f | %ld / %ld | %.1e / "
          "%.1e | %.1f |%s\n",
          law == sc::StiffnessLaw::kIsotropic ? "isotropic" : "paper", d, r.nodes, r.tets, 1e3 * w,
          100.0 * (w / bt.euler_bernoulli_m - 1.0), 100.0 * (w / bt.timoshenko_m - 1.0), 100.0 * (w / finest - 1.0),
          -1e3 * r.tip_bottom[2], 1e6 * ux, axial_m / ux, r.steps, a.steps, r.residual_rel, a.residual_rel,
          r.wall_s + a.wall_s, failed.c_str());
    }
    std::fflush(stdout);
  }
}

// ---------------------------------------------------------------------------
// --sweep

struct Point {
  // Setting
  std::string integrator;
  double dt_s = 0.0;
  int max_depth = 0;
  bool adaptive = false;
  int level = 0;       // uniform level
  double th_Pa = NAN;  // adaptive threshold
  // Outcome
  RunStats st;
  std::size_t nodes = 0, tets = 0, springs = 0, peak_nodes = 0, peak_tets = 0;
  long splits = 0, merges = 0;
  int deepest = 0;                  // deepest leaf tet at the end
  std::size_t tets_at_deepest = 0;  // and how many leaves sit there
  Vec3 tip = Vec3::Zero();
  std::vector<double> tip_t_s;  // the tip after every step (a scene with probes)
  std::vector<Vec3> tip_path_m;
  ph::DisplacementField field;  // dropped once errors are filled
  bool captured = false;
  // Errors vs the reference (filled when both ran)
  double tip_err = NAN, rms_err = NAN, max_err = NAN;
  std::size_t unlocated = 0;
  // The tip's path against the truth of its max depth (set_path_errors).
  double path_err = NAN;
  bool has_error = false;
  bool skipped = false;  // not run (reason in st.error)
  std::string status() const {
    if (skipped) return "skipped";
    if (st.interrupted_by != 0) return "interrupted";
    if (!st.ok) return "failed";
    if (st.capped) return "capped";
    return "ok";
  }
};

struct SweepSetup {
  std::string scene;                                        // its name (CSV, plot)
  std::optional<sc::Scene> from_file;                       // --scene-file: the user's scene
  int base_depth = 0;                                       // uniform levels and adaptive runs start here
  std::optional<sc::CgPreconditioner> preconditioner;       // unset: the scene's own
  std::optional<sc::ExplicitPrecision> explicit_precision;  // unset: the scene's own
  double duration_s;
  std::vector<double> th_Pa;
  std::vector<int> max_depths;
  std::vector<sc::IntegratorKind> kinds;
  std::vector<double> dts_s;
  double wall_cap_s;
  bool cost_uses_cpu = false;  // --clock cpu: costs, the cap and the plot's axis in thread CPU time
  // Read before every step: a signal number there ends the sweep (the run in
  // progress is marked interrupted, the rest are not run).
  const volatile std::sig_atomic_t* stop = nullptr;
  bool stopped() const { return stop && *stop != 0; }
};

sc::Scene sweep_scene(const SweepSetup& s, const MeshChoice& m, sc::IntegratorKind kind, double dt) {
  sc::Scene out;
  if (s.from_file) {
    // The user's scene as it is, but for what each run of the sweep sets.
    out = *s.from_file;
    apply_mesh(out, m);
    if (m.adaptive) out.adaptivity.min_depth = s.base_depth;
    out.integrator.kind = kind;
    out.integrator.dt_s = dt;
  } else if (s.scene == "beam" || s.scene == "beam-r") {
    // Static-ish: ramp the load over a quarter of the run and damp the first
    // bending mode (2.3 Hz) about critically with mass-proportional damping.
    out = beam(m, kind, dt, 0.25 * s.duration_s, s.scene == "beam-r");
    out.material.rayleigh_alpha_per_s = 30.0;
  } else {
    out = paper_cantilever(m, kind, dt, std::numeric_limits<double>::infinity());
  }
  if (s.preconditioner) out.integrator.cg_preconditioner = *s.preconditioner;
  if (s.explicit_precision) out.integrator.explicit_precision = *s.explicit_precision;
  return out;
}

Point run_point(const SweepSetup& s, const MeshChoice& m, sc::IntegratorKind kind, double dt) {
  Point p;
  p.st.cost_uses_cpu = s.cost_uses_cpu;
  p.integrator = kind_name(kind);
  p.dt_s = dt;
  p.adaptive = m.adaptive;
  p.level = m.depth;
  p.max_depth = m.max_depth;
  p.th_Pa = m.adaptive ? m.th_Pa : NAN;
  ph::Simulation sim(sweep_scene(s, m, kind, dt));
  const long steps = std::lround(s.duration_s / dt);
  const bool has_tip = sim.probe_count() > 0;
  advance(
      sim, steps, p.st, s.wall_cap_s,
      [&](const ph::Simulation&) {
        if (!has_tip) return;
        p.tip_t_s.push_back(sim.time_s());
        p.tip_path_m.push_back(sim.probe_displacement_m(0));
      },
      s.stop);
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
  if (p.st.ok && !p.st.capped) {
    // The first probe is the tip (a scene file without probes has no tip error).
    p.tip = sim.probe_count() > 0 ? sim.probe_displacement_m(0) : Vec3::Constant(NAN);
    p.field = ph::capture_displacement_field(sim.body());
    p.captured = true;
  }
  return p;
}

void fill_errors(Point& p, const Point& ref) {
  if (!p.captured || !ref.captured) return;
  p.tip_err = (p.tip - ref.tip).norm() / ref.tip.norm();
  const ph::FieldError fe = ph::compare_displacement_fields(ref.field, p.field);
  p.rms_err = fe.rms_rel;
  p.max_err = fe.max_rel;
  p.unlocated = fe.unlocated;
  p.has_error = true;
}

// The dynamics' truth at each max depth: the uniform run at that depth with
// the smallest time error, explicit (symplectic, sub-stepped far below dt)
// at the smallest dt if the sweep ran it, else implicit, else projective.
// Every run's tip path is measured against it: the same-integrator
// reference above measures the mesh; this measures integrator and dt too
// (implicit Euler's damping at large dt ends in the same static state).
// Returns, per max depth, what the truth was ("" where none finished).
std::map<int, std::string> set_path_errors(std::vector<Point>& points) {
  std::map<int, const Point*> truth;
  const auto rank = [](const Point& p) { return p.integrator == "explicit" ? 0 : p.integrator == "implicit" ? 1 : 2; };
  for (const Point& p : points) {
    if (p.adaptive || p.level != p.max_depth || !p.st.ok || p.st.capped || p.tip_path_m.empty()) continue;
    const Point*& best = truth[p.max_depth];
    if (!best || rank(p) < rank(*best) || (rank(p) == rank(*best) && p.dt_s < best->dt_s)) best = &p;
  }
  std::map<int, std::string> described;
  for (const auto& [md, t] : truth)
    described[md] = t ? t->integrator + " at dt " + fmt("%g", t->dt_s * 1e3) + " ms, uniform L" + std::to_string(md)
                      : std::string();
  for (Point& p : points) {
    const auto it = truth.find(p.max_depth);
    if (it == truth.end() || !it->second || !p.st.ok || p.st.capped || p.tip_path_m.empty()) continue;
    p.path_err = ph::compare_trajectories(it->second->tip_t_s, it->second->tip_path_m, p.tip_t_s, p.tip_path_m).rms_rel;
  }
  return described;
}

double metric_of(const Point& p, const std::string& metric) {
  if (metric == "tip") return p.tip_err;
  if (metric == "path") return p.path_err;
  if (metric == "max") return p.max_err;
  return p.rms_err;
}

std::string csv_num(double v) { return std::isfinite(v) ? fmt("%.6g", v) : ""; }

std::string csv_quote(const std::string& s) {
  std::string out = "\"";
  for (char c : s) out += c == '"' ? std::string("\"\"") : std::string(1, c);
  return out + "\"";
}

std::string csv_text(const std::string& scene, const std::vector<Point>& points,
                     const std::map<int, std::string>& truth) {
  std::ostringstream f;
  f << "scene,integrator,dt_s,max_depth,mode,level,th_Pa,status,message,steps,sim_s,wall_s,cpu_s,"
       "cost_wall_per_sim,cost_cpu_per_sim,"
       "nodes_end,tets_end,springs_end,peak_nodes,peak_tets,splits,merges,tip_uz_m,tip_err_rel,rms_err_rel,"
       "max_err_rel,unlocated,mean_solver_iterations,max_substeps,last_mesh_change_s,deepest_level,tets_at_deepest,"
       "unconverged_steps,tip_path_err_rel,path_truth\n";
  for (const auto& p : points) {
    f << csv_quote(scene) << ',' << p.integrator << ',' << p.dt_s << ',' << p.max_depth << ','
      << (p.adaptive ? "adaptive" : "uniform") << ',' << (p.adaptive ? std::string() : std::to_string(p.level)) << ','
      << csv_num(p.th_Pa) << ',' << p.status() << ','
      << csv_quote(p.st.ok ? (p.st.capped ? "stopped by the per-run wall cap" : "") : p.st.error) << ',' << p.st.steps
      << ',' << csv_num(p.st.sim_s) << ',' << csv_num(p.st.wall_s) << ',' << csv_num(p.st.cpu_s) << ','
      << csv_num(p.st.wall_cost()) << ',' << csv_num(p.st.cpu_cost()) << ',' << p.nodes << ',' << p.tets << ','
      << p.springs << ',' << p.peak_nodes << ',' << p.peak_tets << ',' << p.splits << ',' << p.merges << ','
      << (p.captured ? csv_num(p.tip[2]) : "") << ',' << csv_num(p.tip_err) << ',' << csv_num(p.rms_err) << ','
      << csv_num(p.max_err) << ',' << p.unlocated << ',' << csv_num(p.st.mean_iterations()) << ',' << p.st.max_substeps
      << ',' << csv_num(p.st.last_adapt_s) << ',' << p.deepest << ',' << p.tets_at_deepest << ','
      << p.st.unconverged_steps << ',' << csv_num(p.path_err) << ','
      << csv_quote(truth.count(p.max_depth) ? truth.at(p.max_depth) : "") << '\n';
  }
  return f.str();
}

// Hand-written SVG: one log-log panel per (integrator, dt) row and max-depth
// column, shared axes. Uniform levels: squares joined by a line; the
// reference (error 0 by definition) as a dashed vertical line at its cost;
// adaptive points: circles coloured by Th.
std::string svg_text(const SweepSetup& s, const std::vector<Point>& points, const std::string& metric) {
  const std::vector<std::string> colours = {"#d62728", "#ff7f0e", "#2ca02c", "#1f77b4",
                                            "#9467bd", "#8c564b", "#e377c2", "#17becf"};
  double cmin = INFINITY, cmax = 0, emin = INFINITY, emax = 0;
  for (const auto& p : points) {
    const double c = p.st.cost();
    if (std::isfinite(c) && c > 0) cmin = std::min(cmin, c), cmax = std::max(cmax, c);
    const double e = metric_of(p, metric);
    if (std::isfinite(e) && e > 0) emin = std::min(emin, e), emax = std::max(emax, e);
  }
  if (!(cmax > 0)) cmin = 1e-3, cmax = 1;
  if (!(emax > 0)) emin = 1e-3, emax = 1;
  const double lc0 = std::floor(std::log10(cmin)), lc1 = std::ceil(std::log10(cmax) + 1e-9);
  const double le0 = std::floor(std::log10(emin)), le1 = std::ceil(std::log10(emax) + 1e-9);

  // Rows: integrators; columns: (dt, max depth).
  struct Column {
    double dt;
    int max_depth;
  };
  std::vector<Column> columns;
  for (double dt : s.dts_s)
    for (int md : s.max_depths) columns.push_back({dt, md});
  const auto& rows = s.kinds;
  const int cols = static_cast<int>(columns.size());
  const double pw = 330, ph_ = 230, ml = 70, mr = 20, mt = 36, mb = 46;  // panel size and margins
  const double legend_h = 70, title_h = 40;
  const double width = std::max(900.0, cols * (ml + pw + mr) + 10);
  const double height = title_h + legend_h + rows.size() * (mt + ph_ + mb) + 10;

  std::ostringstream o;
  o << "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" << width << "\" height=\"" << height
    << "\" font-family=\"sans-serif\" font-size=\"11\">\n<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n";
  const std::string metric_label = metric == "tip"    ? "tip displacement error"
                                   : metric == "max"  ? "max node error / max |u_ref|"
                                   : metric == "path" ? "tip path error vs the truth run / max |u_tip,truth|"
                                                      : "RMS node error / max |u_ref|";
  o << "<text x=\"10\" y=\"22\" font-size=\"15\" font-weight=\"bold\">Cost vs error, "
    << tissue::util::escape_xml(s.scene) << " at t = " << s.duration_s
    << " s: adaptive points below the uniform curve = adaptivity pays</text>\n";
  // Legend
  double lx = 10, ly = title_h + 10;
  o << "<rect x=\"" << lx << "\" y=\"" << ly - 6 << "\" width=\"10\" height=\"10\" fill=\"black\"/><text x=\""
    << lx + 14 << "\" y=\"" << ly + 3 << "\">uniform levels L0..L(max-1) (line)</text>\n";
  o << "<line x1=\"" << lx + 230 << "\" y1=\"" << ly - 6 << "\" x2=\"" << lx + 230 << "\" y2=\"" << ly + 6
    << "\" stroke=\"gray\" stroke-dasharray=\"4,3\" stroke-width=\"1.5\"/><text x=\"" << lx + 236 << "\" y=\"" << ly + 3
    << "\">uniform reference at max depth (error 0 by definition): its cost</text>\n";
  for (std::size_t i = 0; i < s.th_Pa.size(); ++i) {
    const double x = lx + 14 + 120 * static_cast<double>(i % 6), y = ly + 22 + 16 * static_cast<double>(i / 6);
    o << "<circle cx=\"" << x - 8 << "\" cy=\"" << y - 4 << "\" r=\"4.5\" fill=\"" << colours[i % colours.size()]
      << "\"/><text x=\"" << x << "\" y=\"" << y << "\">adaptive Th = " << s.th_Pa[i] << " Pa</text>\n";
  }
  o << "<text x=\"" << lx << "\" y=\"" << ly + 54 << "\">x: cost = " << (s.cost_uses_cpu ? "thread CPU" : "wall")
    << " s per simulated s (step incl. adaptation); y: " << metric_label
    << " vs the uniform reference at the same max depth (log-log)</text>\n";

  auto th_index = [&](double th) {
    for (std::size_t i = 0; i < s.th_Pa.size(); ++i)
      if (s.th_Pa[i] == th) return i;
    return std::size_t{0};
  };
  for (std::size_t r = 0; r < rows.size(); ++r) {
    for (int c = 0; c < cols; ++c) {
      const int md = columns[static_cast<std::size_t>(c)].max_depth;
      const double dt = columns[static_cast<std::size_t>(c)].dt;
      const double x0 = c * (ml + pw + mr) + ml, y0 = title_h + legend_h + r * (mt + ph_ + mb) + mt;
      auto X = [&](double cost) { return x0 + pw * (std::log10(cost) - lc0) / (lc1 - lc0); };
      auto Y = [&](double err) { return y0 + ph_ * (1.0 - (std::log10(err) - le0) / (le1 - le0)); };
      o << "<text x=\"" << x0 << "\" y=\"" << y0 - 8 << "\" font-weight=\"bold\">" << kind_name(rows[r])
        << ", dt = " << dt * 1e3 << " ms, max depth " << md << "</text>\n";
      o << "<rect x=\"" << x0 << "\" y=\"" << y0 << "\" width=\"" << pw << "\" height=\"" << ph_
        << "\" fill=\"none\" stroke=\"black\"/>\n";
      for (double d = lc0; d <= lc1 + 1e-9; d += 1) {
        const double x = X(std::pow(10.0, d));
        o << "<line x1=\"" << x << "\" y1=\"" << y0 << "\" x2=\"" << x << "\" y2=\"" << y0 + ph_
          << "\" stroke=\"#ddd\"/><text x=\"" << x << "\" y=\"" << y0 + ph_ + 14 << "\" text-anchor=\"middle\">1e" << d
          << "</text>\n";
      }
      for (double d = le0; d <= le1 + 1e-9; d += 1) {
        const double y = Y(std::pow(10.0, d));
        o << "<line x1=\"" << x0 << "\" y1=\"" << y << "\" x2=\"" << x0 + pw << "\" y2=\"" << y
          << "\" stroke=\"#ddd\"/><text x=\"" << x0 - 4 << "\" y=\"" << y + 4 << "\" text-anchor=\"end\">1e" << d
          << "</text>\n";
      }
      o << "<text x=\"" << x0 + pw / 2 << "\" y=\"" << y0 + ph_ + 30 << "\" text-anchor=\"middle\">cost ["
        << (s.cost_uses_cpu ? "CPU" : "wall") << " s / simulated s]</text>\n";
      o << "<text transform=\"translate(" << x0 - 48 << "," << y0 + ph_ / 2 << ") rotate(-90)\" text-anchor=\"middle\">"
        << (metric == "tip"    ? "tip error [-]"
            : metric == "path" ? "tip path error [-]"
                               : "node error [-]")
        << "</text>\n";

      std::vector<const Point*> uni, ada;
      const Point* ref = nullptr;
      std::vector<std::string> notes;
      int skipped_levels = 0, skipped_adaptive = 0;
      for (const auto& p : points) {
        if (p.integrator != kind_name(rows[r]) || p.dt_s != dt || p.max_depth != md) continue;
        if (!p.adaptive && p.level == md) ref = &p;
        if (p.skipped) {
          ++(p.adaptive ? skipped_adaptive : skipped_levels);
        } else if (!p.st.ok || p.st.capped) {
          std::ostringstream n;
          n << (p.adaptive ? "Th " + fmt("%g", p.th_Pa) : "L" + std::to_string(p.level))
            << (p.st.ok ? " hit the run cap (cost " + fmt("%.3g", p.st.cost()) + " s/s)"
                        : " refused/failed at t=" + fmt("%.3g", p.st.error_time_s) + " s");
          notes.push_back(n.str());
        }
        const double e = metric_of(p, metric), cost = p.st.cost();
        if (!(std::isfinite(e) && e > 0 && std::isfinite(cost) && cost > 0)) continue;
        (p.adaptive ? ada : uni).push_back(&p);
      }
      if (skipped_levels > 0) notes.push_back(std::to_string(skipped_levels) + " finer uniform level(s) not run");
      if (skipped_adaptive > 0)
        notes.push_back(std::to_string(skipped_adaptive) + " adaptive run(s) not run: no reference L" +
                        std::to_string(md));
      if (ref && !ref->captured) notes.push_back("no errors: the reference L" + std::to_string(md) + " did not finish");
      if (ref && std::isfinite(ref->st.cost()) && ref->st.cost() > 0) {
        const double x = X(ref->st.cost());
        o << "<line x1=\"" << x << "\" y1=\"" << y0 << "\" x2=\"" << x << "\" y2=\"" << y0 + ph_
          << "\" stroke=\"gray\" stroke-dasharray=\"4,3\" stroke-width=\"1.5\"/><text x=\"" << x + 3 << "\" y=\""
          << y0 + 12 << "\" fill=\"gray\">L" << md << (ref->st.capped ? " (capped)" : "") << "</text>\n";
      }
      std::sort(uni.begin(), uni.end(), [](const Point* a, const Point* b) { return a->level < b->level; });
      if (uni.size() > 1) {
        o << "<polyline fill=\"none\" stroke=\"black\" stroke-width=\"1.5\" points=\"";
        for (const Point* p : uni) o << X(p->st.cost()) << ',' << Y(metric_of(*p, metric)) << ' ';
        o << "\"/>\n";
      }
      for (const Point* p : uni) {
        const double x = X(p->st.cost()), y = Y(metric_of(*p, metric));
        o << "<rect x=\"" << x - 4 << "\" y=\"" << y - 4 << "\" width=\"8\" height=\"8\" fill=\"black\"/><text x=\""
          << x + 6 << "\" y=\"" << y - 5 << "\">L" << p->level << "</text>\n";
      }
      for (const Point* p : ada) {
        o << "<circle cx=\"" << X(p->st.cost()) << "\" cy=\"" << Y(metric_of(*p, metric))
          << "\" r=\"4.5\" fill-opacity=\"0.85\" fill=\"" << colours[th_index(p->th_Pa) % colours.size()]
          << "\" stroke=\"black\" stroke-width=\"0.5\"/><text x=\"" << X(p->st.cost()) + 6 << "\" y=\""
          << Y(metric_of(*p, metric)) + 10 << "\" font-size=\"9\" fill=\""
          << colours[th_index(p->th_Pa) % colours.size()] << "\">" << p->th_Pa << "</text>\n";
      }
      for (std::size_t i = 0; i < notes.size() && i < 8; ++i)
        o << "<text x=\"" << x0 + 6 << "\" y=\"" << y0 + ph_ - 8 - 12 * static_cast<double>(i)
          << "\" fill=\"#a00\" font-size=\"10\">" << notes[i] << "</text>\n";
    }
  }
  o << "</svg>\n";
  return o.str();
}

// A --csv or --svg file that could not be written (the message names it).
struct OutputError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// Runs the sweep, prints its tables and writes `csv` / `svg` (those opened).
// Returns the signal that interrupted it (the tables and files then hold the
// runs done), or 0.
// How a sweep ended: the signal that stopped it (0: none), and whether any
// run gave figures (ok, or capped by --run-cap with what it reached).
struct SweepEnd {
  int signal = 0;
  bool any_figures = false;
};

SweepEnd run_sweep(const Options& o, OutputFile& csv, OutputFile& svg, const volatile std::sig_atomic_t* stop) {
  SweepSetup s;
  s.scene = o.sweep_scene;
  s.cost_uses_cpu = o.cpu_clock;
  s.stop = stop;
  if (!o.scene_file.empty()) {
    s.from_file = sc::load_scene_file_with_overrides(o.scene_file, o.scene_overrides);
    s.scene = s.from_file->name;
    s.base_depth = s.from_file->adaptivity.min_depth;
  }
  const std::string preconditioner = !o.preconditioner.empty() ? o.preconditioner : s.from_file ? "" : "jacobi";
  if (!preconditioner.empty())
    s.preconditioner = preconditioner == "two_level" ? sc::CgPreconditioner::kTwoLevel
                       : preconditioner == "auto"    ? sc::CgPreconditioner::kAuto
                                                     : sc::CgPreconditioner::kJacobi;
  const std::string precision = !o.explicit_precision.empty() ? o.explicit_precision : s.from_file ? "" : "double";
  if (!precision.empty())
    s.explicit_precision = precision == "float" ? sc::ExplicitPrecision::kFloat : sc::ExplicitPrecision::kDouble;
  const bool is_beam = !s.from_file && (s.scene == "beam" || s.scene == "beam-r");
  s.duration_s = o.sweep_duration_s > 0 ? o.sweep_duration_s : is_beam ? (o.quick ? 0.5 : 1.0) : (o.quick ? 0.2 : 0.5);
  if (!o.th_Pa.empty())
    s.th_Pa = o.th_Pa;
  else if (s.from_file) {  // around the scene's own threshold
    const double th = s.from_file->adaptivity.refine_threshold_Pa;
    s.th_Pa = o.quick ? std::vector<double>{th, 4 * th} : std::vector<double>{0.25 * th, th, 4 * th};
  } else if (is_beam)
    s.th_Pa = o.quick ? std::vector<double>{0.01, 0.1} : std::vector<double>{0.003, 0.01, 0.03, 0.1, 0.3};
  else
    s.th_Pa = o.quick ? std::vector<double>{5, 20, 80} : std::vector<double>{5, 20, 40, 80, 300};
  if (!o.max_depths.empty())
    s.max_depths = o.max_depths;
  else if (s.from_file)
    s.max_depths = {s.from_file->adaptivity.max_depth};
  else
    s.max_depths = o.quick ? std::vector<int>{3} : std::vector<int>{3, 6};
  for (const int md : s.max_depths)
    if (md <= s.base_depth)
      throw std::invalid_argument("max depth " + std::to_string(md) + " leaves nothing to refine above the scene's " +
                                  "adaptivity.min_depth " + std::to_string(s.base_depth) +
                                  " (give --depths above it, or raise the scene's adaptivity.max_depth)");
  if (o.integrators.empty())
    s.kinds = {sc::IntegratorKind::kImplicit, sc::IntegratorKind::kExplicit, sc::IntegratorKind::kProjective};
  else
    for (const auto& k : o.integrators) s.kinds.push_back(kind_of(k));
  if (!o.dts_s.empty())
    s.dts_s = o.dts_s;
  else if (s.from_file)
    s.dts_s = {s.from_file->integrator.dt_s};
  else
    s.dts_s = {1e-3, 5e-3};
  s.wall_cap_s = o.run_wall_cap_s > 0 ? o.run_wall_cap_s : (o.quick ? 3.0 : 30.0);
  const int deepest = *std::max_element(s.max_depths.begin(), s.max_depths.end());
  // Uniform level L is uniform[L - base_depth].
  const auto uniform_at = [&](std::vector<Point>& uniform, int level) -> Point& {
    return uniform[static_cast<std::size_t>(level - s.base_depth)];
  };

  const std::string about = s.from_file ? "scene file " + o.scene_file + ", its loads and boundary conditions"
                            : is_beam   ? "0.05 N ramped over the first quarter, Rayleigh alpha 30/s: static-ish"
                                        : "seed §4.1, constant 5 N: static from ~0.3 s on";
  std::printf("\n## Sweep: %s (%s), state at t = %.2f s%s\n\n", s.scene.c_str(), about.c_str(), s.duration_s,
              o.quick ? " (--quick)" : "");
  if (s.from_file && s.from_file->probes.empty())
    std::printf("The scene has no probes: no tip error (the first probe is the tip).\n");
  std::printf("Th (Pa):");
  for (double t : s.th_Pa) std::printf(" %g", t);
  std::printf("; max depths:");
  for (int d : s.max_depths) std::printf(" %d", d);
  std::printf("; per-run wall cap %.0f s (a capped run still gives its cost, not its error).\n\n", s.wall_cap_s);

  std::vector<Point> points;
  const auto sweep0 = Clock::now();
  for (auto kind : s.kinds) {
    for (double dt : s.dts_s) {
      // Uniform levels base..deepest, run once, compared against each max depth's reference.
      std::vector<Point> uniform;
      std::string stop_reason;  // set once a level failed or hit the cap: finer ones would too
      for (int level = s.base_depth; level <= deepest; ++level) {
        if (s.stopped()) stop_reason = "not run: interrupted by " + signal_name(*s.stop);
        if (!stop_reason.empty()) {
          Point p;
          p.integrator = kind_name(kind);
          p.dt_s = dt;
          p.level = level;
          p.skipped = true;
          p.st.ok = false;
          p.st.error = stop_reason;
          uniform.push_back(p);
          continue;
        }
        const auto t0 = Clock::now();
        uniform.push_back(run_point(s, {false, level, 0.0, level}, kind, dt));
        const Point& p = uniform.back();
        if (!p.st.ok) stop_reason = "not run: uniform L" + std::to_string(level) + " failed or refused";
        if (p.st.interrupted_by != 0) stop_reason = "not run: interrupted by " + signal_name(p.st.interrupted_by);
        if (p.st.capped) stop_reason = "not run: uniform L" + std::to_string(level) + " already hit the wall cap";
        std::fprintf(stderr, "  sweep: %s dt %g uniform L%d: %s, %.1f s wall\n", kind_name(kind), dt, level,
                     p.status().c_str(), seconds_between(t0, Clock::now()));
      }
      for (int md : s.max_depths) {
        const Point& ref = uniform_at(uniform, md);
        for (int level = s.base_depth; level <= md; ++level) {
          Point p = uniform_at(uniform, level);
          p.max_depth = md;
          fill_errors(p, ref);
          points.push_back(std::move(p));
        }
        for (double th : s.th_Pa) {
          if (!ref.captured || s.stopped()) {  // no reference, no error: the point would only cost time
            Point p;
            p.integrator = kind_name(kind);
            p.dt_s = dt;
            p.adaptive = true;
            p.max_depth = md;
            p.th_Pa = th;
            p.skipped = true;
            p.st.ok = false;
            p.st.error = s.stopped()
                             ? "not run: interrupted by " + signal_name(*s.stop)
                             : "not run: no reference (uniform L" + std::to_string(md) + " " + ref.status() + ")";
            points.push_back(std::move(p));
            continue;
          }
          const auto t0 = Clock::now();
          Point p = run_point(s, {true, 0, th, md}, kind, dt);
          fill_errors(p, ref);
          std::fprintf(stderr, "  sweep: %s dt %g max depth %d Th %g: %s, %zu tets, %.1f s wall\n", kind_name(kind), dt,
                       md, th, p.status().c_str(), p.tets, seconds_between(t0, Clock::now()));
          points.push_back(std::move(p));
        }
      }
      for (auto& p : points) {  // fields are large; keep only what the table and files need
        if (p.integrator == kind_name(kind) && p.dt_s == dt) p.field = ph::DisplacementField{};
      }
    }
  }
  const double sweep_wall = seconds_between(sweep0, Clock::now());
  const std::map<int, std::string> truth = set_path_errors(points);
  for (const auto& [md, what] : truth)
    std::printf(
        "Tip path error at max depth %d: RMS over the run of |u_tip(t) - u_truth(t)| / max |u_truth|, "
        "truth = %s.\n",
        md, what.c_str());
  std::printf("\n");

  std::printf(
      "| integrator | dt (ms) | max depth | mesh | status | tets (end) | peak tets | deepest leaf (tets there) | "
      "cost wall (cpu) s/s | tip err | node RMS err | node max err | tip path err | mean iters | max substeps | "
      "last mesh change (s) |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  for (const auto& p : points) {
    const std::string mesh = p.adaptive ? "adaptive Th " + fmt("%g", p.th_Pa) : "uniform L" + std::to_string(p.level);
    std::string status = p.status();
    if (!p.st.ok && !p.skipped) status += " at t=" + fmt("%.3g", p.st.error_time_s) + " s";
    if (p.st.unconverged_steps > 0)  // cheaper, but short of the tolerance: say so beside the cost
      status += ", " + std::to_string(p.st.unconverged_steps) + " steps CG-capped";
    std::printf("| %s | %g | %d | %s | %s | %zu | %zu | %d (%zu) | %s | %s | %s | %s | %s | %.1f | %d | %s |\n",
                p.integrator.c_str(), p.dt_s * 1e3, p.max_depth, mesh.c_str(), status.c_str(), p.tets, p.peak_tets,
                p.deepest, p.tets_at_deepest,
                std::isfinite(p.st.wall_cost())
                    ? (fmt("%.3g", p.st.wall_cost()) + " (" + fmt("%.3g", p.st.cpu_cost()) + ")").c_str()
                    : "n/a",
                p.adaptive || p.level != p.max_depth ? pct(p.tip_err).c_str() : "ref",
                p.adaptive || p.level != p.max_depth ? pct(p.rms_err).c_str() : "ref",
                p.adaptive || p.level != p.max_depth ? pct(p.max_err).c_str() : "ref", pct(p.path_err).c_str(),
                p.st.mean_iterations(), p.st.max_substeps,
                p.adaptive && std::isfinite(p.st.last_adapt_s) ? fmt("%.3f", p.st.last_adapt_s).c_str() : "");
  }

  // Refusals, one line per distinct message.
  std::map<std::string, std::vector<std::string>> refusals;
  for (const auto& p : points)
    if (!p.st.ok) {
      const std::string who = std::string(p.integrator) + " dt " + fmt("%g", p.dt_s * 1e3) + " ms " +
                              (p.adaptive ? "Th " + fmt("%g", p.th_Pa) + " md " + std::to_string(p.max_depth)
                                          : "L" + std::to_string(p.level)) +
                              (p.skipped ? "" : " at t=" + fmt("%.3g", p.st.error_time_s) + " s");
      auto& list = refusals[shorten(p.st.error, 200)];
      if (std::find(list.begin(), list.end(), who) == list.end()) list.push_back(who);
    }
  if (!refusals.empty()) {
    std::printf("\nRefusals / failures:\n");
    for (const auto& [msg, who] : refusals) {
      std::printf("- %s\n  runs:", msg.c_str());
      for (const auto& w : who) std::printf(" [%s]", w.c_str());
      std::printf("\n");
    }
  }

  // Where do the adaptive points lie relative to the uniform curve? Compare
  // each adaptive point's error with the uniform curve interpolated
  // (log-log) at the same cost.
  std::printf("\nAdaptive vs uniform curve (%s metric; 'below' = less error than uniform at equal cost):\n\n",
              o.metric.c_str());
  std::printf("| integrator | dt (ms) | max depth | Th | cost | error | uniform error at that cost | verdict |\n");
  std::printf("|---|---|---|---|---|---|---|---|\n");
  for (const auto& p : points) {
    if (!p.adaptive) continue;
    const double e = metric_of(p, o.metric), c = p.st.cost();
    if (!(std::isfinite(e) && std::isfinite(c))) continue;
    // (log cost, log err) of the uniform levels below md (the reference has
    // no error against itself); the path error is against the truth run, so
    // there the reference level is a point of the curve too.
    std::vector<std::pair<double, double>> curve;
    const bool against_truth = o.metric == "path";
    for (const auto& q : points)
      if (!q.adaptive && q.integrator == p.integrator && q.dt_s == p.dt_s && q.max_depth == p.max_depth &&
          (q.level < q.max_depth || against_truth) && std::isfinite(metric_of(q, o.metric)) &&
          metric_of(q, o.metric) > 0 && std::isfinite(q.st.cost()))
        curve.emplace_back(std::log10(q.st.cost()), std::log10(metric_of(q, o.metric)));
    std::sort(curve.begin(), curve.end());
    double ref_cost = NAN;
    for (const auto& q : points)
      if (!q.adaptive && q.integrator == p.integrator && q.dt_s == p.dt_s && q.max_depth == p.max_depth &&
          q.level == q.max_depth)
        ref_cost = q.st.ok ? q.st.cost() : NAN;
    std::string uni = "n/a", verdict = "no uniform curve";
    const double lc = std::log10(c);
    if (curve.size() >= 2) {
      if (lc < curve.front().first) {
        uni = "—";
        verdict = "cheaper than L0";
        if (std::log10(e) < curve.front().second) verdict += ", and more accurate: below";
      } else if (lc > curve.back().first) {
        uni = "—";
        const bool cheaper_than_ref = std::isfinite(ref_cost) && c < ref_cost;
        verdict = std::log10(e) < curve.back().second
                      ? (cheaper_than_ref ? "below (between L(max-1) and the reference in cost)"
                                          : "costs more than the reference itself")
                      : (cheaper_than_ref ? "above (costlier and less accurate than L(max-1))"
                                          : "costs more than the reference itself");
      } else {
        for (std::size_t i = 0; i + 1 < curve.size(); ++i)
          if (lc >= curve[i].first && lc <= curve[i + 1].first) {
            const double w = (lc - curve[i].first) / std::max(curve[i + 1].first - curve[i].first, 1e-12);
            const double le = curve[i].second + w * (curve[i + 1].second - curve[i].second);
            uni = pct(std::pow(10.0, le));
            verdict = std::log10(e) < le ? fmt("below (%.2gx less error)", std::pow(10.0, le - std::log10(e)))
                                         : fmt("above (%.2gx more error)", std::pow(10.0, std::log10(e) - le));
            break;
          }
      }
    }
    std::printf("| %s | %g | %d | %g | %.3g | %s | %s | %s |\n", p.integrator.c_str(), p.dt_s * 1e3, p.max_depth,
                p.th_Pa, c, pct(e).c_str(), uni.c_str(), verdict.c_str());
  }
  std::printf("\nsweep wall time %.1f s\n", sweep_wall);

  if (csv.is_open()) {
    if (const std::string why = csv.write(csv_text(s.scene, points, truth)); !why.empty()) throw OutputError(why);
    std::printf("wrote %s\n", o.csv_path.c_str());
  }
  if (svg.is_open()) {
    if (const std::string why = svg.write(svg_text(s, points, o.metric)); !why.empty()) throw OutputError(why);
    std::printf("wrote %s\n", o.svg_path.c_str());
  }
  SweepEnd end;
  end.signal = s.stopped() ? *s.stop : 0;
  end.any_figures = std::any_of(points.begin(), points.end(), [](const Point& p) {
    const std::string status = p.status();
    return status == "ok" || status == "capped";
  });
  return end;
}

}  // namespace

int run_trade_study(const std::string& program, const std::vector<std::string>& args) {
  const auto fail = [&](int code, const std::string& why) {
    std::fflush(stdout);
    std::fprintf(stderr, "%s: %s\n", program.c_str(), why.c_str());
    return code;
  };
  Options o;
  try {
    o = parse(args);
  } catch (const std::exception& e) {
    const int code = fail(kTradeExitUsage, e.what());
    usage(program, stderr);
    return code;
  }
  if (o.help) {
    usage(program, stdout);
    return kTradeExitOk;
  }
  try {
    // The sweep's files are opened before anything runs: a path that cannot
    // be written fails now, not after an hour of runs.
    OutputFile csv, svg;
    if (!o.csv_path.empty())
      if (const std::string why = csv.open(o.csv_path, "--csv"); !why.empty()) return fail(kTradeExitOutput, why);
    if (!o.svg_path.empty())
      if (const std::string why = svg.open(o.svg_path, "--svg"); !why.empty()) return fail(kTradeExitOutput, why);
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
    if (o.sweep) {
      // Ctrl-C (or SIGTERM) during the sweep, which can take hours, ends it
      // after the step in progress and keeps what it measured.
      const StopOnSignals stop;
      const SweepEnd end = run_sweep(o, csv, svg, stop.flag());
      if (const int signo = end.signal; signo != 0) {
        std::string files;
        for (const std::string* path : {&o.csv_path, &o.svg_path})
          if (!path->empty()) files += (files.empty() ? "; " : ", ") + *path;
        return fail(exit_code_for_signal(signo), "interrupted by " + signal_name(signo) + ": the tables" +
                                                     (files.empty() ? "" : " and files") +
                                                     " hold the runs done (the rest say \"not run\")" + files);
      }
      if (!end.any_figures)
        return fail(kTradeExitNoRun,
                    "every run failed or was refused (the table says why for each); no figure came out of the sweep");
    }
    std::printf("\ntotal wall time %.1f s\n", seconds_between(t0, Clock::now()));
  } catch (const OutputError& e) {
    return fail(kTradeExitOutput, e.what());
  } catch (const std::exception& e) {
    return fail(kTradeExitUsage, e.what());
  }
  return kTradeExitOk;
}

}  // namespace tissue::app
