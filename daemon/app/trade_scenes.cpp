#include "app/trade_scenes.hpp"

#include <array>
#include <stdexcept>

#include "scene/scene_names.hpp"

namespace tissue::app {

namespace sc = tissue::scene;

namespace {

sc::Region box(sc::Vec3 lo, sc::Vec3 hi) {
  sc::Region r;
  r.kind = sc::Region::Kind::kBox;
  r.min_m = lo;
  r.max_m = hi;
  return r;
}

}  // namespace

void apply_mesh(sc::Scene& s, const MeshChoice& m) {
  s.adaptivity.enabled = m.adaptive;
  s.adaptivity.criterion = sc::RefineCriterion::kStrainEnergy;
  // A uniform mesh keeps the scene's threshold (unused: adaptivity is off),
  // which the scene checks hold to > 0; the uniform choices carry none.
  if (m.adaptive) s.adaptivity.refine_threshold_Pa = m.th_Pa;
  s.adaptivity.min_depth = m.adaptive ? 0 : m.depth;
  s.adaptivity.max_depth = m.adaptive ? m.max_depth : m.depth;
}

const char* integrator_name(sc::IntegratorKind k) { return sc::name_of(sc::kIntegratorNames, k).data(); }

sc::IntegratorKind integrator_kind(const std::string& s) {
  if (const auto k = sc::value_named(sc::kIntegratorNames, s)) return *k;
  throw std::invalid_argument("unknown integrator " + s);
}

namespace {

// What the paper's cantilever and PERFORMANCE.md's beam share: a block
// `length_m` long and 0.1 m high and deep in `cubes`, clamped at x = 0, pulled
// down by `down_N` over its far face (the load "tip"), of the paper's material
// (E 5e4 Pa, 100 kg/m³). The length is given and the cube size derived from
// it, so the loaded face is at x = length_m exactly, where the probes are.
sc::Scene clamped_block(const std::array<int, 3>& cubes, double length_m, double down_N, const MeshChoice& m,
                        sc::IntegratorKind kind, double dt_s) {
  sc::Scene s;
  s.object.cubes = cubes;
  s.object.cube_size_m = length_m / cubes[0];
  s.material.youngs_modulus_Pa = 5.0e4;
  s.material.density_kg_per_m3 = 100.0;
  s.fixed.push_back({box({0.0, 0.0, 0.0}, {0.0, 0.1, 0.1})});
  sc::LoadSpec load;
  load.name = "tip";
  load.region = box({length_m, 0.0, 0.0}, {length_m, 0.1, 0.1});
  load.total_force_N = {0.0, 0.0, -down_N};
  s.loads.push_back(load);
  apply_mesh(s, m);
  s.integrator.kind = kind;
  s.integrator.dt_s = dt_s;
  return s;
}

}  // namespace

sc::Scene paper_cantilever(const MeshChoice& m, sc::IntegratorKind kind, double dt_s, double release_s) {
  sc::Scene s = clamped_block({4, 4, 4}, 0.1, 5.0, m, kind, dt_s);
  s.name = "paper cantilever";
  s.material.rayleigh_beta_s = 0.003;
  s.loads[0].profile.release_s = release_s;
  s.probes = {{"tip_bottom", {0.1, 0.05, 0.0}}, {"tip_centre", {0.1, 0.05, 0.05}}};
  return s;
}

sc::Scene performance_beam(const MeshChoice& m, sc::IntegratorKind kind, double dt_s, double ramp_s, bool r_ladder) {
  sc::Scene s = r_ladder ? clamped_block({12, 3, 3}, 0.4, 0.05, m, kind, dt_s)
                         : clamped_block({8, 2, 2}, 0.4, 0.05, m, kind, dt_s);
  s.name = r_ladder ? "beam-r" : "beam";
  s.loads[0].profile.ramp_s = ramp_s;
  s.probes = {{"tip_centre", {0.4, 0.05, 0.05}}, {"tip_bottom", {0.4, 0.05, 0.0}}};
  return s;
}

}  // namespace tissue::app
