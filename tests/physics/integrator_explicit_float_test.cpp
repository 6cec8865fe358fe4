// The explicit rung in single precision (integrator.explicit_precision: float).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

#include "physics/forces.hpp"
#include "physics/integrator.hpp"
#include "physics/integrator_impl.hpp"
#include "physics/physics_test_support.hpp"

namespace tissue::physics {
namespace {

using testing::beam_scene;
using testing::jiggled_beam;

// Forces of the body's springs from the float stream at its displacements
// and velocities, by node id.
std::vector<Vec3> float_forces(const Body& body, Simd simd, bool with_velocities) {
  ExplicitFloatState state;
  state.build(body);
  const std::size_t nodes = body.x_m.size();
  std::vector<Pad3f> u(nodes + 2), v(nodes + 2), f(nodes + 2);
  for (std::size_t n = 0; n < nodes; ++n)
    for (int k = 0; k < 3; ++k) {
      u[n].v[k] = static_cast<float>(body.x_m[n][k] - body.rest_m[n][k]);
      v[n].v[k] = static_cast<float>(body.v_m_per_s[n][k]);
    }
  explicit_spring_forces_float(simd, state.stream().data(), state.stream().size(), u.data(),
                               with_velocities ? v.data() : nullptr, f.data());
  std::vector<Vec3> out(nodes);
  for (std::size_t n = 0; n < nodes; ++n) out[n] = Vec3(f[n].v[0], f[n].v[1], f[n].v[2]);
  return out;
}

// The float stream's forces against the double reference (add_spring_forces)
// on a jiggled beam, stretched, compressed and with one collapsed spring: the
// same to float precision, with dampers and without.
TEST(ExplicitFloat, ForcesMatchTheDoubleReference) {
  for (const bool damped : {true, false}) {
    SCOPED_TRACE(damped ? "damped" : "undamped");
    const Body body = jiggled_beam(19, damped);
    std::vector<Vec3> reference(body.x_m.size(), Vec3::Zero());
    add_spring_forces(body, reference);
    const std::vector<Vec3> f = float_forces(body, detected_simd(), damped);
    double scale = 0.0;
    for (std::size_t n = 0; n < f.size(); ++n)
      if (body.inv_mass_per_kg[n] != 0.0) scale = std::max(scale, reference[n].cwiseAbs().maxCoeff());
    ASSERT_GT(scale, 0.0);
    for (std::size_t n = 0; n < f.size(); ++n)
      if (body.inv_mass_per_kg[n] != 0.0) {
        EXPECT_LE((f[n] - reference[n]).cwiseAbs().maxCoeff(), 2e-6 * scale) << "node " << n;
      }
  }
}

// Random springs (shared nodes, one collapsed, one near collapse, padding):
// the same bits from both instruction sets, damped and undamped, and the
// undamped kernel gives the damped one's result at c = 0.
TEST(ExplicitFloat, ForceInstructionSetsAreBitIdentical) {
  if (detected_simd() == Simd::kScalar) GTEST_SKIP() << "no AVX2 on this CPU: only the scalar kernel exists";
  std::mt19937 rng(31);
  std::uniform_real_distribution<float> r(-1.0f, 1.0f);
  constexpr std::uint32_t kNodes = 200;
  std::vector<Pad3f> u(kNodes), v(kNodes);
  for (std::uint32_t i = 0; i < kNodes; ++i) {
    u[i] = Pad3f{{0.1f * r(rng), 0.1f * r(rng), 0.1f * r(rng), 0.0f}};
    v[i] = Pad3f{{r(rng), r(rng), r(rng), 0.0f}};
  }
  std::uniform_int_distribution<std::uint32_t> node(0, kNodes - 1);
  std::vector<ExplicitSpringBatchF> batches(150);
  for (auto& b : batches)
    for (int j = 0; j < 8; ++j) {
      b.a4[j] = 4 * node(rng);
      b.b4[j] = 4 * node(rng);
      b.ex[j] = r(rng);
      b.ey[j] = r(rng);
      b.ez[j] = r(rng);
      b.rest_m[j] = std::sqrt((b.ex[j] * b.ex[j] + b.ey[j] * b.ey[j]) + b.ez[j] * b.ez[j]);
      b.k_N_per_m[j] = 100.0f * std::abs(r(rng));
      b.c_N_s_per_m[j] = std::abs(r(rng));
    }
  // Spring (7, 2) joins nodes 0 and 1 with u1 − u0 = −e: collapsed; spring
  // (9, 5) joins 2 and 3 at 0.5 % of its rest length: near collapse.
  batches[7].a4[2] = 0;
  batches[7].b4[2] = 4;
  for (int k = 0; k < 3; ++k)
    u[1].v[k] = u[0].v[k] - (k == 0 ? batches[7].ex[2] : k == 1 ? batches[7].ey[2] : batches[7].ez[2]);
  batches[9].a4[5] = 8;
  batches[9].b4[5] = 12;
  for (int k = 0; k < 3; ++k)
    u[3].v[k] = u[2].v[k] - 0.995f * (k == 0 ? batches[9].ex[5] : k == 1 ? batches[9].ey[5] : batches[9].ez[5]);
  for (const bool damped : {true, false}) {
    std::vector<Pad3f> scalar(kNodes), avx(kNodes);
    const Pad3f* vel = damped ? v.data() : nullptr;
    explicit_spring_forces_float(Simd::kScalar, batches.data(), batches.size(), u.data(), vel, scalar.data());
    explicit_spring_forces_float(Simd::kAvx2, batches.data(), batches.size(), u.data(), vel, avx.data());
    for (std::uint32_t i = 0; i < kNodes; ++i)
      for (int k = 0; k < 4; ++k) ASSERT_EQ(scalar[i].v[k], avx[i].v[k]) << "node " << i << " lane " << k;
    for (std::uint32_t i = 0; i < kNodes; ++i)
      for (int k = 0; k < 3; ++k) ASSERT_TRUE(std::isfinite(scalar[i].v[k])) << "node " << i;
  }
  std::vector<Pad3f> damped_zero(kNodes), undamped(kNodes);
  for (auto& b : batches)
    for (float& c : b.c_N_s_per_m) c = 0.0f;
  explicit_spring_forces_float(Simd::kAvx2, batches.data(), batches.size(), u.data(), v.data(), damped_zero.data());
  explicit_spring_forces_float(Simd::kAvx2, batches.data(), batches.size(), u.data(), nullptr, undamped.data());
  for (std::uint32_t i = 0; i < kNodes; ++i)
    for (int k = 0; k < 4; ++k) ASSERT_EQ(damped_zero[i].v[k], undamped[i].v[k]) << "node " << i << " lane " << k;
}

// A spring at rest has exactly zero force in float: L is |e| as rounded.
TEST(ExplicitFloat, BodyAtRestFeelsNoForce) {
  scene::Scene s = beam_scene();
  s.adaptivity.min_depth = 2;
  const Body body(s);
  for (const Simd simd : {Simd::kScalar, detected_simd()})
    for (const Vec3& f : float_forces(body, simd, true)) ASSERT_EQ(f, Vec3::Zero());
}

// Whole runs: the beam swings under its tip load for 0.3 s on both paths;
// float tracks double to ~1e-6 of the deflection, bit-identically on both
// instruction sets, through a split made on the body; prescribed nodes land
// exactly where the double path puts them.
TEST(ExplicitFloat, TrajectoryTracksDoubleAndIsBitIdenticalAcrossInstructionSets) {
  scene::Scene s = beam_scene();
  s.integrator.kind = scene::IntegratorKind::kExplicit;
  s.adaptivity.enabled = true;
  s.adaptivity.min_depth = 1;
  s.adaptivity.max_depth = 2;
  s.prescribed.push_back({"corner", testing::sphere({0.4, 0.1, 0.1}, 1e-3), {0, 0.01, 0}, {}});
  std::vector<std::vector<Vec3>> finals;
  std::vector<double> tips;
  const auto run = [&](scene::ExplicitPrecision precision, Simd simd) {
    scene::Scene t = s;
    t.integrator.explicit_precision = precision;
    Body body(t);
    ExplicitIntegrator integrator(t.integrator, t.material, simd);
    for (int i = 0; i < 300; ++i) {
      if (i == 150) {  // the stream must follow the split
        bool done = false;
        body.mesh().for_each_tet([&](TetId tet, const mesh::Tet&) {
          if (!done && body.mesh().can_split(body.mesh().diamond_of(tet)))
            done = body.split(body.mesh().diamond_of(tet)) > 0;
        });
        ASSERT_TRUE(done);
      }
      std::vector<Vec3> f(body.x_m.size(), Vec3::Zero());
      body.mesh().for_each_node([&](NodeId n, const mesh::Node&) {
        if (body.rest_m[n].x() == 0.4) f[n] = Vec3(0, 0, -0.05 / 9.0);
        // The prescribed corner moves at a constant 1 cm/s.
        if (body.inv_mass_per_kg[n] == 0.0 && body.rest_m[n].x() > 0.0) body.v_m_per_s[n] = Vec3(0, 0.01, 0);
      });
      const StepOutcome out = integrator.step(body, f, 1e-3);
      ASSERT_TRUE(out.ok) << out.error;
    }
    finals.push_back(body.x_m);
    NodeId tip = 0;
    body.mesh().for_each_node([&](NodeId n, const mesh::Node&) {
      if ((body.rest_m[n] - Vec3(0.4, 0.05, 0.05)).norm() < 1e-9) tip = n;
    });
    tips.push_back((body.x_m[tip] - body.rest_m[tip]).norm());
  };
  run(scene::ExplicitPrecision::kDouble, detected_simd());
  run(scene::ExplicitPrecision::kFloat, Simd::kScalar);
  run(scene::ExplicitPrecision::kFloat, detected_simd());
  ASSERT_EQ(finals.size(), 3u);
  EXPECT_EQ(finals[1], finals[2]) << "scalar and AVX2 float runs differ";
  EXPECT_GT(tips[0], 5e-5);                       // it did move
  EXPECT_NEAR(tips[1], tips[0], 1e-6 * tips[0]);  // measured 8e-8
  // Prescribed (and fixed) nodes: exactly as in double.
  const Body shape(s);
  for (std::size_t n = 0; n < finals[0].size(); ++n)
    if (n < shape.inv_mass_per_kg.size() && shape.inv_mass_per_kg[n] == 0.0) {
      EXPECT_EQ(finals[1][n], finals[0][n]) << "kinematic node " << n;
    }
}

// Mass damping (material.rayleigh_alpha_per_s) divides a free node's
// velocity by 1 + h α each sub-step. Stiff bodies take short sub-steps, and
// in float 1 + h α was 1 for h α below 6e-8 (α dropped: a stiff cube drifting
// at 1 m/s, α 0.002/s, 51 sub-steps per 1 ms: no decay at all) and rounded
// to a multiple of 1.2e-7 above (α 0.01/s: 18% too strong). Even with the
// divisor exact, a velocity in float cannot move by less than half its last
// digit per sub-step. A drifting body whose springs stay at rest feels mass
// damping alone: float must decay it as double does, on both layouts, for
// h α from far below float's last digit to well above it.
TEST(ExplicitFloat, MassDampingDecaysAsInDoubleHoweverShortTheSubSteps) {
  scene::Scene s = testing::free_cube_scene(2, 1);
  s.integrator.kind = scene::IntegratorKind::kExplicit;
  s.material.rayleigh_beta_s = 0.0;  // no spring dampers: α alone
  const Vec3 v0_m_per_s(1.0, -0.5, 0.25);
  const double h_s = 1e-3 / 51;
  const int count = 51, steps = 40;
  for (const double h_alpha : {2e-9, 3.9e-8, 2e-7, 1e-6, 1e-5, 1e-4, 1e-3}) {
    s.material.rayleigh_alpha_per_s = h_alpha / h_s;
    for (const auto layout : {ExplicitIntegrator::Layout::kGathered, ExplicitIntegrator::Layout::kOffset}) {
      char trace[64];
      std::snprintf(trace, sizeof trace, "h alpha %g, %s layout", h_alpha,
                    layout == ExplicitIntegrator::Layout::kOffset ? "offset" : "gathered");
      SCOPED_TRACE(trace);
      std::vector<double> decay;  // 1 − |v| / |v0| of the slowest node: double, float
      for (const auto precision : {scene::ExplicitPrecision::kDouble, scene::ExplicitPrecision::kFloat}) {
        scene::Scene t = s;
        t.integrator.explicit_precision = precision;
        Body body(t);
        body.mesh().for_each_node([&](NodeId n, const mesh::Node&) { body.v_m_per_s[n] = v0_m_per_s; });
        ExplicitIntegrator integrator(t.integrator, t.material);
        integrator.set_layout(layout);
        const std::vector<Vec3> f(body.x_m.size(), Vec3::Zero());
        for (int i = 0; i < steps; ++i) integrator.run_substeps(body, f, h_s, count);
        double slowest = v0_m_per_s.norm(), fastest = 0.0;
        body.mesh().for_each_node([&](NodeId n, const mesh::Node&) {
          slowest = std::min(slowest, body.v_m_per_s[n].norm());
          fastest = std::max(fastest, body.v_m_per_s[n].norm());
        });
        EXPECT_LE(fastest - slowest, 1e-6 * (v0_m_per_s.norm() - slowest)) << "the body drifts as a whole";
        decay.push_back(1.0 - slowest / v0_m_per_s.norm());
      }
      const double exact = 1.0 - std::pow(1.0 + h_alpha, -count * steps);
      EXPECT_NEAR(decay[0], exact, 1e-6 * exact);
      EXPECT_NEAR(decay[1], decay[0], 2e-3 * decay[0]);
    }
  }
}

}  // namespace
}  // namespace tissue::physics
