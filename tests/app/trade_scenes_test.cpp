// The trade study's built-in scenes and mesh choice (app/trade_scenes.hpp).
#include "app/trade_scenes.hpp"

#include <gtest/gtest.h>

#include <stdexcept>

namespace tissue::app {
namespace {

namespace sc = tissue::scene;

TEST(TradeScenes, AUniformMeshPinsBothDepthsAnAdaptiveOneStartsAtZero) {
  sc::Scene s;
  s.adaptivity.criterion = sc::RefineCriterion::kStretch;  // the scene's own: the sweep refines by energy
  apply_mesh(s, {false, 2, 0.0, 2});
  EXPECT_FALSE(s.adaptivity.enabled);
  EXPECT_EQ(s.adaptivity.min_depth, 2);
  EXPECT_EQ(s.adaptivity.max_depth, 2);
  apply_mesh(s, {true, 5, 40.0, 3});  // an adaptive choice's `depth` is not used
  EXPECT_TRUE(s.adaptivity.enabled);
  EXPECT_EQ(s.adaptivity.min_depth, 0);
  EXPECT_EQ(s.adaptivity.max_depth, 3);
  EXPECT_EQ(s.adaptivity.refine_threshold_Pa, 40.0);
  EXPECT_EQ(s.adaptivity.criterion, sc::RefineCriterion::kStrainEnergy);
}

TEST(TradeScenes, IntegratorNamesRoundTripAndAnUnknownOneIsAnError) {
  for (const auto k : {sc::IntegratorKind::kExplicit, sc::IntegratorKind::kImplicit, sc::IntegratorKind::kProjective})
    EXPECT_EQ(integrator_kind(integrator_name(k)), k) << integrator_name(k);
  EXPECT_STREQ(integrator_name(sc::IntegratorKind::kImplicit), "implicit");
  try {
    integrator_kind("rk4");
    FAIL() << "rk4 accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_STREQ(e.what(), "unknown integrator rk4");
  }
}

// Both beams are the same 0.4 m object (the beam theory and PERFORMANCE.md
// compare them), cut into cubes of 5 cm or 1/30 m.
TEST(TradeScenes, BothBeamLaddersAreTheSameObject) {
  const sc::Scene beam = performance_beam({false, 0, 0.0, 0}, sc::IntegratorKind::kImplicit, 1e-3, 0.25);
  const sc::Scene r = performance_beam({false, 0, 0.0, 0}, sc::IntegratorKind::kImplicit, 1e-3, 0.25, true);
  for (int axis = 0; axis < 3; ++axis)
    EXPECT_NEAR(beam.object.cubes[axis] * beam.object.cube_size_m, r.object.cubes[axis] * r.object.cube_size_m, 1e-12)
        << axis;
  EXPECT_NEAR(beam.object.cubes[0] * beam.object.cube_size_m, 0.4, 1e-12);
  EXPECT_EQ(r.name, "beam-r");
  EXPECT_EQ(beam.loads.at(0).profile.ramp_s, 0.25);
  EXPECT_EQ(beam.probes.at(0).name, "tip_centre");  // probe 0 is the tip: the neutral axis
}

TEST(TradeScenes, ThePaperCantileverHasItsTipLoadAndRelease) {
  const sc::Scene s = paper_cantilever({true, 0, 20.0, 3}, sc::IntegratorKind::kExplicit, 5e-3, 1.0);
  EXPECT_EQ(s.loads.at(0).total_force_N[2], -5.0);
  EXPECT_EQ(s.loads.at(0).profile.release_s, 1.0);
  EXPECT_EQ(s.integrator.kind, sc::IntegratorKind::kExplicit);
  EXPECT_EQ(s.integrator.dt_s, 5e-3);
  EXPECT_TRUE(s.adaptivity.enabled);
  EXPECT_EQ(s.probes.at(0).name, "tip_bottom");
}

}  // namespace
}  // namespace tissue::app
