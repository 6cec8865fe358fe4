// Where the adaptive cantilever's split energy comes from (README, "Energy
// across mesh changes"). Two measurements on config/scenes/cantilever.yaml:
//  1. The shipped run (2 s), its adaptation passes redone one diamond at a
//     time (closure split by hand, ancestors first), each split's change of
//     elastic and kinetic energy summed by diamond depth (0 cube, 1 face,
//     2 axis diagonal), with the part the diamond's mean strain explains
//     (its tets' linearised forms at the volume-mean Green strain).
//  2. The static bend of the depth-0 mesh (0.95 s, load still on): the
//     energy change of splitting all 64 cube diagonals at its own
//     equilibrium, and at the depth-3 mesh's equilibrium read at the same
//     nodes (a smooth field).
// Every split's change is also checked against Σ_children E_c(F) − E_parent(F)
// per removed tet; the largest difference is printed.
//
//   ./build/dev/bench/split_energy [path/to/cantilever.yaml]
#include <Eigen/Core>
#include <Eigen/LU>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <functional>
#include <iterator>
#include <map>
#include <memory>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include "mesh/lattice.hpp"
#include "physics/adaptivity.hpp"
#include "physics/forces.hpp"
#include "physics/simulation.hpp"
#include "scene/scene_yaml.hpp"

using namespace tissue;
using namespace tissue::physics;
using Mat3 = Eigen::Matrix3d;
using LeafTet = mesh::SortedTet;

namespace {

Mat3 rest_frame(const Body& b, const std::array<NodeId, 4>& v) {
  Mat3 r;
  for (int i = 0; i < 3; ++i) r.col(i) = b.rest_m[v[i + 1]] - b.rest_m[v[0]];
  return r;
}

// The tet's spring-share energy [J] linearised in the Green strain G (each
// edge's strain nᵀGn): the small-strain form, against the exact one.
double linear_tet_energy_J(const Body& b, const LeafTet& t, const Mat3& G) {
  const auto shares_m3 = b.tet_edge_shares_m3(t.first, t.second);
  double energy_J = 0.0;
  for (int i = 0; i < 6; ++i) {
    const Vec3 d_m = b.rest_m[t.first[mesh::kTetEdgeSlots[i][1]]] - b.rest_m[t.first[mesh::kTetEdgeSlots[i][0]]];
    const double length_m = d_m.norm(), linear_m = d_m.dot(G * d_m) / length_m;
    energy_J += 0.5 * b.scene().material.youngs_modulus_Pa * shares_m3[i] / (length_m * length_m) * linear_m * linear_m;
  }
  return energy_J;
}

struct SplitChange {
  double elastic_J = 0, kinetic_J = 0, predicted_J = 0, linear_J = 0, mean_strain_J = 0;
};

// Splits one diamond (no closure needed) through the simulation.
SplitChange measured_split(Simulation& sim, mesh::Key d) {
  const Body& b = sim.body();
  const auto before = mesh::sorted_live_tets(b.mesh());
  const double elastic_J = sim.elastic_energy_J(), kinetic_J = sim.kinetic_energy_J();
  if (sim.split_diamond(d) != 1) std::fprintf(stderr, "split of one diamond split more\n");
  SplitChange c{sim.elastic_energy_J() - elastic_J, sim.kinetic_energy_J() - kinetic_J, 0, 0};
  const auto after = mesh::sorted_live_tets(b.mesh());
  std::vector<LeafTet> removed, added;
  std::set_difference(before.begin(), before.end(), after.begin(), after.end(), std::back_inserter(removed));
  std::set_difference(after.begin(), after.end(), before.begin(), before.end(), std::back_inserter(added));
  std::vector<Mat3> F(removed.size());
  Mat3 mean_G = Mat3::Zero();
  for (std::size_t i = 0; i < removed.size(); ++i) {
    Mat3 moved;
    for (int k = 0; k < 3; ++k) moved.col(k) = b.x_m[removed[i].first[k + 1]] - b.x_m[removed[i].first[0]];
    F[i] = moved * rest_frame(b, removed[i].first).inverse();
    mean_G += 0.5 * (F[i].transpose() * F[i] - Mat3::Identity()) / static_cast<double>(removed.size());
  }
  for (std::size_t i = 0; i < removed.size(); ++i) {
    const Mat3 G = 0.5 * (F[i].transpose() * F[i] - Mat3::Identity());
    c.predicted_J -= tet_spring_energy_J(b, removed[i].first, removed[i].second, F[i]);
    c.linear_J -= linear_tet_energy_J(b, removed[i], G);
    c.mean_strain_J -= linear_tet_energy_J(b, removed[i], mean_G);
    const Mat3 to_barycentric = rest_frame(b, removed[i].first).inverse();
    for (const LeafTet& child : added) {
      Vec3 centroid_m = Vec3::Zero();
      for (NodeId n : child.first) centroid_m += 0.25 * b.rest_m[n];
      const Vec3 l = to_barycentric * (centroid_m - b.rest_m[removed[i].first[0]]);
      if (l.minCoeff() <= 0.0 || l.sum() >= 1.0) continue;
      c.predicted_J += tet_spring_energy_J(b, child.first, child.second, F[i]);
      c.linear_J += linear_tet_energy_J(b, child, G);
      c.mean_strain_J += linear_tet_energy_J(b, child, mean_G);
    }
  }
  return c;
}

void split_with_ancestors(Simulation& sim, mesh::Key d,
                          const std::function<void(mesh::Key, const SplitChange&)>& book) {
  const mesh::KuhnMesh& mesh = sim.body().mesh();
  std::array<mesh::Key, 4> parents;
  const int count = mesh::diamond_parents(mesh.domain(), mesh.diamond_info(d), &parents);
  for (int i = 0; i < count; ++i)
    if (!mesh.is_split(parents[i])) split_with_ancestors(sim, parents[i], book);
  if (!mesh.is_split(d)) book(d, measured_split(sim, d));
}

struct Sum {
  int splits = 0, added = 0;
  double elastic_J = 0, kinetic_J = 0, linear_J = 0, mean_strain_J = 0;
};

void shipped_run(const std::string& path) {
  const scene::Scene s = scene::load_scene_file(path);
  Simulation sim(s);
  sim.set_adaptation_paused(true);  // the passes are redone below
  const scene::AdaptivitySpec& spec = s.adaptivity;
  const Adaptivity criterion(spec);
  std::array<Sum, 3> by_depth{};
  double merges_J = 0, worst_identity_J = 0;
  int merges = 0;
  const auto book = [&](mesh::Key d, const SplitChange& c) {
    Sum& sum = by_depth[sim.body().mesh().diamond_info(d).depth % 3];
    ++sum.splits;
    sum.added += c.elastic_J + c.kinetic_J > 0;
    sum.elastic_J += c.elastic_J;
    sum.kinetic_J += c.kinetic_J;
    sum.linear_J += c.linear_J;
    sum.mean_strain_J += c.mean_strain_J;
    worst_identity_J = std::max(worst_identity_J, std::abs(c.elastic_J - c.predicted_J));
  };
  const int steps = static_cast<int>(std::lround(2.0 / s.integrator.dt_s));
  for (int step = 1; step <= steps; ++step) {
    if (!sim.step().ok) {
      std::printf("step %d failed\n", step);
      return;
    }
    if (step % spec.every_steps != 0) continue;
    // Adaptivity::adapt, one diamond at a time.
    const Body& b = sim.body();
    const mesh::KuhnMesh& mesh = b.mesh();
    std::vector<std::pair<double, mesh::Key>> refine;
    // As Adaptivity::adapt: -1 (below every measure) on the slots no tet
    // touches, so a node a split below puts there does not look relaxed.
    constexpr double kUnmeasured = -1.0;
    std::vector<double> node_max(b.x_m.size(), kUnmeasured);
    mesh.for_each_tet([&](TetId t, const mesh::Tet& tet) {
      const double m = criterion.measure(b, t);
      for (NodeId n : tet.v) node_max[n] = std::max(node_max[n], m);
      if (m > criterion.refine_threshold() && tet.depth < spec.max_depth) refine.emplace_back(-m, mesh.diamond_of(t));
    });
    std::sort(refine.begin(), refine.end());
    int budget = spec.max_ops_per_step;
    for (std::size_t i = 0; i < refine.size() && budget > 0; ++i) {
      if (mesh.tet_count() >= static_cast<std::size_t>(spec.max_tets)) break;
      if (!mesh.can_split(refine[i].second)) continue;
      const int before = static_cast<int>(mesh.node_count());
      split_with_ancestors(sim, refine[i].second, book);
      budget -= static_cast<int>(mesh.node_count()) - before;
    }
    std::vector<std::tuple<int, double, mesh::Key>> merge;
    mesh.for_each_node([&](NodeId z, const mesh::Node& node) {
      if (node.edge_a == mesh::kInvalidId || node.depth < spec.min_depth) return;
      if (b.step_index - b.changed_step[z] < spec.min_age_steps) return;
      // Nodes the splits above added lie past node_max's end (read out of
      // bounds when min_age_steps is 0), or on a slot unmeasured before them.
      if (z >= node_max.size() || node_max[z] == kUnmeasured || node_max[z] >= criterion.simplify_threshold()) return;
      const Vec3 mid_m = 0.5 * (b.x_m[node.edge_a] + b.x_m[node.edge_b]);
      if ((b.x_m[z] - mid_m).norm() >= spec.midpoint_tolerance * (b.rest_m[node.edge_b] - b.rest_m[node.edge_a]).norm())
        return;
      merge.emplace_back(-static_cast<int>(node.depth), node_max[z], mesh.node_key(z));
    });
    std::sort(merge.begin(), merge.end());
    for (std::size_t i = 0; i < merge.size() && budget > 0; ++i) {
      if (!mesh.can_merge(std::get<2>(merge[i]))) continue;
      --budget;
      const double before_J = sim.kinetic_energy_J() + sim.elastic_energy_J();
      sim.merge_diamond(std::get<2>(merge[i]));
      merges_J += sim.kinetic_energy_J() + sim.elastic_energy_J() - before_J;
      ++merges;
    }
  }
  std::printf("shipped run, 2 s: %ld splits, %d merges, adaptation energy net %.2f mJ (merges %+.3f mJ)\n",
              static_cast<long>(sim.counters().splits), merges, 1e3 * sim.counters().adaptation_energy_J,
              1e3 * merges_J);
  std::printf("%-22s %6s %6s %12s %12s %12s %14s\n", "splits by diamond", "count", "adding", "elastic mJ", "linearised",
              "kinetic mJ", "mean-strain mJ");
  const char* names[] = {"depth 0 (cube diag.)", "depth 1 (face diag.)", "depth 2 (axis)"};
  for (int d = 0; d < 3; ++d)
    std::printf("%-22s %6d %6d %+12.3f %+12.3f %+12.3f %+14.3f\n", names[d], by_depth[d].splits, by_depth[d].added,
                1e3 * by_depth[d].elastic_J, 1e3 * by_depth[d].linear_J, 1e3 * by_depth[d].kinetic_J,
                1e3 * by_depth[d].mean_strain_J);
  std::printf("largest |split change - per-tet prediction|: %.1e J\n\n", worst_identity_J);
}

void static_bend(const std::string& path) {
  const auto equilibrium = [&](int depth) {
    auto sim = std::make_unique<Simulation>(
        scene::load_scene_file_with_overrides(path, {"adaptivity.min_depth=" + std::to_string(depth)}));
    sim->set_adaptation_paused(true);
    // A refused step keeps the state and time: stop rather than retry it for ever.
    while (sim->time_s() < 0.95)
      if (const StepResult r = sim->step(); !r.ok) {
        std::fprintf(stderr, "split_energy: the static bend at depth %d: step at t = %g s refused: %s\n", depth,
                     sim->time_s(), r.error.c_str());
        std::exit(1);
      }
    return sim;
  };
  const auto fine = equilibrium(3);
  std::map<std::array<long, 3>, Vec3> fine_x_m;  // by rest position in µm
  const auto key = [](const Vec3& r_m) {
    return std::array<long, 3>{std::lround(r_m[0] * 1e6), std::lround(r_m[1] * 1e6), std::lround(r_m[2] * 1e6)};
  };
  fine->body().mesh().for_each_node(
      [&](NodeId n, const mesh::Node&) { fine_x_m[key(fine->body().rest_m[n])] = fine->body().x_m[n]; });
  std::printf("static bend at 0.95 s: elastic energy %.3f mJ at depth 0, %.3f mJ at depth 3\n",
              1e3 * equilibrium(0)->elastic_energy_J(), 1e3 * fine->elastic_energy_J());
  for (const bool smooth : {false, true}) {
    auto sim = equilibrium(0);
    if (smooth) {
      Body& b = sim->mutable_body();
      b.mesh().for_each_node([&](NodeId n, const mesh::Node&) { b.x_m[n] = fine_x_m.at(key(b.rest_m[n])); });
    }
    std::vector<mesh::Key> cubes;
    sim->body().mesh().for_each_tet(
        [&](TetId t, const mesh::Tet&) { cubes.push_back(sim->body().mesh().diamond_of(t)); });
    std::sort(cubes.begin(), cubes.end());
    cubes.erase(std::unique(cubes.begin(), cubes.end()), cubes.end());
    const double before_J = sim->elastic_energy_J();
    int adding = 0;
    double mean_strain_J = 0;
    for (const mesh::Key d : cubes) {
      const SplitChange c = measured_split(*sim, d);
      adding += c.elastic_J > 0;
      mean_strain_J += c.mean_strain_J;
    }
    const double change_J = sim->elastic_energy_J() - before_J;
    std::printf("%-44s %.3f mJ -> %+.3f mJ (%+.1f %%) by %zu cube splits, %d adding; mean-strain part %+.3f mJ\n",
                smooth ? "depth-3 equilibrium read at depth-0 nodes:" : "depth-0 mesh at its own equilibrium:",
                1e3 * before_J, 1e3 * change_J, 100 * change_J / before_J, cubes.size(), adding, 1e3 * mean_strain_J);
  }
}

}  // namespace

int main(int argc, char** argv) {
  const std::string arg = argc > 1 ? argv[1] : "";
  if (argc > 2 || arg == "--help" || arg == "-h") {
    std::fprintf(argc > 2 ? stderr : stdout, "usage: %s [path/to/cantilever.yaml]\n", argv[0]);
    return argc > 2 ? 2 : 0;
  }
  const std::string path = arg.empty() ? "config/scenes/cantilever.yaml" : arg;
  try {
    shipped_run(path);
    static_bend(path);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "split_energy: %s\n", e.what());
    return 2;
  }
  return 0;
}
