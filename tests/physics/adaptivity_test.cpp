#include "physics/adaptivity.hpp"

#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <optional>
#include <random>
#include <set>
#include <utility>
#include <vector>

#include "mesh/refine_ops.hpp"
#include "physics/forces.hpp"
#include "physics/physics_test_support.hpp"

namespace tissue::physics {
namespace {

using testing::cantilever_scene;
using testing::run_until;

int max_depth_where(const Body& body, bool (*pred)(const Vec3&)) {
  int deepest = 0;
  body.mesh().for_each_tet([&](TetId, const mesh::Tet& t) {
    Vec3 c = Vec3::Zero();
    for (NodeId n : t.v) c += 0.25 * body.rest_m[n];
    if (pred(c)) deepest = std::max(deepest, static_cast<int>(t.depth));
  });
  return deepest;
}

// The paper's §4.1 experiment: refinement where the bending strain is high
// (at the root), simplification back after the force is released.
TEST(Adaptivity, CantileverRefinesAtTheRootAndSimplifiesAfterRelease) {
  Simulation sim(cantilever_scene(/*release_s=*/0.5));
  ASSERT_TRUE(run_until(sim, 0.5));
  const std::size_t loaded_tets = sim.body().mesh().tet_count();
  EXPECT_GT(loaded_tets, 384u);
  EXPECT_GT(sim.counters().splits, 0);
  EXPECT_EQ(max_depth_where(sim.body(), [](const Vec3& c) { return c.x() < 0.025; }), 3);
  ASSERT_TRUE(run_until(sim, 2.0));
  EXPECT_GT(sim.counters().merges, 0);
  EXPECT_LT(sim.body().mesh().tet_count(), loaded_tets / 2) << "the relaxed mesh simplifies back";
}

TEST(Adaptivity, NoDeformationMeansNoRefinement) {
  scene::Scene s = cantilever_scene();
  s.loads.clear();
  Simulation sim(s);
  ASSERT_TRUE(run_until(sim, 0.2));
  EXPECT_EQ(sim.counters().splits, 0);
  EXPECT_EQ(sim.body().mesh().tet_count(), 384u);
}

TEST(Adaptivity, DisabledAdaptivityBuildsNoState) {
  scene::Scene s = cantilever_scene();
  s.adaptivity.enabled = false;
  Simulation sim(s);
  EXPECT_FALSE(sim.adaptive());
  ASSERT_TRUE(run_until(sim, 0.2));
  EXPECT_EQ(sim.body().mesh().tet_count(), 384u);
  EXPECT_TRUE(Simulation(cantilever_scene()).adaptive());
}

// One pass does at most the budget: a split whose closure does not fit what
// is left waits (at depth 3 no closure alone exceeds 10).
TEST(Adaptivity, OnePassRespectsTheOperationBudget) {
  scene::Scene s = cantilever_scene();
  s.adaptivity.refine_threshold_Pa = 1e-6;  // everything strained wants refining
  s.adaptivity.every_steps = 1;
  s.adaptivity.max_ops_per_step = 10;
  Simulation sim(s);
  const StepResult r = sim.step();
  ASSERT_TRUE(r.ok);
  EXPECT_GE(r.adapted.splits, 10);
  EXPECT_LE(r.adapted.splits, 10);
}

TEST(Adaptivity, AdaptationNeverAddsKineticEnergy) {
  scene::Scene s = cantilever_scene();
  s.adaptivity.enabled = false;  // deform first, then adapt by hand
  s.adaptivity.max_depth = 3;
  Simulation sim(s);
  ASSERT_TRUE(run_until(sim, 0.05));
  scene::Scene adaptive = cantilever_scene();
  Body body(adaptive);
  // Copy the deformed state onto an adaptive body with the same coarse mesh.
  body.x_m = sim.body().x_m;
  body.v_m_per_s = sim.body().v_m_per_s;
  const double ke0 = kinetic_energy_J(body), elastic0_J = elastic_energy_J(body);
  ASSERT_GT(ke0, 0.0);
  Adaptivity adaptivity(adaptive.adaptivity);
  const AdaptStats stats = adaptivity.adapt(body);
  EXPECT_GT(stats.splits, 0);
  EXPECT_LE(kinetic_energy_J(body), ke0 * (1 + 1e-12));
  // The energy booking takes the elastic energy before the pass from the
  // pass itself: it must be the very sum elastic_energy_J makes.
  EXPECT_EQ(stats.elastic_energy_before_J, elastic0_J);
}

// The pass's fast per-edge evaluation equals the per-tet definition (eq. (1)
// with the square, and the stretch measure).
TEST(Adaptivity, RefinesExactlyTheTetsAboveThreshold) {
  for (auto criterion : {scene::RefineCriterion::kStrainEnergy, scene::RefineCriterion::kStretch}) {
    scene::Scene s = cantilever_scene();
    s.adaptivity.criterion = criterion;
    s.adaptivity.stretch_ratio = 1.02;
    s.adaptivity.enabled = false;
    Simulation sim(s);
    ASSERT_TRUE(run_until(sim, 0.05));
    scene::Scene adaptive = s;
    adaptive.adaptivity.enabled = true;
    adaptive.adaptivity.max_ops_per_step = 1000000;
    Body body(adaptive);
    body.x_m = sim.body().x_m;
    Adaptivity adaptivity(adaptive.adaptivity);
    std::set<mesh::Key> wanted;
    body.mesh().for_each_tet([&](TetId t, const mesh::Tet&) {
      const double m =
          criterion == scene::RefineCriterion::kStretch ? max_edge_stretch(body, t) : strain_energy_density_Pa(body, t);
      EXPECT_NEAR(adaptivity.measure(body, t), m, 1e-12 * std::max(1.0, m));
      if (m > adaptivity.refine_threshold()) wanted.insert(body.mesh().diamond_of(t));
    });
    ASSERT_FALSE(wanted.empty());
    adaptivity.adapt(body);
    for (mesh::Key d : wanted) EXPECT_TRUE(body.mesh().is_split(d));
  }
}

TEST(Adaptivity, StretchCriterionRefinesUnderLoad) {
  scene::Scene s = cantilever_scene();
  s.adaptivity.criterion = scene::RefineCriterion::kStretch;
  s.adaptivity.stretch_ratio = 1.02;
  Simulation sim(s);
  ASSERT_TRUE(run_until(sim, 0.3));
  EXPECT_GT(sim.counters().splits, 0);
}

// A free 2x2x2-cube body with adaptivity on, for passes run by hand.
scene::Scene relaxed_cube_scene() {
  scene::Scene s = testing::free_cube_scene(2, 0);
  s.adaptivity.enabled = true;
  s.adaptivity.max_depth = 3;
  return s;
}

// Splits the cube diagonal of a coarse tet (no closure: a coarse diamond
// has no parents) and returns its key.
mesh::Key split_a_cube_diagonal(Body& body) {
  const mesh::Key d = body.mesh().diamond_of(0);
  EXPECT_EQ(body.mesh().tet(0).depth, 0);
  EXPECT_EQ(body.split(d), 1);
  return d;
}

// Every node at (1 + eps) times its rest position: every edge's strain is eps.
void dilate(Body& body, double eps) {
  body.mesh().for_each_node([&](NodeId n, const mesh::Node&) { body.x_m[n] = (1.0 + eps) * body.rest_m[n]; });
}

// Under a uniform dilation or compression by ε every edge has strain ε, so
// every tet's strain-energy density is (E/2) Σ ε² = 3 E ε² (eq. (1), squared:
// compression counts as stretch does) and its stretch max(l/L, L/l) − 1 is
// ε, or 1/(1 + ε) − 1 ≈ |ε| for a compression. A threshold 5 % above
// refines nothing, 5 % below refines.
TEST(Adaptivity, UniformStrainRefinesExactlyWhenItsDensityPassesTheThreshold) {
  for (auto criterion : {scene::RefineCriterion::kStrainEnergy, scene::RefineCriterion::kStretch}) {
    for (double eps : {1e-3, -1e-3}) {
      for (double side : {1.05, 0.95}) {
        SCOPED_TRACE(::testing::Message()
                     << "criterion " << static_cast<int>(criterion) << " eps " << eps << " side " << side);
        scene::Scene s = relaxed_cube_scene();
        s.adaptivity.criterion = criterion;
        const double density_Pa = 3.0 * s.material.youngs_modulus_Pa * eps * eps;
        s.adaptivity.refine_threshold_Pa = side * density_Pa;
        s.adaptivity.stretch_ratio = 1.0 + side * std::abs(eps);
        Body body(s);
        dilate(body, eps);
        Adaptivity adaptivity(s.adaptivity);
        const AdaptStats stats = adaptivity.adapt(body);
        if (side > 1.0) {
          EXPECT_EQ(stats.splits, 0);
        } else {
          EXPECT_GT(stats.splits, 0);
        }
      }
    }
  }
}

// Hysteresis, age: a diamond split at step k may merge from step
// k + min_age_steps on, not before (the body is at rest: every other
// condition holds).
TEST(Adaptivity, ADiamondMergesOnlyOnceMinAgeStepsHavePassed) {
  scene::Scene s = relaxed_cube_scene();
  s.adaptivity.min_age_steps = 20;
  Body body(s);
  body.step_index = 7;
  const mesh::Key d = split_a_cube_diagonal(body);
  Adaptivity adaptivity(s.adaptivity);
  body.step_index = 7 + 19;
  EXPECT_EQ(adaptivity.adapt(body).merges, 0);
  EXPECT_TRUE(body.mesh().is_split(d));
  body.step_index = 7 + 20;
  EXPECT_EQ(adaptivity.adapt(body).merges, 1);
  EXPECT_FALSE(body.mesh().is_split(d));
}

// min_age_steps 0: a diamond split by a pass is not merged by the same pass.
// The split merged first frees a node slot; the pass's first split reuses it.
// (Its per-node measure, taken before the splits, was the free slot's 0, so
// the new node looked relaxed and was merged at once, every pass, while its
// tets stayed above Th.)
TEST(Adaptivity, APassNeverMergesADiamondItSplitEvenAtMinAgeZero) {
  scene::Scene s = relaxed_cube_scene();
  s.adaptivity.min_age_steps = 0;
  const double eps = 1e-3;
  s.adaptivity.refine_threshold_Pa = 0.5 * 3.0 * s.material.youngs_modulus_Pa * eps * eps;
  Body body(s);
  const mesh::Key freed = split_a_cube_diagonal(body);
  body.merge(freed);
  ASSERT_EQ(body.mesh().node_count() + 1, body.mesh().node_capacity()) << "the merge must leave a free node slot";
  std::set<mesh::Key> cube_diagonals;
  body.mesh().for_each_tet([&](TetId t, const mesh::Tet&) { cube_diagonals.insert(body.mesh().diamond_of(t)); });
  ASSERT_EQ(cube_diagonals.size(), 8u);
  body.step_index = 1000;
  dilate(body, eps);  // every tet at 3 E eps^2 = 2 Th
  Adaptivity adaptivity(s.adaptivity);
  const AdaptStats stats = adaptivity.adapt(body);
  EXPECT_EQ(stats.splits, 8);
  EXPECT_EQ(stats.merges, 0);
  for (const mesh::Key d : cube_diagonals) EXPECT_TRUE(body.mesh().is_split(d));
}

// Hysteresis, midpoint: a node further than midpoint_tolerance · L from its
// edge's midpoint stays (merging it would visibly move the surface).
TEST(Adaptivity, ADiamondMergesOnlyWhenItsNodeIsNearItsEdgesMidpoint) {
  scene::Scene s = relaxed_cube_scene();
  s.adaptivity.refine_threshold_Pa = 1e9;  // the offset must not refine
  s.adaptivity.midpoint_tolerance = 1e-3;
  for (double offset : {2e-3, 0.5e-3}) {
    Body body(s);
    const mesh::Key d = split_a_cube_diagonal(body);
    body.step_index = 1000;
    const NodeId z = body.mesh().find_node(d);
    const mesh::Node& node = body.mesh().node(z);
    const Vec3 along = body.rest_m[node.edge_b] - body.rest_m[node.edge_a];
    const Vec3 across = along.unitOrthogonal();
    body.x_m[z] += offset * along.norm() * across;
    Adaptivity adaptivity(s.adaptivity);
    const AdaptStats stats = adaptivity.adapt(body);
    EXPECT_EQ(stats.splits, 0);
    EXPECT_EQ(stats.merges, offset < 1e-3 ? 1 : 0) << "offset " << offset << " L";
  }
}

// Hysteresis, threshold: merge only below Th · simplify_factor. A uniform
// dilation (midpoints stay midpoints) with density between Th/4 and Th
// neither refines nor merges; below Th/4 it merges.
TEST(Adaptivity, ADiamondMergesOnlyBelowTheThresholdTimesTheSimplifyFactor) {
  scene::Scene s = relaxed_cube_scene();
  s.adaptivity.refine_threshold_Pa = 4.0;
  s.adaptivity.simplify_factor = 0.25;
  for (double fraction : {0.5, 0.2}) {  // of Th
    Body body(s);
    const mesh::Key d = split_a_cube_diagonal(body);
    body.step_index = 1000;
    // 3 E ε² = fraction · Th.
    dilate(body, std::sqrt(fraction * s.adaptivity.refine_threshold_Pa / (3.0 * s.material.youngs_modulus_Pa)));
    Adaptivity adaptivity(s.adaptivity);
    const AdaptStats stats = adaptivity.adapt(body);
    EXPECT_EQ(stats.splits, 0);
    EXPECT_EQ(stats.merges, fraction < 0.25 ? 1 : 0) << fraction << " Th";
    EXPECT_EQ(body.mesh().is_split(d), fraction >= 0.25);
  }
}

// The mesh starts refined to min_depth and never simplifies below it: at
// rest, old enough, nothing of the starting mesh merges; a diamond split
// beyond it does.
TEST(Adaptivity, NothingMergesBelowMinDepth) {
  scene::Scene s = relaxed_cube_scene();
  s.adaptivity.min_depth = 1;
  Body body(s);
  const std::size_t start_tets = body.mesh().tet_count();
  ASSERT_EQ(start_tets, 8u * 6u * 2u);
  std::optional<mesh::Key> d;
  body.mesh().for_each_tet([&](TetId t, const mesh::Tet&) {
    if (!d) d = body.mesh().diamond_of(t);  // a face diamond: its parents are split
  });
  ASSERT_TRUE(d.has_value());
  ASSERT_TRUE(body.mesh().can_split(*d));
  ASSERT_GT(body.split(*d), 0);
  body.step_index = 1000;
  Adaptivity adaptivity(s.adaptivity);
  const AdaptStats stats = adaptivity.adapt(body);
  EXPECT_GT(stats.merges, 0);
  EXPECT_EQ(body.mesh().tet_count(), start_tets);
  EXPECT_EQ(adaptivity.adapt(body).merges, 0);
  EXPECT_EQ(body.mesh().tet_count(), start_tets);
}

// Merges count against the pass's budget as splits do.
TEST(Adaptivity, MergesPerPassStayWithinTheBudget) {
  scene::Scene s = relaxed_cube_scene();
  s.adaptivity.max_ops_per_step = 3;
  Body body(s);
  std::set<mesh::Key> cube_diagonals;
  body.mesh().for_each_tet([&](TetId t, const mesh::Tet&) { cube_diagonals.insert(body.mesh().diamond_of(t)); });
  ASSERT_EQ(cube_diagonals.size(), 8u);
  for (const mesh::Key d : cube_diagonals) ASSERT_EQ(body.split(d), 1);
  body.step_index = 1000;
  Adaptivity adaptivity(s.adaptivity);
  EXPECT_EQ(adaptivity.adapt(body).merges, 3);
  EXPECT_EQ(adaptivity.adapt(body).merges, 3);
  EXPECT_EQ(adaptivity.adapt(body).merges, 2);
  EXPECT_EQ(body.mesh().tet_count(), 48u);
}

// Finest diamonds first: a relaxed two-level refinement merges its children
// and then, in the same pass, the parents they were blocking.
TEST(Adaptivity, ARelaxedNestedRefinementMergesBackInOnePass) {
  scene::Scene s = relaxed_cube_scene();
  Body body(s);
  split_a_cube_diagonal(body);
  std::optional<mesh::Key> child;
  body.mesh().for_each_tet([&](TetId t, const mesh::Tet& tet) {
    if (!child && tet.depth == 1) child = body.mesh().diamond_of(t);
  });
  ASSERT_TRUE(child.has_value());
  ASSERT_GT(body.split(*child), 0);
  ASSERT_GT(body.mesh().tet_count(), 48u);
  body.step_index = 1000;
  Adaptivity adaptivity(s.adaptivity);
  const AdaptStats stats = adaptivity.adapt(body);
  EXPECT_GE(stats.merges, 2);
  EXPECT_EQ(body.mesh().tet_count(), 48u);
}

// adaptivity.max_tets: no split once the mesh holds that many leaf tets.
TEST(Adaptivity, NoSplitOnceTheMeshHoldsMaxTets) {
  scene::Scene s = relaxed_cube_scene();
  s.adaptivity.refine_threshold_Pa = 1e-9;  // everything strained wants refining
  for (int extra : {0, 1}) {
    s.adaptivity.max_tets = 48 + extra;
    Body body(s);
    dilate(body, 1e-3);
    Adaptivity adaptivity(s.adaptivity);
    const AdaptStats stats = adaptivity.adapt(body);
    EXPECT_TRUE(stats.ceiling_reached);
    EXPECT_EQ(stats.splits, extra) << "max_tets " << s.adaptivity.max_tets;
  }
}

// The budget counts a split's closure: once one split and the parents it
// needed use up max_ops_per_step, the pass splits nothing more. Here every
// wanted diamond (a coarse cube edge around the one split face diamond)
// needs at least two unsplit face diamonds first, so its closure exceeds a
// budget of 2: the pass's first split takes it whole (a pass always
// progresses), and no other fits.
TEST(Adaptivity, ASplitsClosureCountsAgainstTheBudget) {
  scene::Scene s = relaxed_cube_scene();
  s.adaptivity.max_depth = 6;
  s.adaptivity.refine_threshold_Pa = 1e-6;
  s.adaptivity.max_ops_per_step = 2;
  Body body(s);
  std::set<mesh::Key> cube_diagonals;
  body.mesh().for_each_tet([&](TetId t, const mesh::Tet&) { cube_diagonals.insert(body.mesh().diamond_of(t)); });
  for (const mesh::Key d : cube_diagonals) ASSERT_EQ(body.split(d), 1);
  // The face diamond between the cubes at x = 0 and x = h, y = z = 0.
  const std::int64_t h = body.mesh().domain().coarse_cube();
  const mesh::Key face = mesh::vertex_key({h, h / 2, h / 2});
  ASSERT_EQ(body.split(face), 1);
  const NodeId z = body.mesh().find_node(face);
  body.x_m[z] += Vec3(0.0, 0.0, 1e-3);  // strains exactly the tets around z
  std::set<mesh::Key> wanted;
  body.mesh().for_each_tet([&](TetId t, const mesh::Tet& tet) {
    if (std::find(tet.v.begin(), tet.v.end(), z) != tet.v.end()) wanted.insert(body.mesh().diamond_of(t));
  });
  ASSERT_EQ(wanted.size(), 4u);  // the face's four edges
  Adaptivity adaptivity(s.adaptivity);
  const AdaptStats stats = adaptivity.adapt(body);
  EXPECT_GE(stats.splits, 3);
  int wanted_split = 0;
  for (const mesh::Key d : wanted) wanted_split += body.mesh().is_split(d);
  EXPECT_EQ(wanted_split, 1);
}

// While a tool presses, the mesh under it stays: a relaxed, old, mergeable
// diamond whose node is in the frozen sphere is not merged; unfrozen, it is.
TEST(Adaptivity, AFrozenNodeIsNotMerged) {
  scene::Scene s = relaxed_cube_scene();
  Body body(s);
  const mesh::Key d = split_a_cube_diagonal(body);
  body.step_index = 1000;
  const Vec3 node_m = body.x_m[body.mesh().find_node(d)];
  Adaptivity adaptivity(s.adaptivity);
  adaptivity.freeze_sphere(node_m + Vec3(0.005, 0.0, 0.0), 0.01);
  EXPECT_EQ(adaptivity.adapt(body).merges, 0);
  EXPECT_TRUE(body.mesh().is_split(d));
  adaptivity.unfreeze();
  EXPECT_EQ(adaptivity.adapt(body).merges, 1);
  EXPECT_FALSE(body.mesh().is_split(d));
}

// A merge changes every tet around its node, so a node outside the sphere
// whose tets reach into it stays too: here the sphere holds one end of the
// split cube diagonal (a cube corner) and not the node at its midpoint.
TEST(Adaptivity, AMergeWhoseTetsReachTheFrozenSphereIsSkipped) {
  scene::Scene s = relaxed_cube_scene();
  Body body(s);
  const mesh::Key d = split_a_cube_diagonal(body);
  body.step_index = 1000;
  const mesh::KuhnMesh& m = body.mesh();
  const NodeId z = m.find_node(d);
  const NodeId corner = m.node(z).edge_a;
  const double radius_m = 0.1 * (body.x_m[z] - body.x_m[corner]).norm();
  Adaptivity adaptivity(s.adaptivity);
  adaptivity.freeze_sphere(body.x_m[corner], radius_m);
  int tets_reaching_in = 0;  // the tets the merge would replace, with the corner as a vertex
  m.for_each_tet([&](TetId, const mesh::Tet& tet) {
    const bool has_z = std::find(tet.v.begin(), tet.v.end(), z) != tet.v.end();
    const bool has_corner = std::find(tet.v.begin(), tet.v.end(), corner) != tet.v.end();
    tets_reaching_in += has_z && has_corner;
  });
  ASSERT_GT(tets_reaching_in, 0);
  EXPECT_EQ(adaptivity.adapt(body).merges, 0) << "the merge replaced tets with a vertex in the frozen sphere";
  EXPECT_TRUE(m.is_split(d));
  adaptivity.unfreeze();
  EXPECT_EQ(adaptivity.adapt(body).merges, 1);
  EXPECT_FALSE(m.is_split(d));
}

// The freeze covers what a split's closure changes, not only the wanted
// tet: the face diamond between the cubes at x = 0 and x = H is strained
// (its node-side tets lie around the displaced centre of cube 0, far from
// the sphere), but splitting it first splits the diagonal of cube 1, whose
// tets all reach the corner at x = 2H inside the sphere. That split is
// skipped; the faces whose closure stays clear of the sphere still split.
TEST(Adaptivity, ASplitWhoseClosureReachesTheFrozenSphereIsSkipped) {
  scene::Scene s = relaxed_cube_scene();
  s.adaptivity.refine_threshold_Pa = 1e-6;
  Body body(s);
  const mesh::KuhnMesh& m = body.mesh();
  const std::int64_t H = m.domain().coarse_cube();
  const mesh::Key cube0 = mesh::vertex_key({H / 2, H / 2, H / 2});
  const mesh::Key cube1 = mesh::vertex_key({3 * H / 2, H / 2, H / 2});
  const mesh::Key shared_face = mesh::vertex_key({H, H / 2, H / 2});
  const mesh::Key boundary_face = mesh::vertex_key({0, H / 2, H / 2});
  ASSERT_EQ(body.split(cube0), 1);
  body.x_m[m.find_node(cube0)] += Vec3(1e-3, 2e-3, 3e-3);
  // Cube 1's diagonal ends on x = H and x = 2H; the sphere is around the
  // second end, 0.1 cube wide.
  const mesh::Edge& diagonal1 = m.edge(m.find_edge(cube1));
  const NodeId far_end = body.rest_m[diagonal1.a].x() > body.rest_m[diagonal1.b].x() ? diagonal1.a : diagonal1.b;
  const double cube_m = s.object.cube_size_m;
  ASSERT_NEAR(body.rest_m[far_end].x(), 2 * cube_m, 1e-12);
  Adaptivity adaptivity(s.adaptivity);
  adaptivity.freeze_sphere(body.x_m[far_end], 0.1 * cube_m);
  std::vector<mesh::Key> wanted;  // the strained tets' diamonds: none has a vertex in the sphere
  m.for_each_tet([&](TetId t, const mesh::Tet& tet) {
    if (adaptivity.measure(body, t) <= adaptivity.refine_threshold()) return;
    for (const NodeId n : tet.v) ASSERT_GT((body.x_m[n] - body.x_m[far_end]).norm(), 0.1 * cube_m);
    wanted.push_back(m.diamond_of(t));
  });
  ASSERT_NE(std::find(wanted.begin(), wanted.end(), shared_face), wanted.end());
  ASSERT_NE(std::find(wanted.begin(), wanted.end(), boundary_face), wanted.end());
  EXPECT_GT(adaptivity.adapt(body).splits, 0);
  EXPECT_TRUE(m.is_split(boundary_face));
  EXPECT_FALSE(m.is_split(shared_face));
  EXPECT_FALSE(m.is_split(cube1)) << "the closure split a tet with a vertex in the frozen sphere";
}

// A tool contact must not make every merge candidate pay for the sphere.
// Finding whether a merge reaches into it walks a node's edges (26 (K + 1)
// hash lookups); the pass walked those of every old relaxed node it looked
// at, before its cheap tests, so one contact made every pass ~19x slower on
// a 196,608-tet mesh at rest. It walks the edges of the nodes in the sphere
// instead, once: a cost bounded by what is under the tool.
TEST(Adaptivity, AFrozenSphereCostsAPassWorkForTheNodesInsideItNotForEveryMergeCandidate) {
  scene::Scene s = relaxed_cube_scene();
  Body body(s);
  for (int depth = 0; depth < s.adaptivity.max_depth; ++depth) {
    std::vector<mesh::Key> keys;
    body.mesh().for_each_tet([&](TetId t, const mesh::Tet& tet) {
      if (tet.depth == depth) keys.push_back(body.mesh().diamond_of(t));
    });
    for (const mesh::Key k : keys)
      if (body.mesh().can_split(k)) body.split(k);
  }
  body.step_index = 1000;  // every split node is old, relaxed and mergeable
  int split_nodes = 0;
  body.mesh().for_each_node([&](NodeId, const mesh::Node& n) { split_nodes += n.edge_a != mesh::kInvalidId; });
  // A small contact on the top face, at the centre of a coarse face's edge.
  const double cube_m = s.object.cube_size_m;
  const Vec3 centre_m(cube_m, 0.5 * cube_m, 2.0 * cube_m);
  const double radius_m = 0.3 * cube_m;
  int inside = 0;
  body.mesh().for_each_node(
      [&](NodeId n, const mesh::Node&) { inside += (body.x_m[n] - centre_m).norm() <= radius_m; });
  ASSERT_GT(inside, 0);
  ASSERT_GT(split_nodes, 10 * inside);
  Adaptivity adaptivity(s.adaptivity);
  adaptivity.freeze_sphere(centre_m, radius_m);
  const AdaptStats stats = adaptivity.adapt(body);
  EXPECT_EQ(stats.merges, s.adaptivity.max_ops_per_step);
  EXPECT_LE(stats.frozen_edge_walks, inside) << "of " << split_nodes << " merge candidates";
}

// Hysteresis across a merge: a merge restores the parent tets, whose density
// can be up to ~2x their children's, so with simplify_factor above ~0.5 a
// static body merged a diamond whose parents exceeded Th, re-split it on the
// next pass and merged it again min_age_steps later, forever, booking
// adaptation energy each time. Here one cube's diagonal ends are moved
// oppositely across it (its midpoint stays): the parents' density is ~2x the
// children's, and Th lies between the children's / simplify_factor and the
// parents'. A merge must also leave the parents below Th · simplify_factor,
// so the diamond stays split and the mesh never changes. (The stretch
// criterion cannot thrash so: the parents' only edge their children lack,
// the refinement edge, has its halves' strain.)
TEST(Adaptivity, AStaticBodyNeverReSplitsADiamondAMergeRestored) {
  scene::Scene s = testing::free_cube_scene(1, 0);
  s.adaptivity.enabled = true;
  s.adaptivity.max_depth = 1;
  s.adaptivity.simplify_factor = 0.75;
  s.adaptivity.min_age_steps = 20;
  Body unsplit(s);
  const mesh::Key d = unsplit.mesh().diamond_of(0);
  Body body = unsplit;
  ASSERT_EQ(body.split(d), 1);
  const NodeId z = body.mesh().find_node(d);
  const NodeId a = body.mesh().node(z).edge_a, b = body.mesh().node(z).edge_b;
  const Vec3 across = Vec3(1e-3, 0.0, -1e-3);
  ASSERT_NEAR(across.dot(body.rest_m[b] - body.rest_m[a]), 0.0, 1e-15);
  for (Body* state : {&unsplit, &body}) {
    state->x_m[a] += across;
    state->x_m[b] -= across;
  }
  body.x_m[z] = 0.5 * (body.x_m[a] + body.x_m[b]);
  auto max_density_Pa = [](const Body& state) {
    double worst = 0.0;
    state.mesh().for_each_tet(
        [&](TetId t, const mesh::Tet&) { worst = std::max(worst, strain_energy_density_Pa(state, t)); });
    return worst;
  };
  const double child_Pa = max_density_Pa(body), parent_Pa = max_density_Pa(unsplit);
  s.adaptivity.refine_threshold_Pa = std::sqrt(child_Pa / s.adaptivity.simplify_factor * parent_Pa);
  ASSERT_LT(child_Pa, s.adaptivity.refine_threshold_Pa * s.adaptivity.simplify_factor);
  ASSERT_GT(parent_Pa, s.adaptivity.refine_threshold_Pa);
  Adaptivity adaptivity(s.adaptivity);
  int splits = 0, merges = 0;
  for (int pass = 0; pass < 40; ++pass) {
    body.step_index += 5;
    const AdaptStats stats = adaptivity.adapt(body);
    splits += stats.splits;
    merges += stats.merges;
  }
  EXPECT_EQ(merges, 0) << "merged a diamond whose parents exceed Th · simplify_factor";
  EXPECT_EQ(splits, 0) << "re-split a diamond a merge restored";
  EXPECT_TRUE(body.mesh().is_split(d));
}

// The budget holds at depth, where closures are long: a split whose closure
// is longer than what remains of max_ops_per_step waits for a later pass
// (splitting it anyway overshot by up to a whole closure, 52-134 diamonds at
// max_depth 30). Here one cube is refined towards a point to depth 18, so
// its leaves' closures run from 1 to 71 diamonds, and everything strained
// wants refining: with a budget of the longest closure, no pass may pass it.
// With a budget below the first wanted closure (the most strained tet's
// diamond, the pass's order), that closure is still split whole, and nothing
// more, so a pass always progresses.
TEST(Adaptivity, ALongClosureWaitsWhenItExceedsTheRemainingBudget) {
  scene::Scene s = testing::free_cube_scene(1, 0);
  s.adaptivity.enabled = true;
  s.adaptivity.max_depth = 30;
  s.adaptivity.refine_threshold_Pa = 1e-6;
  Body body(s);
  const std::array<double, 3> point_m{0.0123, 0.0311, 0.0271};
  for (;;) {
    std::vector<mesh::Key> keys;
    body.mesh().for_each_tet([&](TetId t, const mesh::Tet& tet) {
      if (tet.depth >= 18) return;
      const mesh::RegionBox box = mesh::tet_bounds_m(body.mesh(), t);
      for (int i = 0; i < 3; ++i)
        if (point_m[i] < box.min_m[i] || point_m[i] > box.max_m[i]) return;
      keys.push_back(body.mesh().diamond_of(t));
    });
    if (keys.empty()) break;
    for (const mesh::Key k : keys)
      if (body.mesh().can_split(k)) body.split(k);
  }
  std::vector<TetId> tets;
  std::vector<mesh::Key> closure;
  int longest = 0;
  body.mesh().for_each_tet([&](TetId t, const mesh::Tet&) {
    body.mesh().closure_tets(body.mesh().diamond_of(t), tets, closure);
    longest = std::max(longest, static_cast<int>(closure.size()));
  });
  ASSERT_GE(longest, 50);
  dilate(body, 1e-3);
  // The pass's first candidate: most strained first, ties by key, measured
  // as the pass measures (each edge's strain from Body's rest length, summed
  // in the tet's edge order: the dilation's densities differ by rounding
  // only, so the order is the rounding's).
  std::pair<double, mesh::Key> first{0.0, 0};
  bool found = false;
  body.mesh().for_each_tet([&](TetId t, const mesh::Tet& tet) {
    double sum = 0.0;
    for (const EdgeId e : tet.e) {
      const double strain = (body.x_m[body.edge_b[e]] - body.x_m[body.edge_a[e]]).norm() / body.rest_length_m[e] - 1.0;
      sum += strain * strain;
    }
    const double m = 0.5 * body.scene().material.youngs_modulus_Pa * sum;
    if (m <= s.adaptivity.refine_threshold_Pa || tet.depth >= s.adaptivity.max_depth) return;
    const std::pair<double, mesh::Key> candidate{-m, body.mesh().diamond_of(t)};
    if (!found || candidate < first) first = candidate;
    found = true;
  });
  ASSERT_TRUE(found);
  const int first_closure = body.mesh().closure_diamonds(first.second, closure);
  ASSERT_GE(first_closure, 2);
  for (const int budget : {longest, first_closure - 1}) {
    s.adaptivity.max_ops_per_step = budget;
    Body state = body;
    Adaptivity adaptivity(s.adaptivity);
    const AdaptStats stats = adaptivity.adapt(state);
    EXPECT_GT(stats.splits, 0) << "budget " << budget;
    if (budget == longest) {
      EXPECT_LE(stats.splits, budget) << "a closure overshot the budget";
    } else {
      EXPECT_TRUE(state.mesh().is_split(first.second)) << "the first candidate waited";
      EXPECT_EQ(stats.splits, first_closure) << "only the first split may pass the budget, by its own closure";
    }
  }
}

// A pass whose budget binds stops looking for a closure that fits after
// Adaptivity::kMaxSplitWaitsPerPass waits, and walks a waiting diamond's
// closure once, not once per tet: with a few operations left and the
// following candidates' closures longer, it walked each of them up (an O(L²)
// walk, L up to ~130 at depth 30), a diamond up to 8 times, to the end of
// the list (tens of thousands on a big body strained everywhere). Here a
// 2x2x2-cube body, uniform to depth 4, has a third of its leaves split twice
// more and one corner refined towards a point to depth 16 (closures of 1 to
// tens of diamonds, ~870 distinct diamonds), and every node is moved a
// little, so everything wants refining. Each budget's pass walks at most one
// closure per split it makes (at most the budget) plus the waits.
TEST(Adaptivity, ABindingBudgetBoundsTheClosureWalksOfAPass) {
  scene::Scene s = testing::free_cube_scene(2, 0);
  s.adaptivity.enabled = true;
  s.adaptivity.max_depth = 30;
  s.adaptivity.refine_threshold_Pa = 1e-6;
  Body body(s);
  auto split_where = [&](auto&& want) {
    std::vector<mesh::Key> keys;
    body.mesh().for_each_tet([&](TetId t, const mesh::Tet& tet) {
      if (want(t, tet)) keys.push_back(body.mesh().diamond_of(t));
    });
    for (const mesh::Key k : keys)
      if (body.mesh().can_split(k)) body.split(k);
    return !keys.empty();
  };
  for (int depth = 0; depth < 4; ++depth) split_where([&](TetId, const mesh::Tet& tet) { return tet.depth == depth; });
  for (int round = 0; round < 2; ++round) split_where([&](TetId t, const mesh::Tet&) { return t % 3 == 0; });
  const std::array<double, 3> point_m{0.0123, 0.0311, 0.0271};
  while (split_where([&](TetId t, const mesh::Tet& tet) {
    if (tet.depth >= 16) return false;
    const mesh::RegionBox box = mesh::tet_bounds_m(body.mesh(), t);
    for (int i = 0; i < 3; ++i)
      if (point_m[i] < box.min_m[i] || point_m[i] > box.max_m[i]) return false;
    return true;
  })) {
  }
  std::set<mesh::Key> wanted;
  body.mesh().for_each_tet([&](TetId t, const mesh::Tet&) { wanted.insert(body.mesh().diamond_of(t)); });
  // Every node moved by up to 1 um: strain ~ 1 um / L, so the fine tets
  // near the refinement fronts, whose diamonds wait on coarser ones, come
  // first, and no two tets tie.
  // (mt19937's raw output, which the standard fixes, unlike a distribution's.)
  std::mt19937 rng(7);
  auto jitter_m = [&] { return (static_cast<double>(rng()) / 4294967295.0 * 2.0 - 1.0) * 1e-6; };
  body.mesh().for_each_node([&](NodeId n, const mesh::Node&) {
    const double dx_m = jitter_m(), dy_m = jitter_m(), dz_m = jitter_m();
    body.x_m[n] = body.rest_m[n] + Vec3(dx_m, dy_m, dz_m);
  });
  const int waits = Adaptivity::kMaxSplitWaitsPerPass;
  bool capped = false;
  for (int budget = 2; budget <= 40; ++budget) {
    s.adaptivity.max_ops_per_step = budget;
    ASSERT_GT(static_cast<int>(wanted.size()), 10 * (budget + waits));
    Body state = body;
    Adaptivity adaptivity(s.adaptivity);
    const AdaptStats stats = adaptivity.adapt(state);
    ASSERT_EQ(stats.merges, 0);
    EXPECT_LE(stats.closure_walks, budget + waits) << "budget " << budget << ", " << wanted.size() << " wanted";
    EXPECT_LE(stats.split_waits, waits) << "budget " << budget;
    capped = capped || stats.split_waits == waits;
  }
  EXPECT_TRUE(capped) << "no pass waited its most: the case this test is for";
}

// docs/scene-format.md: `stretch` refines when any l/L or L/l exceeds
// stretch_ratio. A spring compressed to 40 % has L/l = 2.5 > 2. (The pass
// compared |l/L - 1| with stretch_ratio - 1, so a compression never reached
// a ratio of 2 or more (|0.4 - 1| = 0.6 < 1), and below that it refined late
// (l/L = 0.951: L/l = 1.0515 > 1.05 was not refined).)
TEST(Adaptivity, StretchCriterionRefinesACompressionWhoseLOverlExceedsTheRatio) {
  scene::Scene s = relaxed_cube_scene();
  s.adaptivity.criterion = scene::RefineCriterion::kStretch;
  for (const auto& [ratio, length_ratio] : {std::pair{2.0, 0.4}, std::pair{1.05, 0.951}}) {
    s.adaptivity.stretch_ratio = ratio;
    Body body(s);
    dilate(body, length_ratio - 1.0);
    Adaptivity adaptivity(s.adaptivity);
    EXPECT_GT(adaptivity.adapt(body).splits, 0) << "l/L " << length_ratio << ", stretch_ratio " << ratio;
  }
}

}  // namespace
}  // namespace tissue::physics
