#include "physics/diagnostics.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include "physics/forces.hpp"
#include "physics/physics_test_support.hpp"
#include "scene/scene_yaml.hpp"

namespace tissue::physics {
namespace {

using testing::box;
using testing::sphere;
using testing::total_energy_J;

TEST(Diagnostics, PassedNeedsFiniteStatesAndAnExcessWithinTheSlack) {
  EnergyAudit audit;
  EXPECT_TRUE(audit.within_energy_bound(0.0));
  audit.worst_excess = 0.1;
  EXPECT_TRUE(audit.within_energy_bound(0.1));
  EXPECT_TRUE(audit.within_energy_bound(0.2));
  EXPECT_FALSE(audit.within_energy_bound(0.05));
  audit.nonfinite = true;
  EXPECT_FALSE(audit.within_energy_bound(1e9));
  audit.nonfinite = false;
  audit.refused = true;  // the explicit rung may refuse a step it cannot take: not a failure
  EXPECT_TRUE(audit.within_energy_bound(0.2));
}

// Damped free vibration of a jiggled free cube: every step is taken, none
// refused, and the body only loses energy, so the excess stays at zero.
TEST(Diagnostics, DampedFreeVibrationPassesEveryStep) {
  Simulation sim(testing::free_cube_scene(2, 1));
  testing::jiggle_free_nodes(sim.mutable_body(), 17, 0.003, 0.2);
  const double e0 = total_energy_J(sim);
  ASSERT_GT(e0, 1e-6);
  const EnergyAudit audit = audit_steps(sim, 40);
  EXPECT_EQ(audit.steps_taken, 40);
  EXPECT_EQ(sim.counters().steps, 40);
  EXPECT_FALSE(audit.refused);
  EXPECT_TRUE(audit.error.empty()) << audit.error;
  EXPECT_FALSE(audit.nonfinite);
  EXPECT_GE(audit.worst_excess, 0.0);
  EXPECT_LE(audit.worst_excess, 1e-6);
  EXPECT_EQ(audit.inverted_tets, 0u);
  EXPECT_TRUE(audit.within_energy_bound(1e-6));
  EXPECT_LT(total_energy_J(sim), e0);
}

// The excess is E / (E0 + W) − 1 with E0 and W counted from the audit's
// start, not the run's. A prescribed push puts energy in that no load's
// work accounts for, so the excess is real; it is recomputed here from a
// twin run (runs are deterministic) stepped by hand.
TEST(Diagnostics, ExcessIsMeasuredFromTheEnergyAndWorkAtTheAuditsStart) {
  scene::Scene s = testing::beam_scene(0.5);
  scene::PrescribedSpec push{"push", box({0.2, 0, 0.1}, {0.2, 0.1, 0.1}), {0, 0, -0.002}, {}};
  push.profile.start_s = 0.02;
  push.profile.ramp_s = 0.03;
  s.prescribed.push_back(push);
  // Some excess to measure: undamped symplectic Euler near its stable step
  // holds O(h ω) more energy than the work done, at times.
  s.integrator.kind = scene::IntegratorKind::kExplicit;
  s.integrator.substep_safety = 0.95;
  s.material.rayleigh_beta_s = 0.0;
  Simulation audited(s), twin(s);
  for (int i = 0; i < 20; ++i) {
    ASSERT_TRUE(audited.step().ok);
    ASSERT_TRUE(twin.step().ok);
  }
  ASSERT_GT(audited.counters().external_work_J, 0.0);  // work done before the audit must not count

  const auto work_J = [](const Simulation& sim) {
    return sim.counters().external_work_J + sim.counters().prescribed_work_J;
  };
  const double e0 = total_energy_J(twin), w0 = work_J(twin);
  double expected = 0.0;
  for (int i = 0; i < 30; ++i) {
    ASSERT_TRUE(twin.step().ok);
    const double budget = e0 + std::max(0.0, work_J(twin) - w0);
    expected = std::max(expected, total_energy_J(twin) / budget - 1.0);
  }
  ASSERT_GT(expected, 0.01);

  const EnergyAudit audit = audit_steps(audited, 30);
  EXPECT_EQ(audit.steps_taken, 30);
  EXPECT_NEAR(audit.worst_excess, expected, 1e-9 * expected);
  EXPECT_FALSE(audit.within_energy_bound(0.5 * expected));
  EXPECT_TRUE(audit.within_energy_bound(2.0 * expected));
}

// The shipped cantilever made 3.6e14 times stiffer (E = 1.8e19 Pa, past the
// loader's 1e13 cap, set here directly; a load of a millinewton on a body of
// 1e13 Pa gets there too): its 5 N tip load strains it ~1e-17, below what
// coordinates of 0.1 m resolve, so its
// elastic energy is rounding (1.7e-15 J against 4.8e-17 J of work) and no
// step gains anything. The audit read 0.185 "excess" there (found by
// tests/physics/scene_extremes_test.cpp); a real gain at that stiffness, a
// jiggle of 1 µm, is still seen.
TEST(Diagnostics, RoundingInABodyTooStiffToResolveItsDeformationIsNoExcess) {
  const std::string path = std::string(TISSUE_SOURCE_DIR) + "/config/scenes/cantilever.yaml";
  scene::Scene s = scene::load_scene_file(path);
  s.material.youngs_modulus_Pa = 1.8e19;
  Simulation sim(s);
  const EnergyAudit audit = audit_steps(sim, 10);
  ASSERT_EQ(audit.steps_taken, 10) << audit.error;
  EXPECT_EQ(audit.worst_excess, 0.0);

  const EnergyBudget budget(sim);
  testing::jiggle_free_nodes(sim.mutable_body(), 17, 1e-6, 0.0);
  EXPECT_GT(budget.excess(sim), 1.0);
}

// A step the explicit rung refuses ends the audit at once: nothing taken,
// the reason kept, the step tried only once, the state untouched.
TEST(Diagnostics, ARefusedStepEndsTheAuditWithItsReason) {
  scene::Scene s = testing::free_cube_scene(2, 1);
  s.integrator.kind = scene::IntegratorKind::kExplicit;
  s.material.youngs_modulus_Pa = 1e9;
  s.integrator.max_substeps = 1;
  Simulation sim(s);
  testing::jiggle_free_nodes(sim.mutable_body(), 19, 0.001, 0.1);
  const auto x0 = sim.body().x_m;
  const EnergyAudit audit = audit_steps(sim, 10);
  EXPECT_TRUE(audit.refused);
  EXPECT_NE(audit.error.find("max_substeps"), std::string::npos) << audit.error;
  EXPECT_EQ(audit.steps_taken, 0);
  EXPECT_EQ(sim.counters().rejected_steps, 1);
  EXPECT_EQ(sim.time_s(), 0.0);
  EXPECT_EQ(sim.body().x_m, x0);
  EXPECT_FALSE(audit.nonfinite);
}

// The stability matrix's verdict: a refusal is the explicit rung's
// documented limit only when that rung refused above integrator.max_substeps.
// Every integrator rejects a non-finite step and keeps the old state, so a
// blow-up reaches the audit as a refusal, never as a non-finite state: it was
// counted "refused (explicit above max_substeps)" and the matrix exited 0.
TEST(Diagnostics, OnlyTheExplicitRungsRefusalAboveMaxSubstepsIsNotAFailure) {
  EnergyAudit clean;
  clean.steps_taken = 10;
  EXPECT_EQ(audit_outcome(clean, 1e-6, false), AuditOutcome::kOk);
  EnergyAudit growth = clean;
  growth.worst_excess = 0.1;
  EXPECT_EQ(audit_outcome(growth, 0.05, true), AuditOutcome::kFailed);
  EXPECT_EQ(audit_outcome(growth, 0.2, true), AuditOutcome::kOk);
  EnergyAudit nonfinite = clean;
  nonfinite.nonfinite = true;
  EXPECT_EQ(audit_outcome(nonfinite, 1e9, true), AuditOutcome::kFailed);

  // The refusal the explicit rung really gives above its cap.
  scene::Scene s = testing::free_cube_scene(2, 1);
  s.integrator.kind = scene::IntegratorKind::kExplicit;
  s.material.youngs_modulus_Pa = 1e9;
  s.integrator.max_substeps = 1;
  Simulation sim(s);
  const EnergyAudit above_cap = audit_steps(sim, 10);
  ASSERT_TRUE(above_cap.refused);
  EXPECT_EQ(audit_outcome(above_cap, 0.05, true), AuditOutcome::kRefusedAboveMaxSubsteps) << above_cap.error;
  EXPECT_EQ(audit_outcome(above_cap, 1e-6, false), AuditOutcome::kFailed) << "only the explicit rung may refuse";
  // Its energy bound's refusal likewise (the step itself is in
  // Stability.UndampedYankOnExplicitEndsRefusedAtItsEnergyBound).
  EnergyAudit above_bound = clean;
  above_bound.refused = true;
  above_bound.error =
      "explicit integrator: energy 3 J is 200 % above its budget 1 J (start + work + mesh changes), "
      "more than integrator.explicit_energy_slack = 1 allows; step refused, previous state kept";
  EXPECT_EQ(audit_outcome(above_bound, 0.05, true), AuditOutcome::kRefusedAboveEnergyBound);
  EXPECT_EQ(audit_outcome(above_bound, 1e-6, false), AuditOutcome::kFailed) << "only the explicit rung may refuse";

  // A rejected blow-up, whichever rung: a failure.
  for (const char* rejected : {"explicit integrator: state became non-finite; step rejected, previous state kept",
                               "implicit integrator: state became non-finite; step rejected, previous state kept",
                               "projective integrator: factorisation of the global system failed"}) {
    EnergyAudit refused = clean;
    refused.refused = true;
    refused.error = rejected;
    EXPECT_EQ(audit_outcome(refused, 0.05, true), AuditOutcome::kFailed) << rejected;
    EXPECT_EQ(audit_outcome(refused, 1e-6, false), AuditOutcome::kFailed) << rejected;
  }
}

// The matrix's outcome column names what failed the case. It judges the
// explicit rung at a slack of 0.05 but the rung refuses only above its own
// integrator.explicit_energy_slack (1), and energy grows gradually: a run
// that ends at the energy bound's refusal has nearly always grown past 0.05
// on an accepted step first. That failure is the growth, so the label leads
// with it and names the refusal second; it printed "FAILED, refused: ...".
TEST(Diagnostics, TheMatrixLabelsEnergyGrowthBeforeTheRefusalThatFollowedIt) {
  EnergyAudit grown_then_refused;
  grown_then_refused.steps_taken = 40;
  grown_then_refused.worst_excess = 0.3;
  grown_then_refused.refused = true;
  grown_then_refused.error =
      "explicit integrator: energy 3 J is 200 % above its budget 1 J (start + work + mesh changes), "
      "more than integrator.explicit_energy_slack = 1 allows; step refused, previous state kept";
  ASSERT_EQ(audit_outcome(grown_then_refused, 0.05, true), AuditOutcome::kFailed);
  EXPECT_EQ(audit_outcome_label(grown_then_refused, 0.05, true), "ENERGY-GROWTH, then refused above its energy bound");
  // A rejected blow-up after the growth keeps its message (it says what broke).
  EnergyAudit grown_then_rejected = grown_then_refused;
  grown_then_rejected.error = "explicit integrator: state became non-finite; step rejected, previous state kept";
  EXPECT_EQ(audit_outcome_label(grown_then_rejected, 0.05, true),
            "ENERGY-GROWTH, then refused: " + grown_then_rejected.error);
  EnergyAudit grown_then_capped = grown_then_refused;
  grown_then_capped.error = "explicit integrator: step needs 2000 sub-steps, more than integrator.max_substeps = 1000";
  EXPECT_EQ(audit_outcome_label(grown_then_capped, 0.05, true), "ENERGY-GROWTH, then refused above max_substeps");

  // Within the slack the refusal is the whole story, as before.
  EnergyAudit refused_within = grown_then_refused;
  refused_within.worst_excess = 0.01;
  EXPECT_EQ(audit_outcome_label(refused_within, 0.05, true), "refused above its energy bound");
  refused_within.error = grown_then_rejected.error;
  EXPECT_EQ(audit_outcome_label(refused_within, 0.05, true), "FAILED, refused: " + refused_within.error);
  EXPECT_EQ(audit_outcome_label(refused_within, 0.05, false), "FAILED, refused: " + refused_within.error);
  // Runs that took every step.
  EnergyAudit clean;
  clean.steps_taken = 40;
  EXPECT_EQ(audit_outcome_label(clean, 0.05, true), "ok");
  clean.worst_excess = 0.3;
  EXPECT_EQ(audit_outcome_label(clean, 0.05, true), "ENERGY-GROWTH");
  clean.worst_excess = std::numeric_limits<double>::quiet_NaN();  // not within any slack: audit_outcome fails it
  EXPECT_EQ(audit_outcome_label(clean, 0.05, true), "ENERGY-GROWTH");
  clean.nonfinite = true;
  EXPECT_EQ(audit_outcome_label(clean, 0.05, true), "NON-FINITE");
}

// A non-finite energy or budget is no health: an infinite mass at a node at
// rest makes the kinetic energy NaN (inf × 0), which read as an excess of 0,
// and a budget taken from such a state made the excess NaN, which std::max
// and `worst > slack` dropped: the audit said kOk.
TEST(Diagnostics, ANonFiniteEnergyOrBudgetIsNeverWithinTheBound) {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  scene::Scene s = testing::beam_scene();
  s.integrator.kind = scene::IntegratorKind::kExplicit;
  Simulation sim(s);
  testing::jiggle_free_nodes(sim.mutable_body(), 23, 0.001, 0.05);
  Body& body = sim.mutable_body();
  NodeId held = 0;  // a fixed node: at rest, and no integrator moves it
  while (body.kind[held] != NodeKind::kFixed) ++held;
  ASSERT_EQ(body.v_m_per_s[held], Vec3::Zero());
  const double mass_kg = body.mass_kg[held];

  const EnergyBudget finite_budget(sim);
  ASSERT_TRUE(std::isfinite(finite_budget.excess(sim)));
  body.mass_kg[held] = kInf;
  ASSERT_TRUE(std::isnan(sim.kinetic_energy_J()));
  EXPECT_EQ(finite_budget.excess(sim), kInf) << "a NaN energy";

  const EnergyBudget nan_budget(sim);  // E0 is NaN
  ASSERT_TRUE(std::isnan(nan_budget.budget_J(sim)));
  body.mass_kg[held] = mass_kg;
  ASSERT_TRUE(std::isfinite(sim.kinetic_energy_J()));
  EXPECT_EQ(nan_budget.excess(sim), kInf) << "a NaN budget";

  // Through the audit: the explicit rung refuses the first step, as its
  // energy is not a finite number and so not within its bound
  // (integrator.explicit_energy_slack)...
  body.mass_kg[held] = kInf;
  const EnergyAudit refused = audit_steps(sim, 5);
  EXPECT_EQ(refused.steps_taken, 0);
  EXPECT_NE(refused.error.find("nan J is inf % above its budget"), std::string::npos) << refused.error;
  EXPECT_EQ(audit_outcome(refused, 1e9, true), AuditOutcome::kRefusedAboveEnergyBound) << refused.error;
  // ... and the implicit rung takes every step (the fixed node's mass is
  // never used), but the energy is NaN throughout.
  s.integrator.kind = scene::IntegratorKind::kImplicit;
  Simulation implicit_sim(s);
  testing::jiggle_free_nodes(implicit_sim.mutable_body(), 23, 0.001, 0.05);
  implicit_sim.mutable_body().mass_kg[held] = kInf;
  const EnergyAudit audit = audit_steps(implicit_sim, 5);
  ASSERT_EQ(audit.steps_taken, 5) << audit.error;
  EXPECT_FALSE(audit.worst_excess <= 0.0) << audit.worst_excess;
  EXPECT_FALSE(audit.within_energy_bound(1e9));
  EXPECT_EQ(audit_outcome(audit, 1e9, false), AuditOutcome::kFailed);

  // A NaN worst excess (from any source) is not within any slack either.
  EnergyAudit nan_excess;
  nan_excess.steps_taken = 10;
  nan_excess.worst_excess = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(nan_excess.within_energy_bound(1e9));
  EXPECT_EQ(audit_outcome(nan_excess, 1e9, false), AuditOutcome::kFailed);
}

// The count is taken at the end: a corner of a very soft cube is driven
// across the plane x = y of its opposite face in one tet (see forces_test),
// inverting that tet during the audit.
TEST(Diagnostics, InvertedTetsAreCountedAtTheEnd) {
  scene::Scene s = testing::free_cube_scene(1, 0);
  s.material.youngs_modulus_Pa = 1.0;                                                    // the other nodes barely move
  scene::PrescribedSpec drag{"drag", sphere({0.05, 0, 0}, 1e-4), {-0.04, 0.03, 0}, {}};  // to (0.2, 0.6, 0) h
  drag.profile.ramp_s = 0.01;
  s.prescribed.push_back(drag);
  Simulation sim(s);
  ASSERT_EQ(inverted_tet_count(sim.body()), 0u);
  const EnergyAudit audit = audit_steps(sim, 20);
  EXPECT_EQ(audit.steps_taken, 20);
  EXPECT_EQ(audit.inverted_tets, 1u);
  EXPECT_EQ(audit.inverted_tets, inverted_tet_count(sim.body()));
}

// diagnostics.hpp: work done on the body counts, negative work (the body
// pushing its load back) as 0: the budget is then the energy it started
// with, not less.
TEST(Diagnostics, NegativeWorkCountsAsZeroInTheBudget) {
  scene::Scene s = testing::free_cube_scene(2, 0);
  s.integrator.kind = scene::IntegratorKind::kExplicit;
  s.loads.push_back({"brake", box({0.1, 0, 0}, {0.1, 0.1, 0.1}), {-1.0, 0.0, 0.0}, {}});
  Simulation sim(s);
  Body& body = sim.mutable_body();
  body.mesh().for_each_node([&](NodeId n, const mesh::Node&) { body.v_m_per_s[n] = Vec3(0.1, 0.0, 0.0); });
  const double e0_J = total_energy_J(sim);
  const EnergyBudget budget(sim);
  for (int i = 0; i < 10; ++i) ASSERT_TRUE(sim.step().ok);
  ASSERT_LT(sim.counters().external_work_J, 0.0);
  EXPECT_EQ(budget.budget_J(sim), e0_J);
}

}  // namespace
}  // namespace tissue::physics
