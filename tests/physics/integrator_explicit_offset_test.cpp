// The explicit sub-steps on the offset layout (integrator_explicit_offset.cpp).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "physics/forces.hpp"
#include "physics/integrator.hpp"
#include "physics/integrator_impl.hpp"
#include "physics/physics_test_support.hpp"

namespace tissue::physics {
namespace {

using testing::beam_scene;
using testing::free_cube_scene;
using testing::jiggled_beam;
using testing::randomly_refined_beam;
using Layout = ExplicitIntegrator::Layout;

Body uniform_beam(int depth, bool damped = true) {
  scene::Scene s = beam_scene();
  s.adaptivity.min_depth = depth;
  if (!damped) s.material.rayleigh_beta_s = 0.0;
  return Body(s);
}

void jiggle(Body& body, std::uint32_t seed) { testing::jiggle_free_nodes(body, seed, 0.003, 0.1); }

// Every spring with a free end sits in exactly one lane, and that lane joins
// the positions of its two nodes; positions are a permutation of the live
// nodes; batches sharing a0 form one group; the stride leaves room for a
// whole vector past the last node.
TEST(OffsetLayout, PlanHoldsEverySpringOnceInTheLaneOfItsNodes) {
  std::vector<Body> bodies;
  bodies.push_back(uniform_beam(3));
  bodies.push_back(randomly_refined_beam(7, 4));
  bodies.emplace_back(free_cube_scene(2, 0));
  for (const Body& body : bodies) {
    for (const int lanes : {4, 8}) {
      SCOPED_TRACE(lanes);
      const OffsetPlan plan = plan_offset_layout(body, lanes);
      ASSERT_EQ(plan.node_at.size(), body.mesh().node_count());
      std::vector<std::uint32_t> position(body.x_m.size(), ~0u);
      for (std::size_t p = 0; p < plan.node_at.size(); ++p) {
        ASSERT_TRUE(body.mesh().node(plan.node_at[p]).alive);
        ASSERT_EQ(position[plan.node_at[p]], ~0u) << "node placed twice";
        position[plan.node_at[p]] = static_cast<std::uint32_t>(p);
      }
      EXPECT_GE(plan.stride, plan.node_at.size() + lanes);
      EXPECT_EQ(plan.stride % lanes, 0u);
      std::multiset<EdgeId> seen;
      for (const OffsetPlan::Batch& batch : plan.batches) {
        EXPECT_EQ(batch.a0 % lanes, 0u);
        EXPECT_GT(batch.b0, batch.a0);
        for (int j = 0; j < lanes; ++j) {
          const EdgeId e = batch.edge[j];
          if (e == mesh::kInvalidId) continue;
          seen.insert(e);
          const std::set<std::uint32_t> ends = {position[body.edge_a[e]], position[body.edge_b[e]]};
          EXPECT_EQ(ends, (std::set<std::uint32_t>{batch.a0 + j, batch.b0 + j}));
        }
        for (int j = lanes; j < 8; ++j) EXPECT_EQ(batch.edge[j], mesh::kInvalidId);
      }
      const std::vector<EdgeId> moving = moving_springs(body);
      EXPECT_EQ(seen, std::multiset<EdgeId>(moving.begin(), moving.end()));
      EXPECT_DOUBLE_EQ(plan.fill, static_cast<double>(moving.size()) /
                                      (static_cast<double>(lanes) * static_cast<double>(plan.batches.size())));
      std::size_t covered = 0;
      for (std::size_t g = 0; g < plan.groups.size(); ++g) {
        const OffsetGroup& group = plan.groups[g];
        EXPECT_EQ(group.first, covered);
        ASSERT_GT(group.end, group.first);
        if (g > 0) {
          EXPECT_GT(group.a0, plan.groups[g - 1].a0);
        }
        for (std::uint32_t q = group.first; q < group.end; ++q) EXPECT_EQ(plan.batches[q].a0, group.a0);
        covered = group.end;
      }
      EXPECT_EQ(covered, plan.batches.size());
    }
  }
}

// A mesh of one depth is a lattice and fills most lanes (its rows split by
// parity, as the Kuhn split alternates between neighbouring cubes); the
// integrator takes the layout there and keeps the gathered stream on an
// adaptively refined mesh.
TEST(OffsetLayout, UniformMeshesTakeItAdaptiveOnesKeepTheGatheredStream) {
  const Body uniform = uniform_beam(3);
  EXPECT_TRUE(mesh_has_one_depth(uniform));
  EXPECT_GE(plan_offset_layout(uniform, 4).fill, ExplicitOffsetState<double>::kMinOffsetFill);
  EXPECT_GE(plan_offset_layout(uniform, 8).fill, ExplicitOffsetState<float>::kMinOffsetFill);
  Body refined = randomly_refined_beam(3, 4);
  EXPECT_FALSE(mesh_has_one_depth(refined));
  for (const auto precision : {scene::ExplicitPrecision::kDouble, scene::ExplicitPrecision::kFloat}) {
    scene::IntegratorSpec spec = uniform.scene().integrator;
    spec.explicit_precision = precision;
    Body copy = uniform;
    const std::vector<Vec3> no_force(copy.x_m.size(), Vec3::Zero());
    ExplicitIntegrator on_uniform(spec, copy.scene().material);
    on_uniform.run_substeps(copy, no_force, 1e-6, 1);
    EXPECT_TRUE(on_uniform.offset_layout());
    ExplicitIntegrator forced_gathered(spec, copy.scene().material);
    forced_gathered.set_layout(Layout::kGathered);
    forced_gathered.run_substeps(copy, no_force, 1e-6, 1);
    EXPECT_FALSE(forced_gathered.offset_layout());
    const std::vector<Vec3> no_force_refined(refined.x_m.size(), Vec3::Zero());
    ExplicitIntegrator on_refined(spec, refined.scene().material);
    on_refined.run_substeps(refined, no_force_refined, 1e-6, 1);
    EXPECT_FALSE(on_refined.offset_layout());
  }
}

// Spring forces recovered from one sub-step (v' − v = h w f on free nodes),
// layout forced.
std::vector<Vec3> substep_forces(const Body& body, scene::ExplicitPrecision precision, Layout layout, Simd simd,
                                 bool* took_offset) {
  scene::IntegratorSpec spec = body.scene().integrator;
  spec.explicit_precision = precision;
  Body copy = body;
  ExplicitIntegrator integrator(spec, body.scene().material, simd);
  integrator.set_layout(layout);
  const double h = 1e-6;
  integrator.run_substeps(copy, std::vector<Vec3>(body.x_m.size(), Vec3::Zero()), h, 1);
  *took_offset = integrator.offset_layout();
  std::vector<Vec3> f(body.x_m.size(), Vec3::Zero());
  for (std::size_t n = 0; n < f.size(); ++n)
    if (body.inv_mass_per_kg[n] != 0.0) f[n] = (copy.v_m_per_s[n] - body.v_m_per_s[n]) / (h * body.inv_mass_per_kg[n]);
  return f;
}

// The layout's forces are the springs' and dampers' (add_spring_forces), on
// stretched, compressed and collapsed springs (jiggled_beam has one), on a
// lattice and on an irregular mesh, in both precisions.
TEST(OffsetLayout, ForcesAreTheReferenceForces) {
  for (const bool damped : {true, false}) {
    std::vector<Body> bodies;
    bodies.push_back(jiggled_beam(19, damped));
    bodies.push_back(randomly_refined_beam(11, 4));
    scene::Scene cube = free_cube_scene(2, 0);  // short rows: offsets below the lane count, δ = 1 among them
    cube.material.rayleigh_beta_s = 0.002;
    bodies.emplace_back(cube);
    for (std::size_t i = 1; i < bodies.size(); ++i) {
      if (!damped) std::fill(bodies[i].damping_N_s_per_m.begin(), bodies[i].damping_N_s_per_m.end(), 0.0);
      jiggle(bodies[i], 5 + static_cast<std::uint32_t>(i));
    }
    for (const Body& body : bodies) {
      std::vector<Vec3> reference(body.x_m.size(), Vec3::Zero());
      add_spring_forces(body, reference);
      double scale = 0.0;
      for (std::size_t n = 0; n < reference.size(); ++n)
        if (body.inv_mass_per_kg[n] != 0.0) scale = std::max(scale, reference[n].cwiseAbs().maxCoeff());
      ASSERT_GT(scale, 0.0);
      for (const auto precision : {scene::ExplicitPrecision::kDouble, scene::ExplicitPrecision::kFloat}) {
        SCOPED_TRACE(std::string(damped ? "damped " : "undamped ") +
                     (precision == scene::ExplicitPrecision::kFloat ? "float" : "double"));
        bool offset = false;
        const std::vector<Vec3> f = substep_forces(body, precision, Layout::kOffset, detected_simd(), &offset);
        ASSERT_TRUE(offset);
        // Recovering f from v' − v costs digits in double (1e-6 h); float
        // carries 7 digits of the displacements.
        const double tolerance = precision == scene::ExplicitPrecision::kFloat ? 2e-5 : 1e-6;
        for (std::size_t n = 0; n < f.size(); ++n) {
          if (body.inv_mass_per_kg[n] != 0.0) {
            EXPECT_LE((f[n] - reference[n]).cwiseAbs().maxCoeff(), tolerance * scale) << "node " << n;
          }
        }
      }
    }
  }
}

// Scalar and AVX2 kernels of the layout give the same bits over many
// sub-steps, with dampers and mass damping, a collapsed spring (rest-
// direction fallback), a near-collapsed one (float's scalar lanes) and
// irregular offsets, among them δ = 1 (the rotated x-springs).
TEST(OffsetLayout, TrajectoryIsBitIdenticalAcrossInstructionSets) {
  if (detected_simd() == Simd::kScalar) GTEST_SKIP() << "no AVX2 on this CPU: only the scalar kernel exists";
  std::vector<Body> bodies;
  bodies.push_back(jiggled_beam(23));
  bodies.push_back(randomly_refined_beam(13, 4));
  jiggle(bodies.back(), 9);
  {
    scene::Scene s = free_cube_scene(2, 0);
    s.material.rayleigh_beta_s = 0.002;
    s.material.rayleigh_alpha_per_s = 3.0;
    bodies.emplace_back(s);
    jiggle(bodies.back(), 3);
  }
  bool rotated = false;
  for (Body& body : bodies) {
    for (const int lanes : {4, 8})
      for (const OffsetPlan::Batch& batch : plan_offset_layout(body, lanes).batches)
        rotated = rotated || batch.b0 == batch.a0 + 1;
    // A near-collapsed spring: its b end at 0.5 % of the rest length from a.
    bool placed = false;
    body.mesh().for_each_edge([&](EdgeId e, const mesh::Edge& edge) {
      if (placed || body.inv_mass_per_kg[edge.b] == 0.0 || body.inv_mass_per_kg[edge.a] == 0.0) return;
      body.x_m[edge.b] = body.x_m[edge.a] + 0.005 * (body.rest_m[edge.b] - body.rest_m[edge.a]);
      placed = true;
      (void)e;
    });
    ASSERT_TRUE(placed);
    for (const auto precision : {scene::ExplicitPrecision::kDouble, scene::ExplicitPrecision::kFloat}) {
      SCOPED_TRACE(precision == scene::ExplicitPrecision::kFloat ? "float" : "double");
      scene::IntegratorSpec spec = body.scene().integrator;
      spec.explicit_precision = precision;
      std::vector<std::vector<Vec3>> x, v;
      for (const Simd simd : {Simd::kScalar, Simd::kAvx2}) {
        Body copy = body;
        ExplicitIntegrator integrator(spec, body.scene().material, simd);
        integrator.set_layout(Layout::kOffset);
        const std::vector<Vec3> f(copy.x_m.size(), Vec3(0, 0, -1e-3));
        integrator.run_substeps(copy, f, 0.2 * explicit_stable_dt_s(body), 30);
        ASSERT_TRUE(integrator.offset_layout());
        ASSERT_TRUE(state_is_finite(copy));
        x.push_back(copy.x_m);
        v.push_back(copy.v_m_per_s);
      }
      EXPECT_EQ(x[0], x[1]);
      EXPECT_EQ(v[0], v[1]);
    }
  }
  EXPECT_TRUE(rotated) << "no mesh here exercises the δ = 1 rotation";
}

// Whole steps on the layout follow the gathered stream's trajectory to
// rounding (the summation order into the nodes differs), under a load, with
// the integrator's automatic sub-steps.
TEST(OffsetLayout, StepsFollowTheGatheredTrajectory) {
  for (const auto precision : {scene::ExplicitPrecision::kDouble, scene::ExplicitPrecision::kFloat}) {
    SCOPED_TRACE(precision == scene::ExplicitPrecision::kFloat ? "float" : "double");
    Body start = uniform_beam(3);
    scene::IntegratorSpec spec = start.scene().integrator;
    spec.explicit_precision = precision;
    std::vector<Vec3> load(start.x_m.size(), Vec3::Zero());
    start.mesh().for_each_node([&](NodeId n, const mesh::Node&) {
      if (start.rest_m[n].x() > 0.399) load[n] = Vec3(0, 0, -0.01);
    });
    std::vector<std::vector<Vec3>> finals;
    for (const Layout layout : {Layout::kOffset, Layout::kGathered}) {
      Body body = start;
      ExplicitIntegrator integrator(spec, body.scene().material);
      integrator.set_layout(layout);
      for (int i = 0; i < 50; ++i) ASSERT_TRUE(integrator.step(body, load, 1e-3).ok);
      EXPECT_EQ(integrator.offset_layout(), layout == Layout::kOffset);
      finals.push_back(body.x_m);
    }
    double moved = 0.0, apart = 0.0;
    for (std::size_t n = 0; n < start.x_m.size(); ++n) {
      moved = std::max(moved, (finals[1][n] - start.x_m[n]).norm());
      apart = std::max(apart, (finals[0][n] - finals[1][n]).norm());
    }
    ASSERT_GT(moved, 1e-5);
    EXPECT_LE(apart, (precision == scene::ExplicitPrecision::kFloat ? 1e-5 : 1e-10) * moved);
  }
}

// The largest relative displacement of a spring's ends (the deformed
// stiffness bound's r) is the same from the scalar and AVX2 passes, in both
// precisions, and matches the body's own springs.
TEST(OffsetLayout, EndDisplacementRatioIsTheBodysAndTheSameOnEitherInstructionSet) {
  Body body = uniform_beam(3);
  jiggle(body, 5);
  double expected = 0.0;
  for (std::size_t e = 0; e < body.edge_a.size(); ++e)
    if (body.stiffness_N_per_m[e] > 0.0 &&
        (body.inv_mass_per_kg[body.edge_a[e]] > 0.0 || body.inv_mass_per_kg[body.edge_b[e]] > 0.0))
      expected = std::max(expected, ((body.x_m[body.edge_b[e]] - body.rest_m[body.edge_b[e]]) -
                                     (body.x_m[body.edge_a[e]] - body.rest_m[body.edge_a[e]]))
                                            .norm() /
                                        body.rest_length_m[e]);
  ASSERT_GT(expected, 0.01);
  const std::vector<Vec3> f(body.x_m.size(), Vec3::Zero());
  ExplicitOffsetState<double> d;
  ASSERT_TRUE(d.build(body, true));
  d.load(body, f);
  ExplicitOffsetState<float> s;
  ASSERT_TRUE(s.build(body, true));
  s.load(body, f);
  EXPECT_NEAR(d.end_displacement_ratio(Simd::kScalar), expected, 1e-12 * expected);
  EXPECT_NEAR(s.end_displacement_ratio(Simd::kScalar), expected, 1e-5 * expected);
  if (detected_simd() == Simd::kAvx2) {
    EXPECT_EQ(d.end_displacement_ratio(Simd::kAvx2), d.end_displacement_ratio(Simd::kScalar));
    EXPECT_EQ(s.end_displacement_ratio(Simd::kAvx2), s.end_displacement_ratio(Simd::kScalar));
  }
  // Measured inside a sub-step's force pass (one sub-step: the loaded
  // state's forces), damped and undamped kernels, either instruction set:
  // the same value as the pass of its own.
  const auto in_pass_and_alone = [&](auto state, const Body& b, Simd simd) {
    EXPECT_TRUE(state.build(b, true));
    state.load(b, f);
    const double alone = state.end_displacement_ratio(simd);
    double in_pass = -1.0;
    state.substeps(simd, 1e-6, 0.0, 1, &in_pass);
    return std::make_pair(in_pass, alone);
  };
  for (const bool damped : {true, false}) {
    Body b = uniform_beam(3, damped);
    jiggle(b, 5);
    for (const Simd simd : {Simd::kScalar, detected_simd()}) {
      const auto [in_pass_d, alone_d] = in_pass_and_alone(ExplicitOffsetState<double>{}, b, simd);
      EXPECT_EQ(in_pass_d, alone_d) << "damped " << damped;
      EXPECT_NEAR(in_pass_d, expected, 1e-12 * expected);
      const auto [in_pass_s, alone_s] = in_pass_and_alone(ExplicitOffsetState<float>{}, b, simd);
      EXPECT_EQ(in_pass_s, alone_s) << "damped " << damped;
    }
  }
}

// On the offset layout a verified step's r is measured at the last
// sub-step's forces, i.e. at that sub-step's start: its move is in
// r_rise_bound, so r plus the bound covers the state the step reached (it
// was set to 0 there, the last sub-step's move unseen). A tip load from
// rest: r rises at every sub-step.
TEST(OffsetLayout, AVerifiedStepsRiseBoundCoversItsLastSubstep) {
  Body body = uniform_beam(3);
  std::vector<Vec3> load(body.x_m.size(), Vec3::Zero());
  body.mesh().for_each_node([&](NodeId n, const mesh::Node&) {
    if (body.rest_m[n].x() > 0.399) load[n] = Vec3(0, 0, -0.01);
  });
  ExplicitIntegrator integrator(body.scene().integrator, body.scene().material);
  integrator.set_layout(Layout::kOffset);
  std::int64_t verified = 0;
  for (int i = 0; i < 50; ++i) {
    const StepOutcome out = integrator.step(body, load, 1e-3);
    ASSERT_TRUE(out.ok) << out.error;
    ASSERT_TRUE(integrator.offset_layout());
    double reached = 0.0;
    for (std::size_t e = 0; e < body.edge_a.size(); ++e)
      if (body.stiffness_N_per_m[e] > 0.0 &&
          (body.inv_mass_per_kg[body.edge_a[e]] > 0.0 || body.inv_mass_per_kg[body.edge_b[e]] > 0.0))
        reached = std::max(reached, ((body.x_m[body.edge_b[e]] - body.rest_m[body.edge_b[e]]) -
                                     (body.x_m[body.edge_a[e]] - body.rest_m[body.edge_a[e]]))
                                            .norm() /
                                        body.rest_length_m[e]);
    if (out.verified_substeps) ++verified;
    EXPECT_LE(reached, integrator.end_displacement_ratio() + integrator.r_rise_bound())
        << "step " << i << (out.verified_substeps ? " (verified)" : "");
  }
  EXPECT_GT(verified, 0);
}

// A state gone non-finite (or past the finiteness limit: 1e150 N is finite
// in double) on the layout is rejected and the body kept.
TEST(OffsetLayout, NonFiniteStepIsRejectedAndTheStateKept) {
  for (const auto precision : {scene::ExplicitPrecision::kDouble, scene::ExplicitPrecision::kFloat})
    for (const double bad_N :
         {std::numeric_limits<double>::infinity(), std::numeric_limits<double>::quiet_NaN(), 1e150}) {
      Body body = uniform_beam(2);
      scene::IntegratorSpec spec = body.scene().integrator;
      spec.explicit_precision = precision;
      ExplicitIntegrator integrator(spec, body.scene().material);
      integrator.set_layout(Layout::kOffset);
      std::vector<Vec3> f(body.x_m.size(), Vec3::Zero());
      NodeId free_node = mesh::kInvalidId;
      body.mesh().for_each_node([&](NodeId n, const mesh::Node&) {
        if (body.inv_mass_per_kg[n] != 0.0) free_node = n;
      });
      ASSERT_NE(free_node, mesh::kInvalidId);
      f[free_node] = Vec3(0, bad_N, 0);
      const std::vector<Vec3> before = body.x_m;
      const StepOutcome out = integrator.step(body, f, 1e-3);
      EXPECT_FALSE(out.ok);
      EXPECT_NE(out.error.find("non-finite"), std::string::npos) << out.error;
      EXPECT_EQ(body.x_m, before);
      EXPECT_TRUE(integrator.offset_layout());
    }
}

}  // namespace
}  // namespace tissue::physics
