// The implicit rung (integrator_implicit.cpp): its single-precision spring
// blocks against the full clamped Hessian, unit-scale independence, the
// matvec kernels and paths, the layout cache and the preconditioner choice.
// The two-level preconditioner itself: integrator_implicit_two_level_test.cpp.
#include <gtest/gtest.h>

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include "physics/body.hpp"
#include "physics/boundary.hpp"
#include "physics/forces.hpp"
#include "physics/integrator.hpp"
#include "physics/integrator_impl.hpp"
#include "physics/integrator_simd.hpp"
#include "physics/physics_test_support.hpp"

namespace tissue::physics {
namespace {

using testing::beam_scene;
using testing::jiggled_beam;
using testing::random_free_vector;

// A = M' + Σ (h c d̂d̂ᵀ + h² k [d̂d̂ᵀ + t (I − d̂d̂ᵀ)]) applied to p from the full
// 3x3 blocks at `state` (kinematic nodes excluded: their p must be zero).
// springs_part, when given: per node Σ |B| |p_a − p_b| over its springs (the
// size of what single-precision blocks can be off by, relative).
std::vector<Vec3> full_hessian_product(const Body& state, double h, double alpha_per_s, const std::vector<Vec3>& p,
                                       std::vector<double>* springs_part = nullptr) {
  std::vector<Vec3> reference(p.size());
  if (springs_part) springs_part->assign(p.size(), 0.0);
  for (std::size_t n = 0; n < p.size(); ++n) reference[n] = state.mass_kg[n] * (1.0 + h * alpha_per_s) * p[n];
  state.mesh().for_each_edge([&](EdgeId e, const mesh::Edge&) {
    const SpringFrame f = spring_frame(state, e);
    const Eigen::Matrix3d along = f.direction * f.direction.transpose();
    const double rest = state.rest_length_m[e];
    const double t = f.length_m > rest ? 1.0 - rest / f.length_m : 0.0;
    const Eigen::Matrix3d k = state.stiffness_N_per_m[e] * (along + t * (Eigen::Matrix3d::Identity() - along));
    const Eigen::Matrix3d block = h * state.damping_N_s_per_m[e] * along + h * h * k;
    const Vec3 dp = p[state.edge_a[e]] - p[state.edge_b[e]];
    const Vec3 q = block * dp;
    reference[state.edge_a[e]] += q;
    reference[state.edge_b[e]] -= q;
    if (springs_part) {
      const double size = block.norm() * dp.norm();
      (*springs_part)[state.edge_a[e]] += size;
      (*springs_part)[state.edge_b[e]] += size;
    }
  });
  return reference;
}

// The integrator's product equals the reference on free nodes within the
// rounding of its blocks to single precision (2^-22 of their size: e and
// iso each within 2^-24 relative) plus 1e-12 of the largest entry, and is
// zero on kinematic ones.
void expect_product_matches(ImplicitIntegrator& integrator, const Body& state, double h, double alpha_per_s,
                            const std::string& what) {
  const std::vector<Vec3> p = random_free_vector(state, 3);
  std::vector<double> springs_part;
  const std::vector<Vec3> reference = full_hessian_product(state, h, alpha_per_s, p, &springs_part);
  double scale = 0.0;
  for (std::size_t n = 0; n < p.size(); ++n)
    if (state.inv_mass_per_kg[n] != 0.0) scale = std::max(scale, reference[n].cwiseAbs().maxCoeff());
  std::vector<Vec3> y;
  integrator.system_product(p, y);
  ASSERT_EQ(y.size(), p.size());
  for (std::size_t n = 0; n < p.size(); ++n) {
    if (state.inv_mass_per_kg[n] == 0.0) {
      EXPECT_EQ(y[n], Vec3::Zero()) << "kinematic node " << n << " is not an unknown; " << what;
    } else {
      EXPECT_LE((y[n] - reference[n]).cwiseAbs().maxCoeff(), std::ldexp(springs_part[n], -22) + 1e-12 * scale)
          << "node " << n << "; " << what;
    }
  }
}

// The compact per-spring block (√along d̂, iso, in single precision) applies
// the full 3x3 blocks' operator within their rounding, with kinematic nodes
// not unknowns, for both matvec paths and both instruction sets; and the
// four apply the same stored blocks: they agree to 1e-12.
TEST(ImplicitIntegrator, CompactBlocksMatchTheFullClampedHessian) {
  for (const double h : {1e-3, 1e-2}) {
    std::vector<Vec3> first;
    for (const auto matvec :
         {ImplicitIntegrator::Matvec::kMatrixFree, ImplicitIntegrator::Matvec::kAssembledBlockCsr}) {
      for (const Simd simd : {Simd::kScalar, detected_simd()}) {
        Body body = jiggled_beam(7);
        const Body before = body;
        scene::MaterialSpec material = body.scene().material;
        material.rayleigh_alpha_per_s = 3.0;
        ImplicitIntegrator integrator(body.scene().integrator, material, matvec, simd);
        const std::vector<Vec3> no_force(body.x_m.size(), Vec3::Zero());
        ASSERT_TRUE(integrator.step(body, no_force, h).ok);
        const std::string what = "h " + std::to_string(h) + " simd " + std::to_string(static_cast<int>(simd));
        expect_product_matches(integrator, before, h, material.rayleigh_alpha_per_s, what);
        std::vector<Vec3> y;
        integrator.system_product(random_free_vector(before, 3), y);
        if (first.empty()) {
          first = y;
          continue;
        }
        double scale = 0.0;
        for (const Vec3& v : first) scale = std::max(scale, v.cwiseAbs().maxCoeff());
        for (std::size_t n = 0; n < y.size(); ++n)
          ASSERT_LE((y[n] - first[n]).cwiseAbs().maxCoeff(), 1e-12 * scale) << "node " << n << "; " << what;
      }
    }
  }
}

// The single-precision records are scaled by a power of two chosen per step,
// so no unit system over- or underflows them: a material 2^±400 (~10^±120)
// times stiffer and denser (the same dynamics) steps to the same bits, where
// unscaled blocks (e ~ 2^±200) would be beyond a float's 2^±128.
TEST(ImplicitIntegrator, StepDoesNotDependOnTheUnitsScale) {
  const auto run = [](double factor) {
    scene::Scene s = beam_scene();
    s.material.youngs_modulus_Pa *= factor;
    s.material.density_kg_per_m3 *= factor;
    s.material.rayleigh_alpha_per_s = 3.0;
    s.loads.clear();
    s.integrator.cg_tolerance = 1e-10;
    s.integrator.cg_max_iterations = 2000;
    Body body(s);
    testing::jiggle_free_nodes(body, 11, 0.005, 0.05);
    ImplicitIntegrator integrator(s.integrator, s.material);
    const std::vector<Vec3> no_force(body.x_m.size(), Vec3::Zero());
    for (int i = 0; i < 20; ++i) {
      const StepOutcome out = integrator.step(body, no_force, 2e-3);
      EXPECT_TRUE(out.ok && out.solver_converged) << "factor " << factor << " step " << i << ": " << out.error;
    }
    return body;
  };
  const Body unit = run(1.0);
  for (const double factor : {std::ldexp(1.0, 400), std::ldexp(1.0, -400)}) {
    const Body scaled = run(factor);
    for (std::size_t n = 0; n < unit.x_m.size(); ++n) {
      ASSERT_EQ(scaled.x_m[n], unit.x_m[n]) << "factor " << factor << " node " << n;
      ASSERT_EQ(scaled.v_m_per_s[n], unit.v_m_per_s[n]) << "factor " << factor << " node " << n;
    }
  }
}

// CG warm-starts from the last step's Δv only where that is nearer this
// step's solution than zero is (in the system's energy norm). Capped short of
// its tolerance, a stale guess used to be carried forward step after step: at
// 5 iterations and dt = 10 ms the loaded cantilever reached 1e17 J in 2 s
// (the integrator alone, without Simulation's energy guard). Now it stays
// near its converged bend.
TEST(ImplicitIntegrator, CappedCgDoesNotCarryAStaleWarmStartForward) {
  scene::Scene s = testing::cantilever_scene();
  s.adaptivity.enabled = false;
  s.integrator.cg_max_iterations = 5;
  s.integrator.cg_preconditioner = scene::CgPreconditioner::kJacobi;
  Body body(s);
  ImplicitIntegrator integrator(s.integrator, s.material);
  LoadDistribution loads;
  loads.rebuild(body);
  std::vector<Vec3> f_N;
  const double dt_s = 0.01;
  int unconverged = 0;
  double peak_m = 0.0, peak_energy_J = 0.0;
  for (int i = 0; i < 200; ++i) {
    loads.external_forces(body, (i + 1) * dt_s, f_N);  // 5 N until 1 s, then released
    const StepOutcome out = integrator.step(body, f_N, dt_s);
    ASSERT_TRUE(out.ok) << out.error;
    unconverged += out.solver_converged ? 0 : 1;
    for (std::size_t n = 0; n < body.x_m.size(); ++n) peak_m = std::max(peak_m, (body.x_m[n] - body.rest_m[n]).norm());
    peak_energy_J = std::max(peak_energy_J, kinetic_energy_J(body) + elastic_energy_J(body));
  }
  EXPECT_GT(unconverged, 100);  // the cap really bit
  // Converged, the coarse cantilever bends ~10 mm and stores ~20 mJ.
  EXPECT_LT(peak_m, 0.015);
  EXPECT_LT(peak_energy_J, 0.05);
}

// The AVX2 spring matvec sums in the scalar order without FMA: on random
// springs (including kinematic ends in the sink) both give the same bits.
TEST(ImplicitIntegrator, MatvecInstructionSetsAreBitIdentical) {
  if (detected_simd() == Simd::kScalar) GTEST_SKIP() << "no AVX2 on this CPU: only the scalar kernel exists";
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::uniform_real_distribution<float> uf(-1.0f, 1.0f);
  constexpr std::uint32_t kUnknowns = 300;  // + the sink
  std::vector<Pad3> p(kUnknowns + 1);
  for (std::uint32_t i = 0; i < kUnknowns; ++i) p[i] = Pad3{{u(rng), u(rng), u(rng), 0.0}};
  std::vector<ImplicitSpring> springs(2000);
  std::uniform_int_distribution<std::uint32_t> node(0, kUnknowns);  // kUnknowns = sink
  for (auto& s : springs) {
    s = {{uf(rng), uf(rng), uf(rng)}, std::abs(uf(rng)), 4 * node(rng), 4 * node(rng)};
  }
  std::vector<Pad3> scalar(kUnknowns + 1), avx(kUnknowns + 1);
  for (std::uint32_t i = 0; i < kUnknowns; ++i) scalar[i] = avx[i] = Pad3{{u(rng), u(rng), u(rng), 0.0}};
  implicit_spring_matvec(Simd::kScalar, springs.data(), springs.size(), p.data(), scalar.data());
  implicit_spring_matvec(Simd::kAvx2, springs.data(), springs.size(), p.data(), avx.data());
  for (std::uint32_t i = 0; i <= kUnknowns; ++i)
    for (int k = 0; k < 4; ++k) ASSERT_EQ(scalar[i].v[k], avx[i].v[k]) << "unknown " << i << " lane " << k;
}

// Whole trajectories: scalar and AVX2 kernels agree bit for bit, so batch
// reports do not depend on the CPU.
TEST(ImplicitIntegrator, TrajectoryDoesNotDependOnTheInstructionSet) {
  if (detected_simd() == Simd::kScalar) GTEST_SKIP() << "no AVX2 on this CPU: only the scalar kernel exists";
  scene::Scene s = beam_scene();
  s.integrator.cg_tolerance = 1e-300;
  s.integrator.cg_max_iterations = 20;
  std::vector<std::vector<Vec3>> finals;
  for (const Simd simd : {Simd::kScalar, Simd::kAvx2}) {
    Body body = jiggled_beam(13);
    ImplicitIntegrator integrator(s.integrator, s.material, ImplicitIntegrator::Matvec::kMatrixFree, simd);
    std::vector<Vec3> f(body.x_m.size(), Vec3(0, 0, -1e-3));
    for (int i = 0; i < 30; ++i) ASSERT_TRUE(integrator.step(body, f, 1e-3).ok);
    finals.push_back(body.x_m);
  }
  EXPECT_EQ(finals[0], finals[1]);
}

// The integrator caches its unknown numbering and spring list per mesh
// topology (Body::parameters_version): a split made directly on the body,
// with no mesh_changed() call, is still picked up by the next step.
TEST(ImplicitIntegrator, LayoutFollowsMeshChangesWithoutNotice) {
  scene::Scene s = beam_scene();
  s.adaptivity.enabled = true;
  s.adaptivity.min_depth = 1;
  s.adaptivity.max_depth = 2;
  Body body(s);
  ImplicitIntegrator integrator(body.scene().integrator, body.scene().material);
  std::vector<Vec3> f(body.x_m.size(), Vec3(0, 0, -1e-2));
  ASSERT_TRUE(integrator.step(body, f, 1e-3).ok);
  const std::uint64_t version = body.parameters_version();
  int splits = 0;
  body.mesh().for_each_tet([&](TetId t, const mesh::Tet&) {
    if (splits == 0 && body.mesh().can_split(body.mesh().diamond_of(t))) splits = body.split(body.mesh().diamond_of(t));
  });
  ASSERT_GT(splits, 0);
  EXPECT_NE(body.parameters_version(), version);
  f.assign(body.x_m.size(), Vec3(0, 0, -1e-2));
  const Body before = body;
  ASSERT_TRUE(integrator.step(body, f, 1e-3).ok);
  expect_product_matches(integrator, before, 1e-3, body.scene().material.rayleigh_alpha_per_s, "after a split");
}

// The CG warm start is kept by node id across mesh changes, and KuhnMesh
// reuses a merged node's id for the next split's node. That node must start
// CG from zero, as a node with a new id does, not from the Δv of the node
// that merged away somewhere else. Two runs reach the same body: a merge then
// a split that reuses the merged node's id, and the split first (a new id),
// then the merge. With the CG capped short of its tolerance, their next
// steps agree only if the warm starts do.
TEST(ImplicitIntegrator, ANodeIdReusedAfterAMergeStartsCgFromZero) {
  // 3x3x3 cubes: the 2x2x2 ones' diagonals all meet at the centre.
  scene::Scene s = testing::free_cube_scene(3, 0);
  s.adaptivity.enabled = true;
  s.adaptivity.max_depth = 6;
  s.integrator.cg_max_iterations = 2;
  s.integrator.cg_tolerance = 1e-300;
  s.integrator.cg_preconditioner = scene::CgPreconditioner::kJacobi;
  const double dt_s = 1e-3;
  // A steady load that varies across the body, so Δv does too and changes
  // little from step to step (the warm start is used).
  const auto forces = [](const Body& body) {
    std::vector<Vec3> f(body.x_m.size(), Vec3::Zero());
    body.mesh().for_each_node([&](NodeId n, const mesh::Node&) {
      const Vec3& r = body.rest_m[n];
      f[n] = body.mass_kg[n] * Vec3(2000.0 * r.x(), -1000.0 * r.y(), 500.0 * r.z() * r.x() / 0.15);
    });
    return f;
  };
  // The corner cube's diagonal d1 (a = (0, 0, 0) to b = (h, h, h)) is split,
  // then a few steps leave a Δv at every node.
  struct Run {
    Body body;
    ImplicitIntegrator integrator;
  };
  mesh::Key d1{}, d2{};
  bool found_d2 = false;
  NodeId z1 = mesh::kInvalidId;
  const auto history = [&]() {
    Run run{Body(s), ImplicitIntegrator(s.integrator, s.material)};
    Body& body = run.body;
    NodeId a = mesh::kInvalidId, b = mesh::kInvalidId;
    body.mesh().for_each_node([&](NodeId n, const mesh::Node&) {
      if (body.rest_m[n].isZero(0.0)) a = n;
      if ((body.rest_m[n] - Vec3(0.05, 0.05, 0.05)).isZero(1e-12)) b = n;
    });
    d1 = mesh::edge_key(body.mesh().node(a).lattice, body.mesh().node(b).lattice);
    EXPECT_EQ(body.split(d1), 1);
    z1 = body.mesh().find_node(d1);
    // d2: another cube's diagonal, sharing no node with d1's edge.
    body.mesh().for_each_tet([&](TetId t, const mesh::Tet&) {
      const mesh::Key d = body.mesh().diamond_of(t);
      if (found_d2 || d == d1 || !body.mesh().can_split(d)) return;
      const mesh::Edge& e = body.mesh().edge(body.mesh().find_edge(d));
      for (const NodeId n : {e.a, e.b})
        if (n == a || n == b || n == z1) return;
      const double length2_m2 = (body.rest_m[e.b] - body.rest_m[e.a]).squaredNorm();
      if (std::abs(length2_m2 - 3 * 0.05 * 0.05) > 1e-12) return;  // not a cube diagonal
      d2 = d;
      found_d2 = true;
    });
    for (int i = 0; i < 3; ++i) EXPECT_TRUE(run.integrator.step(body, forces(body), dt_s).ok);
    return run;
  };
  Run reused = history();
  ASSERT_TRUE(found_d2);
  reused.body.merge(d1);
  ASSERT_EQ(reused.body.split(d2), 1);
  ASSERT_EQ(reused.body.mesh().find_node(d2), z1) << "the split reuses the merged node's id";
  Run fresh = history();
  ASSERT_EQ(fresh.body.split(d2), 1);
  ASSERT_NE(fresh.body.mesh().find_node(d2), z1);
  fresh.body.merge(d1);
  // The same body, node for node by rest position (ids aside).
  const auto counterpart = [&](NodeId n) {
    NodeId found = mesh::kInvalidId;
    fresh.body.mesh().for_each_node([&](NodeId m, const mesh::Node&) {
      if (fresh.body.rest_m[m] == reused.body.rest_m[n]) found = m;
    });
    return found;
  };
  reused.body.mesh().for_each_node([&](NodeId n, const mesh::Node&) {
    const NodeId m = counterpart(n);
    ASSERT_NE(m, mesh::kInvalidId);
    ASSERT_EQ(reused.body.x_m[n], fresh.body.x_m[m]);
    ASSERT_EQ(reused.body.v_m_per_s[n], fresh.body.v_m_per_s[m]);
    ASSERT_EQ(reused.body.mass_kg[n], fresh.body.mass_kg[m]);
  });
  for (Run* run : {&reused, &fresh}) {
    ASSERT_TRUE(run->integrator.step(run->body, forces(run->body), dt_s).ok);
  }
  double speed = 0.0, worst = 0.0;
  reused.body.mesh().for_each_node([&](NodeId n, const mesh::Node&) {
    speed = std::max(speed, reused.body.v_m_per_s[n].norm());
    worst = std::max(worst, (reused.body.v_m_per_s[n] - fresh.body.v_m_per_s[counterpart(n)]).norm());
  });
  EXPECT_LT(worst, 1e-9 * speed) << "largest velocity difference [m/s], speeds up to " << speed;
}

// kAuto (the scene default) is Jacobi below kAutoTwoLevelUnknowns free nodes
// and two-level from there on, and runs exactly as the fixed choice would.
TEST(ImplicitIntegrator, AutoPreconditionerPicksByTheNumberOfFreeNodes) {
  for (const int depth : {0, 6}) {  // the beam: 81 nodes (72 free); 2,673 nodes (2,592 free)
    scene::Scene s = beam_scene();
    s.adaptivity.min_depth = depth;
    const bool large = depth == 6;
    std::vector<std::vector<Vec3>> finals;
    for (const auto preconditioner :
         {ImplicitIntegrator::Preconditioner::kAuto,
          large ? ImplicitIntegrator::Preconditioner::kTwoLevel : ImplicitIntegrator::Preconditioner::kJacobi}) {
      Body body(s);
      EXPECT_EQ(free_node_count(body) >= ImplicitIntegrator::kAutoTwoLevelUnknowns, large) << "depth " << depth;
      ImplicitIntegrator integrator(s.integrator, s.material, ImplicitIntegrator::Matvec::kMatrixFree, detected_simd(),
                                    preconditioner);
      const std::vector<Vec3> f(body.x_m.size(), Vec3(0, 0, -2e-3));
      for (int i = 0; i < 3; ++i) ASSERT_TRUE(integrator.step(body, f, 1e-3).ok);
      EXPECT_EQ(integrator.two_level(), large) << "depth " << depth;
      EXPECT_EQ(integrator.coarse_active(), large) << "depth " << depth;
      finals.push_back(body.x_m);
    }
    EXPECT_EQ(finals[0], finals[1]) << "depth " << depth << ": auto differs from its choice";
  }
  EXPECT_EQ(implicit_preconditioner(scene::CgPreconditioner::kAuto), ImplicitIntegrator::Preconditioner::kAuto);
  EXPECT_EQ(implicit_preconditioner(scene::CgPreconditioner::kJacobi), ImplicitIntegrator::Preconditioner::kJacobi);
  EXPECT_EQ(implicit_preconditioner(scene::CgPreconditioner::kTwoLevel), ImplicitIntegrator::Preconditioner::kTwoLevel);
}

// The assembled block-CSR and matrix-free paths give the same trajectory (to
// rounding: they sum in a different order), and each is bit-reproducible.
TEST(ImplicitIntegrator, AssembledAndMatrixFreePathsAgree) {
  scene::Scene s = beam_scene();
  s.adaptivity.min_depth = 1;
  s.integrator.cg_tolerance = 1e-300;  // same iteration count on both paths
  s.integrator.cg_max_iterations = 40;
  std::vector<std::vector<Vec3>> finals;
  for (const auto matvec : {ImplicitIntegrator::Matvec::kMatrixFree, ImplicitIntegrator::Matvec::kMatrixFree,
                            ImplicitIntegrator::Matvec::kAssembledBlockCsr}) {
    Body body = jiggled_beam(11);
    ImplicitIntegrator integrator(s.integrator, s.material, matvec);
    std::vector<Vec3> f(body.x_m.size(), Vec3(0, 0, -1e-3));
    for (int i = 0; i < 50; ++i) ASSERT_TRUE(integrator.step(body, f, 1e-3).ok);
    finals.push_back(body.x_m);
  }
  EXPECT_EQ(finals[0], finals[1]) << "matrix-free path is not deterministic";
  double worst = 0.0;
  for (std::size_t n = 0; n < finals[0].size(); ++n)
    worst = std::max(worst, (finals[0][n] - finals[2][n]).cwiseAbs().maxCoeff());
  EXPECT_LT(worst, 1e-12);  // positions are O(0.1) m
}

}  // namespace
}  // namespace tissue::physics
