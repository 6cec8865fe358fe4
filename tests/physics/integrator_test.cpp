// What every rung promises through the common interface (integrator.hpp):
// the same static solution, conservation, no energy gain, non-finite states
// rejected; each rung's own machinery is tested beside its source file.
#include "physics/integrator.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <random>
#include <string>

#include "physics/physics_test_support.hpp"
#include "physics/simulation.hpp"

namespace tissue::physics {
namespace {

using testing::beam_scene;
using testing::free_cube_scene;
using testing::run_until;
using testing::total_energy_J;

const scene::IntegratorKind kAll[] = {scene::IntegratorKind::kExplicit, scene::IntegratorKind::kImplicit,
                                      scene::IntegratorKind::kProjective};

double static_tip_mm(scene::Scene s) {
  s.integrator.kind = scene::IntegratorKind::kImplicit;
  s.integrator.dt_s = 0.05;
  s.integrator.cg_tolerance = 1e-10;
  s.integrator.cg_max_iterations = 2000;
  Simulation sim(s);
  EXPECT_TRUE(run_until(sim, 20.0));
  return -1e3 * sim.probe_displacement_m(0).z();
}

// Beam theory for PERFORMANCE.md's beam: 2.56 mm (Euler–Bernoulli), 2.68 mm
// with Timoshenko shear. The isotropic springs at depth 3 land within 2%.
TEST(Integrator, StaticBeamAtDepthThreeMatchesBeamTheory) {
  scene::Scene s = beam_scene();
  s.adaptivity.min_depth = 3;
  const double tip = static_tip_mm(s);
  EXPECT_NEAR(tip, 2.68, 0.02 * 2.68);
}

// Run long with mass damping, every rung settles on the same static tip.
TEST(Integrator, AllRungsSettleOnTheSameStaticTip) {
  scene::Scene s = beam_scene();
  s.material.rayleigh_alpha_per_s = 20.0;
  const double reference = static_tip_mm(s);
  for (auto kind : kAll) {
    s.integrator = {};
    s.integrator.kind = kind;
    s.integrator.dt_s = 1e-3;
    Simulation sim(s);
    std::string error;
    ASSERT_TRUE(run_until(sim, 3.0, &error)) << error;
    EXPECT_NEAR(-1e3 * sim.probe_displacement_m(0).z(), reference, 0.01 * reference) << sim.integrator().name();
  }
}

// A free body with no external force: momentum is conserved by every rung
// (by the implicit one to its CG tolerance: the residual is what it misses).
TEST(Integrator, MomentumIsConservedWithoutExternalForces) {
  for (auto kind : kAll) {
    scene::Scene s = free_cube_scene(2, 1);
    s.integrator.kind = kind;
    Simulation sim(s);
    std::mt19937 rng(1);
    std::uniform_real_distribution<double> u(-0.1, 0.1);
    Body& body = sim.mutable_body();
    body.mesh().for_each_node([&](NodeId n, const mesh::Node&) { body.v_m_per_s[n] = Vec3(u(rng), u(rng), u(rng)); });
    const Vec3 p0 = body.momentum_kg_m_per_s();
    ASSERT_TRUE(run_until(sim, 0.2));
    const double tolerance = kind == scene::IntegratorKind::kImplicit ? 10 * s.integrator.cg_tolerance : 1e-10;
    EXPECT_LT((sim.body().momentum_kg_m_per_s() - p0).norm(), tolerance * p0.norm()) << sim.integrator().name();
  }
}

// Free vibration: implicit and projective never gain energy. Symplectic
// Euler conserves a shadow energy instead: the true energy oscillates by
// O(h ω) (large here: random velocities excite the highest modes) but never
// drifts upward.
TEST(Integrator, FreeVibrationNeverGainsEnergy) {
  for (auto kind : kAll) {
    scene::Scene s = free_cube_scene(2, 2);
    s.material.rayleigh_beta_s = 0.0;
    s.integrator.kind = kind;
    Simulation sim(s);
    std::mt19937 rng(4);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    Body& body = sim.mutable_body();
    body.mesh().for_each_node(
        [&](NodeId n, const mesh::Node&) { body.v_m_per_s[n] = 0.05 * Vec3(u(rng), u(rng), u(rng)); });
    const double e0 = total_energy_J(sim);
    double worst_early = 0, worst_late = 0;
    for (int i = 0; i < 800; ++i) {
      ASSERT_TRUE(sim.step().ok);
      (i < 400 ? worst_early : worst_late) = std::max(i < 400 ? worst_early : worst_late, total_energy_J(sim));
    }
    if (kind == scene::IntegratorKind::kExplicit) {
      EXPECT_LE(worst_early, 1.5 * e0);
      EXPECT_LE(worst_late, 1.001 * worst_early) << "explicit energy drifts upward";
    } else {
      EXPECT_LE(std::max(worst_early, worst_late), (1.0 + 1e-9) * e0) << sim.integrator().name();
    }
    EXPECT_GT(total_energy_J(sim), 0.0);
  }
}

// A state driven past floating-point range is rejected and the last finite
// state kept, for every rung.
TEST(Integrator, NonFiniteStateIsRejectedAndTheLastFiniteStateKept) {
  for (int rung = 0; rung < 4; ++rung) {  // kAll, and explicit in single precision
    scene::Scene s = beam_scene(1e300);
    s.integrator.kind = rung < 3 ? kAll[rung] : scene::IntegratorKind::kExplicit;
    if (rung == 3) s.integrator.explicit_precision = scene::ExplicitPrecision::kFloat;
    s.integrator.max_substeps = 1000000000;
    Simulation sim(s);
    bool failed = false;
    for (int i = 0; i < 50 && !failed; ++i) {
      const auto x_before = sim.body().x_m;
      const auto v_before = sim.body().v_m_per_s;
      const double t_before = sim.time_s();
      const StepResult r = sim.step();
      if (!r.ok) {
        failed = true;
        EXPECT_NE(r.error.find("non-finite"), std::string::npos) << r.error;
        EXPECT_EQ(sim.body().x_m, x_before);
        EXPECT_EQ(sim.body().v_m_per_s, v_before);
        EXPECT_EQ(sim.time_s(), t_before);
      }
      EXPECT_TRUE(state_is_finite(sim.body())) << sim.integrator().name();
    }
    EXPECT_TRUE(failed) << sim.integrator().name() << " never overflowed";
  }
}

}  // namespace
}  // namespace tissue::physics
