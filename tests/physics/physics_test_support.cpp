#include "physics/physics_test_support.hpp"

#include <Eigen/Dense>
#include <cmath>
#include <random>
#include <string>
#include <vector>

namespace tissue::physics::testing {

double dense_rest_frequency2_per_s2(const Body& body) {
  const int n = static_cast<int>(body.x_m.size());
  Eigen::MatrixXd k = Eigen::MatrixXd::Zero(3 * n, 3 * n);
  body.mesh().for_each_edge([&](EdgeId e, const mesh::Edge& edge) {
    const Vec3 d = (body.rest_m[edge.b] - body.rest_m[edge.a]).normalized();
    const Eigen::Matrix3d block = body.stiffness_N_per_m[e] * d * d.transpose();
    k.block<3, 3>(3 * edge.a, 3 * edge.a) += block;
    k.block<3, 3>(3 * edge.b, 3 * edge.b) += block;
    k.block<3, 3>(3 * edge.a, 3 * edge.b) -= block;
    k.block<3, 3>(3 * edge.b, 3 * edge.a) -= block;
  });
  Eigen::VectorXd sqrt_w(3 * n);  // zero on kinematic nodes: their rows and columns drop out
  for (int i = 0; i < n; ++i) sqrt_w.segment<3>(3 * i).setConstant(std::sqrt(body.inv_mass_per_kg[i]));
  const Eigen::MatrixXd s = sqrt_w.asDiagonal() * k * sqrt_w.asDiagonal();
  return Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(s, Eigen::EigenvaluesOnly).eigenvalues().maxCoeff();
}

void jiggle_free_nodes(Body& body, std::uint32_t seed, double amplitude_m, double speed_m_per_s) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  body.mesh().for_each_node([&](NodeId n, const mesh::Node&) {
    if (body.inv_mass_per_kg[n] == 0.0) return;
    body.x_m[n] += amplitude_m * Vec3(u(rng), u(rng), u(rng));
    body.v_m_per_s[n] = speed_m_per_s * Vec3(u(rng), u(rng), u(rng));
  });
}

Body jiggled_beam(std::uint32_t seed, bool damped) {
  scene::Scene s = beam_scene();
  s.adaptivity.min_depth = 1;
  if (!damped) s.material.rayleigh_beta_s = 0.0;  // no spring has a damper
  Body body(s);
  jiggle_free_nodes(body, seed, 0.01, 0.1);
  bool collapsed = false;
  body.mesh().for_each_edge([&](EdgeId, const mesh::Edge& edge) {
    if (collapsed || body.inv_mass_per_kg[edge.b] == 0.0) return;
    body.x_m[edge.b] = body.x_m[edge.a];
    collapsed = true;
  });
  return body;
}

Body randomly_refined_beam(std::uint32_t seed, int max_depth) {
  scene::Scene s = beam_scene();
  s.adaptivity.enabled = true;
  s.adaptivity.max_depth = max_depth;
  Body body(s);
  std::mt19937 rng(seed);
  for (int round = 0; round < 40; ++round) {
    std::vector<mesh::Key> candidates;
    body.mesh().for_each_tet([&](TetId t, const mesh::Tet& tet) {
      if (tet.depth < max_depth && body.mesh().can_split(body.mesh().diamond_of(t)))
        candidates.push_back(body.mesh().diamond_of(t));
    });
    if (candidates.empty()) break;
    body.split(candidates[std::uniform_int_distribution<std::size_t>(0, candidates.size() - 1)(rng)]);
  }
  return body;
}

scene::Scene beam_scene(double tip_force_N) {
  scene::Scene s;
  s.name = "beam";
  s.object.cubes = {8, 2, 2};
  s.object.cube_size_m = 0.05;
  s.material.rayleigh_beta_s = 0.01;
  s.fixed.push_back({box({0, 0, 0}, {0, 0.1, 0.1})});
  s.loads.push_back({"tip", box({0.4, 0, 0}, {0.4, 0.1, 0.1}), {0, 0, -tip_force_N}, {}});
  s.probes.push_back({"tip", {0.4, 0.05, 0.05}});
  return s;
}

scene::Scene cantilever_scene(double release_s) {
  scene::Scene s;
  s.name = "cantilever";
  s.object.cubes = {4, 4, 4};
  s.object.cube_size_m = 0.025;
  s.material.rayleigh_beta_s = 0.003;
  s.fixed.push_back({box({0, 0, 0}, {0, 0.1, 0.1})});
  scene::LoadSpec load{"tip", box({0.1, 0, 0}, {0.1, 0.1, 0.1}), {0, 0, -5.0}, {}};
  load.profile.release_s = release_s;
  s.loads.push_back(load);
  s.adaptivity.enabled = true;
  s.adaptivity.refine_threshold_Pa = 20.0;
  s.adaptivity.max_depth = 3;
  s.probes.push_back({"tip", {0.1, 0.05, 0.0}});
  return s;
}

scene::Scene free_cube_scene(int cubes, int depth) {
  scene::Scene s;
  s.name = "free cube";
  s.object.cubes = {cubes, cubes, cubes};
  s.object.cube_size_m = 0.05;
  s.adaptivity.min_depth = depth;
  return s;
}

std::vector<Vec3> random_free_vector(const Body& state, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::vector<Vec3> p(state.x_m.size());
  for (auto& v : p) v = Vec3(u(rng), u(rng), u(rng));
  for (std::size_t n = 0; n < p.size(); ++n)
    if (state.inv_mass_per_kg[n] == 0.0) p[n].setZero();
  return p;
}

double total_energy_J(const Simulation& sim) { return sim.kinetic_energy_J() + sim.elastic_energy_J(); }

bool run_until(Simulation& sim, double t_end_s, std::string* error) {
  while (sim.time_s() < t_end_s - 1e-12) {
    const StepResult r = sim.step();
    if (!r.ok) {
      if (error) *error = r.error;
      return false;
    }
  }
  return true;
}

}  // namespace tissue::physics::testing
