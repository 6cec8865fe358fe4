#include "physics/adaptivity.hpp"

#include <gtest/gtest.h>

#include <set>

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

// One pass does at most the budget, overshooting only by its last split's
// closure (a few diamonds per level).
TEST(Adaptivity, OnePassRespectsTheOperationBudget) {
  scene::Scene s = cantilever_scene();
  s.adaptivity.refine_threshold_Pa = 1e-6;  // everything strained wants refining
  s.adaptivity.every_steps = 1;
  s.adaptivity.max_ops_per_step = 10;
  Simulation sim(s);
  const StepResult r = sim.step();
  ASSERT_TRUE(r.ok);
  EXPECT_GE(r.adapted.splits, 10);
  EXPECT_LE(r.adapted.splits, 10 + 3 * 3);
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
          criterion == scene::RefineCriterion::kStretch ? max_edge_strain(body, t) : strain_energy_density_Pa(body, t);
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

}  // namespace
}  // namespace tissue::physics
