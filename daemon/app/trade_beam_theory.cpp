#include "app/trade_beam_theory.hpp"

#include <chrono>
#include <cstdio>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "app/trade_format.hpp"
#include "app/trade_run.hpp"
#include "app/trade_scenes.hpp"
#include "physics/boundary.hpp"
#include "physics/forces.hpp"
#include "scene/scene_yaml.hpp"

namespace tissue::app {

namespace sc = tissue::scene;
namespace ph = tissue::physics;
using ph::Vec3;
using Clock = std::chrono::steady_clock;

BeamTheory beam_theory_tip() {
  const double F = 0.05, L = 0.4, b = 0.1, h = 0.1, E = 5.0e4, nu = 0.25;  // nu = 1/4 for eq. (3) springs
  const double I = b * h * h * h / 12.0, A = b * h, G = E / (2.0 * (1.0 + nu));
  const double kappa = 10.0 * (1.0 + nu) / (12.0 + 11.0 * nu);  // rectangular section (Cowper)
  const double eb = F * L * L * L / (3.0 * E * I);
  return {eb, eb + F * L / (kappa * G * A)};
}

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

namespace {

// `s` with the integrator solve_static steps it with.
sc::Scene as_static(sc::Scene s) {
  s.integrator.kind = sc::IntegratorKind::kImplicit;
  s.integrator.dt_s = 0.05;
  s.integrator.cg_max_iterations = 2000;
  s.integrator.cg_tolerance = 1e-10;
  return s;
}

// The beam of the table's row for `law` at uniform `depth` (bending load).
sc::Scene beam_at_depth(sc::StiffnessLaw law, int depth) {
  sc::Scene s = performance_beam({false, depth, 0.0, depth}, sc::IntegratorKind::kImplicit, 0.05, 0.0);
  s.material.stiffness = law;
  return s;
}

}  // namespace

void check_beam_depth(int max_depth) {
  for (int d = 0; d <= max_depth; ++d)
    for (const auto law : {sc::StiffnessLaw::kIsotropic, sc::StiffnessLaw::kPaper}) {
      try {
        sc::validate_scene(as_static(beam_at_depth(law, d)));
      } catch (const sc::SceneError& e) {
        throw std::invalid_argument("--beam-depth " + std::to_string(max_depth) + ": the uniform beam at depth " +
                                    std::to_string(d) + ": " + e.reason() + " (" + e.key_path() + ")");
      }
    }
}

StaticResult solve_static(sc::Scene s, long max_steps, double tol_rel) {
  s = as_static(std::move(s));
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

namespace {

// F L / (E A) [m]: the axial tip displacement of an ideal bar under the beam's load.
constexpr double kAxialTip_m = 0.05 * 0.4 / (5.0e4 * 0.01);

// One law's statics at uniform depths 0..max_depth: bending (0.05 N down)
// and axial (0.05 N along +x) at each.
struct LawResults {
  std::vector<StaticResult> bend, axial;
};

const char* law_name(sc::StiffnessLaw law) { return law == sc::StiffnessLaw::kIsotropic ? "isotropic" : "paper"; }

LawResults solve_law(sc::StiffnessLaw law, int max_depth, long max_steps, double tol_rel) {
  LawResults out;
  for (int d = 0; d <= max_depth; ++d) {
    sc::Scene s = beam_at_depth(law, d);
    out.bend.push_back(solve_static(s, max_steps, tol_rel));
    s.loads[0].total_force_N = {0.05, 0.0, 0.0};
    out.axial.push_back(solve_static(s, max_steps, tol_rel));
    std::fprintf(stderr, "  beam-theory: %s depth %d: %.1f + %.1f s wall\n", law_name(law), d, out.bend.back().wall_s,
                 out.axial.back().wall_s);
  }
  return out;
}

// One table row per depth: the tip against theory and against the finest
// depth of the same law (the discretisation error alone).
void print_law_rows(sc::StiffnessLaw law, const LawResults& results, const BeamTheory& bt) {
  const double finest = -results.bend.back().tip_centre[2];
  for (std::size_t d = 0; d < results.bend.size(); ++d) {
    const StaticResult& r = results.bend[d];
    const StaticResult& a = results.axial[d];
    const double w = -r.tip_centre[2];
    const double ux = a.tip_centre[0];
    std::string failed;
    if (!r.ok) failed += " bending failed: " + shorten(r.error);
    if (!a.ok) failed += " axial failed: " + shorten(a.error);
    std::printf(
        "| %s | %d | %zu | %zu | %.3f | %+.1f %% | %+.1f %% | %+.1f %% | %.3f | %.2f | %.3f | %ld / %ld | %.1e / "
        "%.1e | %.1f |%s\n",
        law_name(law), static_cast<int>(d), r.nodes, r.tets, 1e3 * w, 100.0 * (w / bt.euler_bernoulli_m - 1.0),
        100.0 * (w / bt.timoshenko_m - 1.0), 100.0 * (w / finest - 1.0), -1e3 * r.tip_bottom[2], 1e6 * ux,
        kAxialTip_m / ux, r.steps, a.steps, r.residual_rel, a.residual_rel, r.wall_s + a.wall_s, failed.c_str());
  }
}

}  // namespace

void run_beam_theory(const TradeOptions& o) {
  const int max_depth = o.beam_max_depth >= 0 ? o.beam_max_depth : (o.quick ? 4 : 6);
  const long max_steps = o.quick ? 200 : 600;
  const double tol_rel = 1e-6;
  const BeamTheory bt = beam_theory_tip();
  std::printf("\n## Beam theory: static tip of the 0.4 x 0.1 x 0.1 m beam, E = 5e4 Pa, 0.05 N (linear regime)\n\n");
  std::printf(
      "Bending: 0.05 N down on the free face; Euler-Bernoulli %.3f mm, Timoshenko (nu = 1/4, kappa = "
      "10(1+nu)/(12+11nu)) %.3f mm. Tip = free-face centre {0.4, 0.05, 0.05} (neutral axis). Axial check (separates "
      "lattice anisotropy from bending error): 0.05 N along +x, tip u_x vs F L / (E A) = %.1f um -> effective E_x "
      "(clamped end, so slightly stiff). Statics by implicit Euler dt 0.05 s, CG tol 1e-10, until the free-node "
      "force residual < %.0e of the load (max %ld steps).\n\n",
      1e3 * bt.euler_bernoulli_m, 1e3 * bt.timoshenko_m, 1e6 * kAxialTip_m, tol_rel, max_steps);
  std::printf(
      "| law | depth | nodes | tets | tip u_z (mm) | vs Euler-Bernoulli | vs Timoshenko | vs depth %d, same law | "
      "bottom-edge u_z (mm) | axial u_x (um) | E_x,eff / E | steps bend / axial | residual / load | wall s |\n",
      max_depth);
  std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  for (const auto law : {sc::StiffnessLaw::kIsotropic, sc::StiffnessLaw::kPaper}) {
    print_law_rows(law, solve_law(law, max_depth, max_steps, tol_rel), bt);
    std::fflush(stdout);
  }
}

}  // namespace tissue::app
