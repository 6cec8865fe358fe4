// What every rung promises through the common interface (integrator.hpp):
// the same static solution, conservation, no energy gain, non-finite states
// rejected; each rung's own machinery is tested beside its source file.
#include "physics/integrator.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
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

// Mass-proportional Rayleigh damping (c = α m) is taken implicitly by every
// rung: in a rigid drift no spring stretches, so each (sub-)step of length
// h only divides the velocity by 1 + h α (backward Euler on m v' = −α m v).
// Explicit on a one-depth mesh (offset layout), on a mixed-depth one
// (gathered stream) and in single precision; implicit; projective.
TEST(Integrator, MassDampingSlowsARigidDriftByOnePlusHAlphaPerStep) {
  const Vec3 v0(0.3, -0.2, 0.1);
  for (int rung = 0; rung < 5; ++rung) {
    scene::Scene s = free_cube_scene(4, 3);  // a lattice the offset layout fills
    s.adaptivity.enabled = true;             // room for the split below
    s.adaptivity.min_depth = 3;
    s.adaptivity.max_depth = 4;
    s.adaptivity.every_steps = 1000;
    s.material.rayleigh_alpha_per_s = 50.0;
    s.integrator.dt_s = 2e-3;
    s.integrator.kind = rung < 3 ? scene::IntegratorKind::kExplicit : kAll[rung - 2];
    if (rung == 2) s.integrator.explicit_precision = scene::ExplicitPrecision::kFloat;
    Simulation sim(s);
    if (rung == 1) {  // mixed depths: not the offset layout
      const Body& b = sim.body();
      ASSERT_GE(sim.split_diamond(b.mesh().diamond_of(0)), 1);
    }
    Body& body = sim.mutable_body();
    body.mesh().for_each_node([&](NodeId n, const mesh::Node&) { body.v_m_per_s[n] = v0; });
    double expected = 1.0;  // |v| / |v0|
    for (int i = 0; i < 10; ++i) {
      const StepResult r = sim.step();
      ASSERT_TRUE(r.ok) << r.error;
      expected /= std::pow(1.0 + s.integrator.dt_s / r.substeps * s.material.rayleigh_alpha_per_s, r.substeps);
      if (i == 0 && rung < 2) {
        EXPECT_EQ(sim.counters().offset_layout_steps, rung == 0 ? 1 : 0);
      }
    }
    ASSERT_LT(expected, 0.5);
    const double tolerance = rung == 2 ? 1e-5 : (rung == 3 ? 10 * s.integrator.cg_tolerance : 1e-9);
    double worst = 0.0;
    sim.body().mesh().for_each_node([&](NodeId n, const mesh::Node&) {
      worst = std::max(worst, (sim.body().v_m_per_s[n] - expected * v0).norm());
    });
    EXPECT_LT(worst, tolerance * v0.norm()) << sim.integrator().name() << " rung " << rung;
  }
}

// integrator.hpp: a state is finite when every live node's position and
// velocity is finite and below 1e100 in magnitude.
TEST(Integrator, StateIsFiniteRefusesInfinitiesAndMagnitudesFrom1e100) {
  const Body rest(free_cube_scene(1, 0));
  EXPECT_TRUE(state_is_finite(rest));
  for (const bool velocity : {false, true})
    for (const double bad : {std::numeric_limits<double>::infinity(), -2e100}) {
      Body body = rest;
      (velocity ? body.v_m_per_s : body.x_m)[3].y() = bad;
      EXPECT_FALSE(state_is_finite(body)) << (velocity ? "velocity " : "position ") << bad;
    }
  Body large = rest;
  large.x_m[3].y() = 0.5e100;
  large.v_m_per_s[3].y() = -0.5e100;
  EXPECT_TRUE(state_is_finite(large));
}

// The same for a NaN in any one component. (state_is_finite compared
// cwiseAbs().maxCoeff(), and Eigen's maxCoeff is undefined with a NaN
// present: it skipped a NaN in y or z, so the implicit and projective rungs
// and audit_steps took such a state as finite.)
TEST(Integrator, StateIsFiniteCatchesANaNInAnyComponent) {
  const Body rest(free_cube_scene(1, 0));
  for (const bool velocity : {false, true})
    for (int component = 0; component < 3; ++component) {
      Body body = rest;
      (velocity ? body.v_m_per_s : body.x_m)[3][component] = std::numeric_limits<double>::quiet_NaN();
      EXPECT_FALSE(state_is_finite(body)) << (velocity ? "velocity" : "position") << " component " << component;
    }
}

}  // namespace
}  // namespace tissue::physics
