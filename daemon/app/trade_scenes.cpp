#include "app/trade_scenes.hpp"

#include <array>
#include <stdexcept>

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
  s.adaptivity.refine_threshold_Pa = m.th_Pa;
  s.adaptivity.min_depth = m.adaptive ? 0 : m.depth;
  s.adaptivity.max_depth = m.adaptive ? m.max_depth : m.depth;
}

const char* integrator_name(sc::IntegratorKind k) {
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

sc::IntegratorKind integrator_kind(const std::string& s) {
  if (s == "explicit") return sc::IntegratorKind::kExplicit;
  if (s == "implicit") return sc::IntegratorKind::kImplicit;
  if (s == "projective") return sc::IntegratorKind::kProjective;
  throw std::invalid_argument("unknown integrator " + s);
}

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

sc::Scene performance_beam(const MeshChoice& m, sc::IntegratorKind kind, double dt_s, double ramp_s, bool r_ladder) {
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

}  // namespace tissue::app
