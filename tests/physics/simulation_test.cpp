#include "physics/simulation.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>

#include "mesh/refine_ops.hpp"
#include "physics/integrator_impl.hpp"
#include "physics/physics_test_support.hpp"

namespace tissue::physics {
namespace {

using testing::beam_scene;
using testing::box;
using testing::cantilever_scene;
using testing::run_until;
using testing::sphere;
using testing::total_energy_J;

TEST(Simulation, SameSceneGivesBitIdenticalRuns) {
  Simulation a(cantilever_scene()), b(cantilever_scene());
  ASSERT_TRUE(run_until(a, 0.3));
  ASSERT_TRUE(run_until(b, 0.3));
  ASSERT_GT(a.counters().splits, 0);
  EXPECT_EQ(a.body().x_m, b.body().x_m);
  EXPECT_EQ(a.body().v_m_per_s, b.body().v_m_per_s);
  EXPECT_EQ(a.counters().splits, b.counters().splits);
  EXPECT_EQ(a.counters().merges, b.counters().merges);
}

// Paper §4.2: the centre vertex of the free face is moved; the node lands
// exactly on its target and the probe there reads it.
TEST(Simulation, PrescribedDisplacementIsFollowedExactly) {
  scene::Scene s = cantilever_scene();
  s.loads.clear();
  scene::PrescribedSpec poke{"poke", sphere({0.1, 0.05, 0.05}, 1e-4), {0, 0, -0.01}, {}};
  poke.profile.ramp_s = 0.2;
  s.prescribed.push_back(poke);
  s.probes = {{"poke", {0.1, 0.05, 0.05}}};
  Simulation sim(s);
  ASSERT_TRUE(run_until(sim, 0.1));
  EXPECT_NEAR(sim.probe_displacement_m(0).z(), -0.005, 1e-12);  // half way up the ramp
  ASSERT_TRUE(run_until(sim, 0.3));
  EXPECT_NEAR(sim.probe_displacement_m(0).z(), -0.01, 1e-12);
  EXPECT_NEAR(sim.probe_displacement_m(0).x(), 0.0, 1e-12);
}

// The drivers' work: pushing the free face's centre 1 cm in slowly (0.5 s
// ramp, held to 1 s) stores what they did, less what the dampers took.
// Undamped and explicit, nothing is lost; damped and implicit, a little is.
TEST(Simulation, PrescribedWorkIsTheEnergyASlowPushStores) {
  for (const bool damped : {false, true}) {
    SCOPED_TRACE(damped ? "damped, implicit" : "undamped, explicit");
    scene::Scene s = cantilever_scene();
    s.loads.clear();
    s.adaptivity.enabled = false;
    scene::PrescribedSpec poke{"poke", sphere({0.1, 0.05, 0.05}, 1e-4), {0, 0, -0.01}, {}};
    poke.profile.ramp_s = 0.5;
    s.prescribed.push_back(poke);
    s.material.rayleigh_beta_s = damped ? 0.003 : 0.0;
    s.integrator.kind = damped ? scene::IntegratorKind::kImplicit : scene::IntegratorKind::kExplicit;
    Simulation sim(s);
    ASSERT_TRUE(run_until(sim, 1.0));
    const double stored_J = sim.kinetic_energy_J() + sim.elastic_energy_J(), work_J = sim.counters().prescribed_work_J;
    EXPECT_EQ(sim.counters().external_work_J, 0.0);  // no load, no gravity: all of it is the drivers'
    ASSERT_GT(stored_J, 0.01);                       // measured 31 mJ
    // Measured: undamped 0.2 %, damped 1.4 % more work than energy.
    EXPECT_GE(work_J, stored_J);
    EXPECT_LE(work_J, stored_J * (damped ? 1.03 : 1.005));
  }
}

// The step sets kinematic velocities from a list of the fixed and
// prescribed nodes: nodes a split adds on a prescribed face must join it.
// Split mid-ramp, they carry the ramp's velocity; if the list were not
// rebuilt they would keep it past the ramp's end and overshoot.
TEST(Simulation, PrescribedNodesMadeByASplitFollowTheProfile) {
  scene::Scene s = cantilever_scene();
  s.loads.clear();
  scene::PrescribedSpec push{"push", box({0.1, 0.0, 0.0}, {0.1, 0.1, 0.1}), {0, 0, -0.01}, {}};
  push.profile.ramp_s = 0.2;
  s.prescribed.push_back(push);
  Simulation sim(s);
  sim.set_adaptation_paused(true);  // only the splits below change the mesh
  auto prescribed_nodes = [&] {
    std::vector<NodeId> nodes;
    sim.body().mesh().for_each_node([&](NodeId n, const mesh::Node&) {
      if (sim.body().kind[n] == NodeKind::kPrescribed) nodes.push_back(n);
    });
    return nodes;
  };
  const std::size_t before = prescribed_nodes().size();
  ASSERT_TRUE(run_until(sim, 0.1));
  for (int pass = 0; pass < 3; ++pass) {  // the first splits take the cubes' diagonals, inside
    std::vector<mesh::Key> diamonds;
    sim.body().mesh().for_each_tet([&](TetId t, const mesh::Tet& tet) {
      for (NodeId n : tet.v)
        if (sim.body().kind[n] == NodeKind::kPrescribed) diamonds.push_back(sim.body().mesh().diamond_of(t));
    });
    for (mesh::Key d : diamonds)
      if (sim.body().mesh().can_split(d)) sim.split_diamond(d);
  }
  ASSERT_GT(prescribed_nodes().size(), before);
  ASSERT_TRUE(run_until(sim, 0.3));
  for (NodeId n : prescribed_nodes()) {
    const Vec3 u = sim.body().x_m[n] - sim.body().rest_m[n];
    EXPECT_NEAR(u.z(), -0.01, 1e-12) << "node " << n;
    EXPECT_NEAR(u.x(), 0.0, 1e-12) << "node " << n;
  }
}

// A face load is shared by area: its resultant and its centre stay exact
// however unevenly the face is refined.
TEST(Simulation, SurfaceLoadKeepsItsResultantAndCentreUnderUnevenRefinement) {
  scene::Scene s = beam_scene(1.0);
  s.adaptivity.enabled = true;
  s.adaptivity.max_depth = 6;
  Simulation sim(s);
  // Refine one corner of the loaded face only.
  std::vector<mesh::Key> diamonds;
  sim.body().mesh().for_each_tet([&](TetId t, const mesh::Tet&) {
    for (NodeId n : sim.body().mesh().tet(t).v)
      if ((sim.body().rest_m[n] - Vec3(0.4, 0.0, 0.0)).norm() < 0.03)
        diamonds.push_back(sim.body().mesh().diamond_of(t));
  });
  for (int pass = 0; pass < 6; ++pass) {
    std::vector<mesh::Key> next;
    for (mesh::Key d : diamonds)
      if (sim.body().mesh().can_split(d)) sim.split_diamond(d);
    sim.body().mesh().for_each_tet([&](TetId t, const mesh::Tet& tet) {
      for (NodeId n : tet.v)
        if ((sim.body().rest_m[n] - Vec3(0.4, 0.0, 0.0)).norm() < 0.03) next.push_back(sim.body().mesh().diamond_of(t));
    });
    diamonds = next;
  }
  ASSERT_GT(sim.body().mesh().tet_count(), 192u + 100u);
  ASSERT_TRUE(sim.step().ok);
  // Σ f over the loaded face equals the load; its first moment sits at the face centre.
  Vec3 total = Vec3::Zero(), moment = Vec3::Zero();
  const auto& body = sim.body();
  std::vector<Vec3> f;
  LoadDistribution loads;
  loads.rebuild(body);
  loads.external_forces(body, sim.time_s(), f);
  body.mesh().for_each_node([&](NodeId n, const mesh::Node&) {
    total += f[n];
    moment += f[n].z() * body.rest_m[n];
  });
  EXPECT_NEAR(total.z(), -1.0, 1e-12);
  EXPECT_NEAR(moment.y() / total.z(), 0.05, 1e-12);
  EXPECT_NEAR(moment.z() / total.z(), 0.05, 1e-12);
}

TEST(Simulation, LoadedBeamNeverHoldsMoreEnergyThanTheWorkDoneOnIt) {
  Simulation sim(beam_scene(0.05));
  for (int i = 0; i < 1000; ++i) {
    ASSERT_TRUE(sim.step().ok);
    EXPECT_LE(sim.kinetic_energy_J() + sim.elastic_energy_J(), sim.counters().external_work_J * (1 + 1e-6) + 1e-15);
  }
  EXPECT_GT(sim.counters().external_work_J, 0.0);
}

// A constant load's work telescopes: Σ over steps of f · Δx is f · (x − x0)
// at the end. The step sums it over the loaded nodes only; a node left out
// (or a wrong position before the step) breaks the equality.
TEST(Simulation, WorkOfAConstantLoadIsTheLoadTimesTheDisplacement) {
  for (const auto kind : {scene::IntegratorKind::kExplicit, scene::IntegratorKind::kImplicit}) {
    scene::Scene s = beam_scene(0.05);
    s.integrator.kind = kind;
    s.gravity_m_per_s2 = {0.0, 0.0, -9.81};  // every free node loaded, the tip ones twice
    Simulation sim(s);
    ASSERT_TRUE(run_until(sim, 0.2));
    std::vector<Vec3> f;
    LoadDistribution loads;
    loads.rebuild(sim.body());
    loads.external_forces(sim.body(), sim.time_s(), f);
    double work_J = 0.0, scale_J = 0.0;
    sim.body().mesh().for_each_node([&](NodeId n, const mesh::Node&) {
      if (sim.body().inv_mass_per_kg[n] == 0.0) return;
      work_J += f[n].dot(sim.body().x_m[n] - sim.body().rest_m[n]);
      scale_J += f[n].norm() * (sim.body().x_m[n] - sim.body().rest_m[n]).norm();
    });
    ASSERT_GT(scale_J, 0.0);
    EXPECT_NEAR(sim.counters().external_work_J, work_J, 1e-9 * scale_J);
  }
}

// Time is the step count times dt, not a running sum (0.1 summed eight
// times is 0.7999999999999999): a load released at 0.8 s acts in the first
// seven 0.1 s steps only, and the clock reads 0.8 after eight.
TEST(Simulation, AProfileEdgeAtAStepTimeIsCrossedAtThatStep) {
  scene::Scene s = beam_scene(0.05);
  s.integrator.kind = scene::IntegratorKind::kImplicit;
  s.integrator.dt_s = 0.1;
  s.loads[0].profile.release_s = 0.8;
  Simulation sim(s);
  for (int i = 0; i < 7; ++i) ASSERT_TRUE(sim.step().ok);
  const double work_after_7_J = sim.counters().external_work_J;
  EXPECT_GT(work_after_7_J, 0.0);
  ASSERT_TRUE(sim.step().ok);
  EXPECT_EQ(sim.time_s(), 0.8);
  EXPECT_EQ(sim.body().time_s(), 0.8);
  EXPECT_EQ(sim.counters().external_work_J, work_after_7_J);  // the 8th step: released, no work
}

// Every mesh change books exactly the energy it made: a split or merge from
// outside (split_diamond, merge_diamond) and the adaptation pass of a step
// (against a twin whose pass is paused: same step, no pass).
TEST(Simulation, MeshChangesBookTheEnergyTheyMake) {
  scene::Scene s = cantilever_scene();
  s.integrator.kind = scene::IntegratorKind::kExplicit;
  s.adaptivity.every_steps = 1;
  Simulation sim(s);
  sim.set_adaptation_paused(true);  // bent on the coarse mesh: every diamond free to split
  ASSERT_TRUE(run_until(sim, 0.02));
  const auto energy_J = [](const Simulation& x) { return x.kinetic_energy_J() + x.elastic_energy_J(); };
  const double scale_J = energy_J(sim);
  ASSERT_GT(scale_J, 0.0);

  // Outside changes: split a few diamonds of the bent body, then merge one.
  int changes = 0;
  double largest_change_J = 0.0;
  for (TetId t = 0; t < sim.body().mesh().tet_capacity() && changes < 6; t += 37) {
    if (!sim.body().mesh().tet_alive(t)) continue;
    const mesh::Key d = sim.body().mesh().diamond_of(t);
    if (!sim.body().mesh().can_split(d)) continue;
    const double before_J = energy_J(sim), booked_before_J = sim.counters().adaptation_energy_J;
    ASSERT_GT(sim.split_diamond(d), 0);
    const double change_J = energy_J(sim) - before_J;
    EXPECT_NEAR(sim.counters().adaptation_energy_J - booked_before_J, change_J, 1e-12 * scale_J);
    largest_change_J = std::max(largest_change_J, std::abs(change_J));
    ++changes;
    if (changes == 3) {  // and merge it back
      const double merge_before_J = energy_J(sim), booked_J = sim.counters().adaptation_energy_J;
      ASSERT_TRUE(sim.body().mesh().can_merge(d));
      sim.merge_diamond(d);
      EXPECT_NEAR(sim.counters().adaptation_energy_J - booked_J, energy_J(sim) - merge_before_J, 1e-12 * scale_J);
    }
  }
  EXPECT_GE(changes, 6);
  EXPECT_GT(largest_change_J, 1e-6 * scale_J);  // the changes did change the energy
  EXPECT_GE(sim.counters().adaptation_energy_added_J, std::max(0.0, sim.counters().adaptation_energy_J));

  // The pass inside a step. The twin, identical so far, takes the same steps
  // with its pass paused; they part at the first pass that changes the mesh.
  Simulation adapting(s), twin(s);
  twin.set_adaptation_paused(true);
  for (int i = 0; i < 200; ++i) {
    const double booked_J = adapting.counters().adaptation_energy_J;
    const StepResult r = adapting.step();
    ASSERT_TRUE(r.ok && twin.step().ok);
    if (r.adapted.splits + r.adapted.merges == 0) {
      ASSERT_EQ(adapting.counters().adaptation_energy_J, booked_J);  // no change, nothing booked
      continue;
    }
    EXPECT_NEAR(adapting.counters().adaptation_energy_J - booked_J, energy_J(adapting) - energy_J(twin),
                1e-12 * scale_J);
    EXPECT_NE(energy_J(adapting), energy_J(twin));
    return;
  }
  ADD_FAILURE() << "no adaptation pass changed the mesh in 200 steps";
}

// The explicit rung's energy bound across a merge that takes energy out of a
// body holding more than its budget (the integrator's gain, unchecked
// between checks or within the slack). Booked in full, the merge took it all
// from the budget: the excess, in joules, stayed, over a budget shrunk
// toward 0 (below it when the merge took more than the budget), so the body
// was over its bound by many times the slack and every later step refused
// for good. A free cube drifting rigidly (the budget: its kinetic energy K0)
// has one split node flung, standing in for the integrator's gain (set
// through the body reference kept, which, unlike mutable_body(), leaves the
// bound's base alone), then merged away. Undamped and unloaded, the energy
// after stays what the merge left: the bound must judge it by the excess
// the body held before the merge, neither forgiven nor magnified.
TEST(Simulation, AMergeNeitherForgivesNorMagnifiesTheExplicitEnergyExcess) {
  const double gain = 0.9;  // of K0: within the default slack (1), above a slack of 0.8
  for (const double slack : {1.0, 0.8}) {
    SCOPED_TRACE(::testing::Message() << "gain " << gain << " x K0, slack " << slack);
    scene::Scene s = testing::free_cube_scene(2, 0);
    s.adaptivity.enabled = true;  // for split_diamond / merge_diamond
    s.adaptivity.every_steps = 100000;
    s.material.rayleigh_beta_s = 0.0;
    s.integrator.kind = scene::IntegratorKind::kExplicit;
    s.integrator.substep_safety = 0.1;  // symplectic Euler's own swing ~0.01 of the budget, not ~0.1
    s.integrator.explicit_energy_slack = slack;
    Simulation sim(s);
    const mesh::Key d = sim.body().mesh().diamond_of(0);
    ASSERT_EQ(sim.split_diamond(d), 1);
    const NodeId z = sim.body().mesh().find_node(d);
    Body& body = sim.mutable_body();
    const Vec3 drift_m_per_s(0.1, 0.0, 0.0);
    for (std::size_t n = 0; n < body.v_m_per_s.size(); ++n) body.v_m_per_s[n] = drift_m_per_s;
    ASSERT_TRUE(sim.step().ok);  // the base: K0, checked (the first step is)
    const double k0_J = total_energy_J(sim);
    ASSERT_GT(k0_J, 0.0);
    // The gain: z flung across the drift, adding gain × K0 of kinetic energy.
    const double speed_m_per_s = std::sqrt(2.0 * gain * k0_J / body.mass_kg[z]);
    body.v_m_per_s[z] += Vec3(0.0, 0.0, speed_m_per_s);
    const double before_J = total_energy_J(sim);
    ASSERT_NEAR(before_J / k0_J - 1.0, gain, 0.02);
    sim.merge_diamond(d);
    const double after_J = total_energy_J(sim);
    // The case: the merge took out half of K0 or more (z's momentum shared
    // with its edge's ends, inelastically), so booked in full the budget
    // fell below half of K0 with the whole gain still over it.
    ASSERT_LT(after_J, before_J - 0.5 * k0_J);
    // Steps until two checks have run (32 sub-steps each at most).
    std::string refused;
    for (int i = 0; i < 64 && refused.empty(); ++i)
      if (const StepResult r = sim.step(); !r.ok) refused = r.error;
    if (gain <= slack)
      EXPECT_EQ(refused, "") << "the merge magnified the excess";
    else
      EXPECT_NE(refused.find("above its budget"), std::string::npos) << "the merge forgave the excess: " << refused;
  }
}

// The explicit bound is checked once 32 sub-steps have run, so the state a
// refusal keeps (the one before the checked step) may itself hold more than
// the bound allows: gained between checks, never checked. Then every retry
// is refused, and the refusal must say so (the state kept is over, a retry
// cannot pass, the scene must be started afresh) rather than read as if the
// next try might. The gain between checks stands in as above: one split node
// of a drifting free cube flung to 2 x K0 (over the slack, 1), through the
// body reference kept; and, the reviewer's case, that node then merged away
// (booked in full, the merge took the budget below 0).
TEST(Simulation, AnExplicitRefusalWhoseKeptStateIsOverTheBoundSaysARetryCannotPass) {
  for (const bool merge : {false, true}) {
    SCOPED_TRACE(merge ? "flung node merged away" : "flung node kept");
    scene::Scene s = testing::free_cube_scene(2, 0);
    s.adaptivity.enabled = true;
    s.adaptivity.every_steps = 100000;
    s.material.rayleigh_beta_s = 0.0;
    s.integrator.kind = scene::IntegratorKind::kExplicit;
    s.integrator.substep_safety = 0.1;
    Simulation sim(s);
    const mesh::Key d = sim.body().mesh().diamond_of(0);
    ASSERT_EQ(sim.split_diamond(d), 1);
    const NodeId z = sim.body().mesh().find_node(d);
    Body& body = sim.mutable_body();
    for (std::size_t n = 0; n < body.v_m_per_s.size(); ++n) body.v_m_per_s[n] = Vec3(0.1, 0.0, 0.0);
    ASSERT_TRUE(sim.step().ok);
    const double k0_J = total_energy_J(sim);
    body.v_m_per_s[z] += Vec3(0.0, 0.0, std::sqrt(2.0 * 2.0 * k0_J / body.mass_kg[z]));
    if (merge) sim.merge_diamond(d);
    StepResult refused;
    for (int i = 0; i < 64 && refused.ok; ++i) refused = sim.step();
    ASSERT_FALSE(refused.ok);
    const std::string& why = refused.error;
    EXPECT_EQ(why.find('\n'), std::string::npos) << why;
    for (const char* says : {"step refused, previous state kept", "; the state kept is itself ",
                             " % above its budget (gained between checks, once 32 sub-steps have run)",
                             "so every retry is refused too", "set, reset, load_scene or reload"})
      EXPECT_NE(why.find(says), std::string::npos) << says << " not in: " << why;
    // The budget stays above 0 across the merge (fix of the booking above).
    const std::size_t at = why.find("above its budget ");
    ASSERT_NE(at, std::string::npos) << why;
    EXPECT_GT(std::stod(why.substr(at + std::string("above its budget ").size())), 0.0) << why;
    // Asked again: refused again, the state as it was, and says so again.
    const std::vector<Vec3> x_kept_m = sim.body().x_m;
    const StepResult again = sim.step();
    EXPECT_FALSE(again.ok);
    EXPECT_NE(again.error.find("; the state kept is itself "), std::string::npos) << again.error;
    EXPECT_EQ(sim.body().x_m, x_kept_m);
    // Started afresh (here: the state set again, the bound's base with it),
    // it runs on.
    Body& fresh = sim.mutable_body();
    for (Vec3& v : fresh.v_m_per_s) v = Vec3(0.1, 0.0, 0.0);
    for (int i = 0; i < 64; ++i) ASSERT_TRUE(sim.step().ok) << "step " << i;
  }
}

// The scene chooses the CG preconditioner (integrator.cg_preconditioner):
// at dt = 10 ms, 20 iterations carry the beam's bending with the two-level
// one and not with Jacobi (TwoLevelPreconditioner.KeepsTwentyIterations... holds
// the integrator-level figures); here the choice must reach the integrator.
TEST(Simulation, TheSceneChoosesTheCgPreconditioner) {
  const auto tip_mm = [](scene::CgPreconditioner preconditioner, double tolerance, int iterations) {
    scene::Scene s = beam_scene();
    s.adaptivity.min_depth = 2;
    s.integrator.dt_s = 1e-2;
    s.integrator.cg_tolerance = tolerance;
    s.integrator.cg_max_iterations = iterations;
    s.integrator.cg_preconditioner = preconditioner;
    Simulation sim(s);
    EXPECT_TRUE(run_until(sim, 0.4));
    return -1e3 * sim.probe_displacement_m(0).z();
  };
  const double reference = tip_mm(scene::CgPreconditioner::kJacobi, 1e-10, 5000);
  const double jacobi = tip_mm(scene::CgPreconditioner::kJacobi, 1e-300, 20);
  const double two_level = tip_mm(scene::CgPreconditioner::kTwoLevel, 1e-300, 20);
  EXPECT_NEAR(two_level, reference, 0.01 * std::abs(reference));
  EXPECT_GT(std::abs(jacobi - reference), 3.0 * std::abs(two_level - reference))
      << "jacobi " << jacobi << " two-level " << two_level << " reference " << reference;
}

// The counters say what each step cost the integrator and which steps
// stopped at cg_max_iterations short of cg_tolerance (the accuracy given up).
TEST(Simulation, CountsSolverWorkAndUnconvergedSteps) {
  const auto run = [](scene::IntegratorKind kind, double tolerance, int iterations) {
    scene::Scene s = beam_scene();
    s.integrator.kind = kind;
    s.integrator.cg_tolerance = tolerance;
    s.integrator.cg_max_iterations = iterations;
    Simulation sim(s);
    std::int64_t iterations_sum = 0, substeps_sum = 0, unconverged = 0;
    int iterations_max = 0, substeps_max = 0;
    for (int i = 0; i < 20; ++i) {
      const StepResult r = sim.step();
      EXPECT_TRUE(r.ok) << r.error;
      iterations_sum += r.solver_iterations;
      iterations_max = std::max(iterations_max, r.solver_iterations);
      substeps_sum += r.substeps;
      substeps_max = std::max(substeps_max, r.substeps);
      unconverged += r.solver_converged ? 0 : 1;
    }
    const SimCounters& c = sim.counters();
    EXPECT_EQ(c.steps, 20);
    EXPECT_EQ(c.solver_iterations, iterations_sum);
    EXPECT_EQ(c.max_solver_iterations, iterations_max);
    EXPECT_EQ(c.substeps, substeps_sum);
    EXPECT_EQ(c.max_substeps, substeps_max);
    EXPECT_EQ(c.unconverged_steps, unconverged);
    EXPECT_DOUBLE_EQ(c.solver_iterations_per_step(), static_cast<double>(iterations_sum) / 20.0);
    EXPECT_DOUBLE_EQ(c.substeps_per_step(), static_cast<double>(substeps_sum) / 20.0);
    return c;
  };
  EXPECT_EQ(SimCounters{}.solver_iterations_per_step(), 0.0);  // no step yet: no mean
  // Converged implicit steps: some iterations, none given up.
  const SimCounters converged = run(scene::IntegratorKind::kImplicit, 1e-6, 200);
  EXPECT_GT(converged.solver_iterations, 0);
  EXPECT_EQ(converged.unconverged_steps, 0);
  // One iteration cannot reach 1e-12 while the load bends the beam: every step is capped.
  const SimCounters capped = run(scene::IntegratorKind::kImplicit, 1e-12, 1);
  EXPECT_EQ(capped.max_solver_iterations, 1);
  EXPECT_EQ(capped.unconverged_steps, 20);
  const SimCounters projective = run(scene::IntegratorKind::kProjective, 1e-12, 1);
  EXPECT_EQ(projective.unconverged_steps, 20);
  // Explicit: the automatic sub-steps are counted (the damped beam needs many).
  const SimCounters explicit_run = run(scene::IntegratorKind::kExplicit, 1e-6, 200);
  EXPECT_GT(explicit_run.max_substeps, 1);
  EXPECT_EQ(explicit_run.substeps, 20 * static_cast<std::int64_t>(explicit_run.max_substeps));  // same mesh, same dt
  EXPECT_EQ(explicit_run.unconverged_steps, 0);
}

// Kinetic + elastic energy after each step against the state before it plus
// what the step was given: the work on the body and the energy its mesh
// changes made (booked apart). Returns the worst relative excess.
double worst_step_excess(Simulation& sim, int steps) {
  const auto energy_J = [&] { return sim.kinetic_energy_J() + sim.elastic_energy_J(); };
  const auto given_J = [&] {
    const SimCounters& c = sim.counters();
    return c.external_work_J + c.prescribed_work_J + c.adaptation_energy_J;
  };
  double worst = 0.0;
  for (int i = 0; i < steps; ++i) {
    const double before_J = energy_J(), given_before_J = given_J();
    const StepResult r = sim.step();
    EXPECT_TRUE(r.ok) << r.error;
    if (!r.ok) break;
    EXPECT_TRUE(state_is_finite(sim.body()));
    const double budget_J = before_J + (given_J() - given_before_J);
    worst = std::max(worst, (energy_J() - budget_J) / std::max({before_J, budget_J, 1e-12}));
  }
  return worst;
}

// Backward Euler linearises the springs at the step's start. A 1000 N pull on
// the 0.1 m cantilever at dt = 1/30 s turns them far within one step: the
// step alone ended with 7.9x the work done on the body (measured before the
// guard; with the CG capped at one iteration and E = 1 kPa, 1.5e19x its
// budget at 1.43 s). The guard
// shortens the move and slows the nodes until no step holds more than it was
// given, and says how often it did.
TEST(Simulation, ImplicitStepsNeverEndWithMoreEnergyThanTheyWereGiven) {
  for (const int iterations : {1, 100}) {
    SCOPED_TRACE(::testing::Message() << "cg_max_iterations " << iterations);
    scene::Scene s = cantilever_scene();
    s.loads[0].total_force_N = {0, 0, -1000.0};
    s.integrator.dt_s = 1.0 / 30;
    s.integrator.cg_max_iterations = iterations;
    s.integrator.cg_preconditioner = scene::CgPreconditioner::kJacobi;
    Simulation sim(s);
    EXPECT_LE(worst_step_excess(sim, 45), 1e-8);
    EXPECT_GT(sim.counters().energy_limited_steps, 0);
    EXPECT_GT(sim.counters().energy_limited_J, 0.0);
    EXPECT_GT(sim.counters().external_work_J, 0.0);
  }
}

// The guard takes out about the excess, not much more: the first step of
// the 1000 N pull (7.9x its work before the guard) ends near its budget,
// the work done on the body in that step. (Halving the move alone, before
// the bisection, left a step 55 % under its budget.)
TEST(Simulation, TheEnergyGuardTakesOutAboutTheExcess) {
  scene::Scene s = cantilever_scene();
  s.loads[0].total_force_N = {0, 0, -1000.0};
  s.integrator.dt_s = 1.0 / 30;
  s.integrator.cg_preconditioner = scene::CgPreconditioner::kJacobi;
  Simulation sim(s);
  ASSERT_TRUE(sim.step().ok);
  ASSERT_EQ(sim.counters().energy_limited_steps, 1);
  const double energy_J = sim.kinetic_energy_J() + sim.elastic_energy_J(), work_J = sim.counters().external_work_J;
  EXPECT_LE(energy_J, work_J * (1 + 1e-8));
  EXPECT_GE(energy_J, 0.95 * work_J) << "took out " << sim.counters().energy_limited_J << " J";
}

// With a prescribed node (contact.yaml's poke, one CG iteration at 1/30 s)
// the budget holds the drivers' work, which depends on the dampers at the
// driven node, hence on the velocities the guard scales (the guard takes it
// again after scaling): every step stays within the work as booked.
TEST(Simulation, TheEnergyGuardHoldsWithPrescribedNodes) {
  scene::Scene s = cantilever_scene();
  s.loads.clear();
  scene::PrescribedSpec poke{"poke", sphere({0.1, 0.05, 0.05}, 1e-4), {0, 0, -0.01}, {}};
  poke.profile.ramp_s = 0.5;
  s.prescribed.push_back(poke);
  s.integrator.dt_s = 1.0 / 30;
  s.integrator.cg_max_iterations = 1;
  s.integrator.cg_preconditioner = scene::CgPreconditioner::kJacobi;
  Simulation sim(s);
  EXPECT_LE(worst_step_excess(sim, 30), 1e-8);
  EXPECT_GT(sim.counters().energy_limited_steps, 0);
  EXPECT_GT(sim.counters().prescribed_work_J, 0.0);
}

// The guard is for the steps the linearisation gets wrong: the shipped
// cantilever's load and release (dt = 1 ms) and the loaded beam never need it.
TEST(Simulation, TheEnergyGuardLeavesOrdinaryImplicitStepsAlone) {
  for (const scene::Scene& s : {cantilever_scene(0.3), beam_scene()}) {
    Simulation sim(s);
    EXPECT_LE(worst_step_excess(sim, 500), 1e-9) << s.name;
    EXPECT_EQ(sim.counters().energy_limited_steps, 0) << s.name;
    EXPECT_EQ(sim.counters().energy_limited_J, 0.0) << s.name;
  }
}

// adaptivity.max_tets stops the splits (a threshold far below every tet's
// density and a deep max_depth doubled the mesh each pass until the process
// ran out of memory); a pass's last split may pass it by its closure.
TEST(Simulation, RefinementStopsAtTheTetCeiling) {
  scene::Scene s = cantilever_scene();
  s.adaptivity.every_steps = 1;
  s.adaptivity.max_tets = 500;
  Simulation sim(s);
  ASSERT_TRUE(run_until(sim, 0.15));
  EXPECT_GT(sim.counters().refine_ceiling_passes, 0);
  EXPECT_GE(sim.counters().peak_tets, 500u);
  EXPECT_LT(sim.counters().peak_tets, 600u);
  s.adaptivity.max_tets = scene::AdaptivitySpec{}.max_tets;  // the default does not bind here
  Simulation free(s);
  ASSERT_TRUE(run_until(free, 0.15));
  EXPECT_EQ(free.counters().refine_ceiling_passes, 0);
  EXPECT_GT(free.counters().peak_tets, 1000u);
}

// By default (cg_preconditioner: auto) an adaptive mesh that grows past
// kAutoTwoLevelUnknowns free nodes changes to the two-level preconditioner at
// the next mesh change: the cantilever refining to depth 5 under its load.
TEST(Simulation, AutoPreconditionerChangesAsTheMeshGrows) {
  scene::Scene s = cantilever_scene();
  s.adaptivity.max_depth = 5;
  s.adaptivity.refine_threshold_Pa = 5.0;
  ASSERT_EQ(s.integrator.cg_preconditioner, scene::CgPreconditioner::kAuto);  // the default
  Simulation sim(s);
  const auto& implicit = dynamic_cast<const ImplicitIntegrator&>(sim.integrator());
  ASSERT_TRUE(sim.step().ok);
  EXPECT_FALSE(implicit.two_level());  // 125 nodes
  bool changed = false;
  for (int i = 0; i < 400 && !changed; ++i) {
    const StepResult r = sim.step();
    ASSERT_TRUE(r.ok) << r.error;
    changed = implicit.two_level();
  }
  ASSERT_TRUE(changed) << "still Jacobi at " << sim.body().mesh().node_count() << " nodes";
  EXPECT_GE(free_node_count(sim.body()), ImplicitIntegrator::kAutoTwoLevelUnknowns);
}

TEST(Simulation, ProbeOutsideTheObjectIsRejected) {
  scene::Scene s = beam_scene();
  s.probes.push_back({"lost", {1.0, 0.05, 0.05}});
  try {
    Simulation sim(s);
    FAIL() << "a probe outside the object must be rejected";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("lost"), std::string::npos);
  }
}

// A free cube with a tool, no gravity, explicit (momentum to rounding).
scene::Scene free_cube_with_tool() {
  scene::Scene s = testing::free_cube_scene(2, 0);
  s.tool = scene::ToolSpec{};
  s.adaptivity.enabled = true;  // for split_diamond / merge_diamond
  s.adaptivity.every_steps = 1000;
  s.integrator.kind = scene::IntegratorKind::kExplicit;
  return s;
}

// The tool's force is shared by the weights normalised to sum 1: the body
// receives the whole force, no more. On a free body the momentum it gains
// over a step is exactly force · dt.
TEST(SimulationTool, TheBodyReceivesTheWholeToolForceWhateverTheWeightsSum) {
  Simulation sim(free_cube_with_tool());
  const Vec3 force_N(0.0, 0.0, -0.5);
  ASSERT_LT(force_N.norm(), sim.scene().tool->max_force_N);
  ASSERT_TRUE(sim.set_tool_force({0, 1, 2}, {1, 1, 2}, force_N));
  const Vec3 p0 = sim.body().momentum_kg_m_per_s();
  ASSERT_TRUE(sim.step().ok);
  const Vec3 gained = sim.body().momentum_kg_m_per_s() - p0;
  EXPECT_LT((gained - sim.scene().integrator.dt_s * force_N).norm(),
            1e-12 * sim.scene().integrator.dt_s * force_N.norm())
      << gained.transpose();
}

// Barycentric weights on the touched triangle are never negative: a negative
// one (normalised with the rest) would push one node harder than
// tool.max_force_N and pull another back. Refused, nothing applied.
TEST(SimulationTool, ANegativeWeightIsRefused) {
  Simulation sim(free_cube_with_tool());
  EXPECT_FALSE(sim.set_tool_force({0, 1, 2}, {2, -1, 0}, Vec3(0, 0, -0.5)));
  EXPECT_EQ(sim.tool_force_N(), Vec3::Zero());
}

// A node the tool pushes on that merges away releases the tool (its id may
// be reused by another node anywhere in the body).
TEST(SimulationTool, MergingAwayAToolNodeReleasesTheTool) {
  Simulation sim(free_cube_with_tool());
  const mesh::Key d = sim.body().mesh().diamond_of(0);
  ASSERT_EQ(sim.split_diamond(d), 1);
  const NodeId z = sim.body().mesh().find_node(d);
  ASSERT_TRUE(sim.set_tool_force({z, z, z}, {1, 0, 0}, Vec3(0, 0, -0.5)));
  ASSERT_NE(sim.tool_force_N(), Vec3::Zero());
  sim.merge_diamond(d);
  EXPECT_EQ(sim.tool_force_N(), Vec3::Zero());
  // A tool on nodes that survive the merge stays.
  ASSERT_EQ(sim.split_diamond(d), 1);
  ASSERT_TRUE(sim.set_tool_force({0, 1, 2}, {1, 0, 0}, Vec3(0, 0, -0.5)));
  sim.merge_diamond(d);
  EXPECT_NE(sim.tool_force_N(), Vec3::Zero());
}

// A surface load is shared anew after every mesh change: when a loaded node
// merges away, its share goes to the nodes that remain, so a free body still
// gains exactly load · dt of momentum per step.
TEST(Simulation, ALoadKeepsItsResultantWhenALoadedNodeMergesAway) {
  scene::Scene s = testing::free_cube_scene(2, 2);  // face centres are nodes
  s.adaptivity.enabled = true;
  s.adaptivity.max_depth = 3;
  s.adaptivity.every_steps = 1000;
  s.integrator.kind = scene::IntegratorKind::kExplicit;
  const Vec3 load_N(0.0, 0.0, -1.0);
  s.loads.push_back({"push", testing::box({0.1, 0, 0}, {0.1, 0.1, 0.1}), {load_N.x(), load_N.y(), load_N.z()}, {}});
  Simulation sim(s);
  // The centre of the loaded face of the cube at x in [h, 2h], y, z in [0, h].
  const std::int64_t h = sim.body().mesh().domain().coarse_cube();
  const mesh::Key face_centre = mesh::vertex_key({2 * h, h / 2, h / 2});
  ASSERT_NE(sim.body().mesh().find_node(face_centre), mesh::kInvalidId);
  sim.merge_diamond(face_centre);
  ASSERT_FALSE(sim.body().mesh().is_split(face_centre));
  const Vec3 p0 = sim.body().momentum_kg_m_per_s();
  ASSERT_TRUE(sim.step().ok);
  const double dt = s.integrator.dt_s;
  EXPECT_LT((sim.body().momentum_kg_m_per_s() - p0 - dt * load_N).norm(), 1e-12 * dt * load_N.norm());
}

}  // namespace
}  // namespace tissue::physics
