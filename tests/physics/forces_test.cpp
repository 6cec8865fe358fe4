#include "physics/forces.hpp"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <vector>

#include "physics/body.hpp"
#include "physics/physics_test_support.hpp"

namespace tissue::physics {
namespace {

constexpr double kCube_m = 0.05;  // free_cube_scene's cube size

// The live node resting at p (exactly one).
NodeId node_at(const Body& body, const Vec3& p) {
  NodeId found = mesh::kInvalidId;
  body.mesh().for_each_node([&](NodeId n, const mesh::Node&) {
    if ((body.rest_m[n] - p).norm() < 1e-12) found = n;
  });
  EXPECT_NE(found, mesh::kInvalidId) << "no node at " << p.transpose();
  return found;
}

// A live edge whose ends have different masses (a cube edge from a corner on
// the cube's diagonal to one off it).
EdgeId edge_of_unequal_masses(const Body& body) {
  EdgeId found = mesh::kInvalidId;
  body.mesh().for_each_edge([&](EdgeId e, const mesh::Edge& edge) {
    if (found == mesh::kInvalidId && body.mass_kg[edge.a] != body.mass_kg[edge.b]) found = e;
  });
  EXPECT_NE(found, mesh::kInvalidId);
  return found;
}

// Leaves spring e the only spring (and damper) of the body: the arrays are
// plain data, so one spring can be pinned by hand.
void keep_only_spring(Body& body, EdgeId e) {
  for (EdgeId other = 0; other < body.stiffness_N_per_m.size(); ++other)
    if (other != e) body.stiffness_N_per_m[other] = body.damping_N_s_per_m[other] = 0.0;
}

// x = rest stretched by (1 + ex) along x and (1 + ey) along y.
void stretch(Body& body, double ex, double ey = 0.0) {
  body.mesh().for_each_node([&](NodeId n, const mesh::Node&) {
    body.x_m[n] = body.rest_m[n];
    body.x_m[n].x() *= 1.0 + ex;
    body.x_m[n].y() *= 1.0 + ey;
  });
}

// Largest k L over the springs: the force a spring squashed flat would feel.
double largest_spring_force_N(const Body& body) {
  double m = 0.0;
  for (EdgeId e = 0; e < body.stiffness_N_per_m.size(); ++e)
    m = std::max(m, body.stiffness_N_per_m[e] * body.rest_length_m[e]);
  return m;
}

double max_norm(const std::vector<Vec3>& f) {
  double m = 0.0;
  for (const Vec3& v : f) m = std::max(m, v.norm());
  return m;
}

TEST(Forces, SpringFrameIsTheUnitVectorFromAToBAndTheLength) {
  Body body(testing::free_cube_scene(1, 0));
  const EdgeId e = edge_of_unequal_masses(body);
  body.x_m[body.edge_a[e]] = Vec3(0.01, 0.02, 0.03);
  body.x_m[body.edge_b[e]] = Vec3(0.04, -0.02, 0.03);  // 3-4-5: (0.03, -0.04, 0)
  const SpringFrame f = spring_frame(body, e);
  EXPECT_NEAR(f.length_m, 0.05, 1e-15);
  EXPECT_NEAR((f.direction - Vec3(0.6, -0.8, 0.0)).norm(), 0.0, 1e-15);
}

// Below 1e-9 of its rest length the spring's own direction is noise (or 0/0):
// the rest direction a→b stands in; the length reported is still the real one.
TEST(Forces, CollapsedSpringFallsBackToItsRestDirection) {
  Body body(testing::free_cube_scene(1, 0));
  const EdgeId e = edge_of_unequal_masses(body);
  const NodeId a = body.edge_a[e], b = body.edge_b[e];
  const double rest = body.rest_length_m[e];
  const Vec3 rest_direction = (body.rest_m[b] - body.rest_m[a]).normalized();
  const Vec3 across = rest_direction.unitOrthogonal();

  body.x_m[b] = body.x_m[a];  // exactly on top of each other
  SpringFrame f = spring_frame(body, e);
  EXPECT_EQ(f.length_m, 0.0);
  EXPECT_NEAR((f.direction - rest_direction).norm(), 0.0, 1e-15);

  body.x_m[b] = body.x_m[a] + 1e-10 * rest * across;  // squashed below the threshold, sideways
  f = spring_frame(body, e);
  EXPECT_NEAR(f.length_m, 1e-10 * rest, 1e-6 * 1e-10 * rest);  // a difference of positions near 0.05 m
  EXPECT_NEAR((f.direction - rest_direction).norm(), 0.0, 1e-15);

  body.x_m[b] = body.x_m[a] + 1e-8 * rest * across;  // above it: its own direction
  f = spring_frame(body, e);
  EXPECT_NEAR((f.direction - across).norm(), 0.0, 1e-6);

  // The force of the collapsed spring is finite and pushes the ends apart
  // along the rest direction with k L.
  body.x_m[b] = body.x_m[a];
  keep_only_spring(body, e);
  std::vector<Vec3> force(body.x_m.size(), Vec3::Zero());
  add_spring_forces(body, force);
  const Vec3 expected = -body.stiffness_N_per_m[e] * rest * rest_direction;
  EXPECT_NEAR((force[a] - expected).norm(), 0.0, 1e-12 * expected.norm());
  EXPECT_NEAR((force[b] + expected).norm(), 0.0, 1e-12 * expected.norm());
}

// One spring alone: k (l − L) along a→b on a (a stretched spring pulls a
// toward b, a squashed one pushes it away), the opposite on b, nothing
// elsewhere; and the forces are added to what f already holds.
TEST(Forces, SpringForceIsKTimesTheStretchAlongTheSpringEqualAndOpposite) {
  Body body(testing::free_cube_scene(1, 0));
  const EdgeId e = edge_of_unequal_masses(body);
  keep_only_spring(body, e);
  const NodeId a = body.edge_a[e], b = body.edge_b[e];
  const double k = body.stiffness_N_per_m[e], rest = body.rest_length_m[e];
  ASSERT_GT(k, 0.0);
  const Vec3 direction = Vec3(1.0, 2.0, -2.0) / 3.0;
  for (const double ratio : {1.1, 0.9}) {
    SCOPED_TRACE(ratio);
    body.x_m[b] = body.x_m[a] + ratio * rest * direction;
    const Vec3 already(0.5, -1.0, 2.0);
    std::vector<Vec3> f(body.x_m.size(), already);
    add_spring_forces(body, f, false);
    const Vec3 on_a = k * (ratio - 1.0) * rest * direction;
    EXPECT_NEAR((f[a] - already - on_a).norm(), 0.0, 1e-12 * on_a.norm());
    EXPECT_NEAR((f[b] - already + on_a).norm(), 0.0, 1e-12 * on_a.norm());
    for (NodeId n = 0; n < f.size(); ++n) {
      if (n == a || n == b) continue;
      EXPECT_EQ(f[n], already) << "node " << n;
    }
  }
}

// Rigid motions (a rotation and translation of the rest shape, a rigid
// velocity field) stretch no spring and move no damper: zero force, with and
// without dampers.
TEST(Forces, ZeroAtRestAndUnderRigidMotion) {
  Body body(testing::free_cube_scene(2, 1));
  const double force_scale = largest_spring_force_N(body);
  ASSERT_GT(force_scale, 0.0);
  std::vector<Vec3> f(body.x_m.size(), Vec3::Zero());
  add_spring_forces(body, f);
  EXPECT_LT(max_norm(f), 1e-12 * force_scale) << "at rest";

  const Eigen::Matrix3d rotation = Eigen::AngleAxisd(0.7, Vec3(1.0, -2.0, 0.5).normalized()).toRotationMatrix();
  const Vec3 shift(0.3, -0.1, 0.2), omega(2.0, -1.0, 3.0), drift(0.5, 0.25, -1.0);
  body.mesh().for_each_node([&](NodeId n, const mesh::Node&) {
    body.x_m[n] = rotation * body.rest_m[n] + shift;
    body.v_m_per_s[n] = drift + omega.cross(body.x_m[n]);
  });
  f.assign(body.x_m.size(), Vec3::Zero());
  add_spring_forces(body, f);
  EXPECT_LT(max_norm(f), 1e-9 * force_scale) << "rigid motion";
}

// Newton's third law over a whole deformed, moving body (one spring collapsed
// onto its end, so its rest-direction fallback is in): every spring and damper
// force is equal, opposite and along the line of its ends, so the forces sum
// to zero and have no net moment.
TEST(Forces, WholeBodyForcesHaveNoResultantAndNoMoment) {
  const Body body = testing::jiggled_beam(5);
  std::vector<Vec3> f(body.x_m.size(), Vec3::Zero());
  add_spring_forces(body, f);
  Vec3 total = Vec3::Zero(), moment = Vec3::Zero();
  body.mesh().for_each_node([&](NodeId n, const mesh::Node&) {
    total += f[n];
    moment += body.x_m[n].cross(f[n]);
  });
  ASSERT_GT(max_norm(f), 0.0);
  EXPECT_LT(total.norm(), 1e-12 * max_norm(f));
  EXPECT_LT(moment.norm(), 1e-12 * max_norm(f) * 0.4);  // 0.4 m: the beam's length
}

// The springs are conservative: f = −∂E/∂x with E = elastic_energy_J, checked
// by central differences on every coordinate of every node of a jiggled,
// refined beam (fixed nodes too: f holds the forces on every node).
TEST(Forces, SpringForcesAreMinusTheGradientOfTheElasticEnergy) {
  scene::Scene s = testing::beam_scene();
  s.adaptivity.min_depth = 1;
  Body body(s);
  testing::jiggle_free_nodes(body, 3, 0.005, 0.0);
  std::vector<Vec3> f(body.x_m.size(), Vec3::Zero());
  add_spring_forces(body, f, false);
  const double scale = max_norm(f);
  ASSERT_GT(scale, 0.1);
  const double h = 1e-7;
  int checked = 0;
  body.mesh().for_each_node([&](NodeId n, const mesh::Node&) {
    for (int axis = 0; axis < 3; ++axis) {
      const double x0 = body.x_m[n][axis];
      body.x_m[n][axis] = x0 + h;
      const double plus = elastic_energy_J(body);
      body.x_m[n][axis] = x0 - h;
      const double minus = elastic_energy_J(body);
      body.x_m[n][axis] = x0;
      EXPECT_NEAR(f[n][axis], -(plus - minus) / (2 * h), 1e-6 * scale) << "node " << n << " axis " << axis;
      ++checked;
    }
  });
  EXPECT_EQ(checked, 3 * static_cast<int>(body.mesh().node_count()));
}

// With the body at rest and one node moving at v: the node feels
// −Σ c (v·d̂) d̂ over its springs (only the velocity along each spring), each
// neighbour the opposite share, and the power is negative. Without dampers,
// or with dampers off, nothing.
TEST(Forces, DampersResistTheRelativeVelocityAlongTheSpringOnlyWhenAsked) {
  Body body(testing::free_cube_scene(2, 0));
  const NodeId moving = node_at(body, Vec3(kCube_m, kCube_m, kCube_m));  // the centre: springs every way
  const Vec3 v(0.3, -0.2, 0.1);
  body.v_m_per_s[moving] = v;

  std::vector<Vec3> expected(body.x_m.size(), Vec3::Zero());
  int springs = 0;
  body.mesh().for_each_edge([&](EdgeId e, const mesh::Edge& edge) {
    if (edge.a != moving && edge.b != moving) return;
    const NodeId other = edge.a == moving ? edge.b : edge.a;
    const Vec3 d = (body.rest_m[other] - body.rest_m[moving]).normalized();
    const Vec3 share = body.damping_N_s_per_m[e] * v.dot(d) * d;
    expected[moving] -= share;
    expected[other] += share;
    ++springs;
  });
  ASSERT_GE(springs, 14);  // axis edges, face and body diagonals

  std::vector<Vec3> damped(body.x_m.size(), Vec3::Zero()), by_default = damped, undamped = damped;
  add_spring_forces(body, damped, true);
  add_spring_forces(body, by_default);
  add_spring_forces(body, undamped, false);
  const double scale = expected[moving].norm();
  ASSERT_GT(scale, 0.0);
  for (NodeId n = 0; n < damped.size(); ++n) {
    EXPECT_NEAR((damped[n] - expected[n]).norm(), 0.0, 1e-9 * scale) << "node " << n;
    EXPECT_EQ(by_default[n], damped[n]) << "node " << n;
    EXPECT_LT(undamped[n].norm(), 1e-9 * scale) << "node " << n;
  }
  EXPECT_LT(damped[moving].dot(v), 0.0);
}

// One damper alone, for a moderate and an absurdly long step: the relative
// velocity along the spring becomes u / (1 + h c (1/m_a + 1/m_b)), the
// relative velocity across it is untouched, momentum is kept, and no other
// node changes.
TEST(Forces, ImplicitDamperDividesTheRelativeSpeedAlongTheSpring) {
  for (const double h : {1e-3, 1e6}) {
    SCOPED_TRACE(h);
    Body body(testing::free_cube_scene(1, 0));
    const EdgeId e = edge_of_unequal_masses(body);
    keep_only_spring(body, e);
    const NodeId a = body.edge_a[e], b = body.edge_b[e];
    const double c = body.damping_N_s_per_m[e], ma = body.mass_kg[a], mb = body.mass_kg[b];
    ASSERT_GT(c, 0.0);
    body.mesh().for_each_node([&](NodeId n, const mesh::Node&) { body.v_m_per_s[n] = Vec3(0.1 * n, -0.2, 0.05 * n); });
    body.v_m_per_s[a] = Vec3(0.3, -0.1, 0.2);
    body.v_m_per_s[b] = Vec3(-0.4, 0.5, 0.1);
    const Body before = body;
    EXPECT_GT(apply_spring_dampers_implicitly(body, h).iterations, 0);

    const Vec3 d = (body.x_m[b] - body.x_m[a]).normalized();
    const Vec3 rel0 = before.v_m_per_s[b] - before.v_m_per_s[a], rel = body.v_m_per_s[b] - body.v_m_per_s[a];
    const double u0 = rel0.dot(d);
    ASSERT_GT(std::abs(u0), 0.1);
    EXPECT_NEAR(rel.dot(d), u0 / (1.0 + h * c * (1.0 / ma + 1.0 / mb)), 1e-12 * std::abs(u0));
    EXPECT_NEAR((rel - rel.dot(d) * d - (rel0 - u0 * d)).norm(), 0.0, 1e-12);
    const Vec3 p0 = ma * before.v_m_per_s[a] + mb * before.v_m_per_s[b],
               p = ma * body.v_m_per_s[a] + mb * body.v_m_per_s[b];
    EXPECT_NEAR((p - p0).norm(), 0.0, 1e-12 * p0.norm());
    for (NodeId n = 0; n < body.v_m_per_s.size(); ++n) {
      if (n == a || n == b) continue;
      EXPECT_EQ(body.v_m_per_s[n], before.v_m_per_s[n]) << "node " << n;
    }
  }
}

// The whole solve on a free cube (no kinematic nodes): momentum kept, kinetic
// energy never grows, at any step however long; positions untouched.
TEST(Forces, ImplicitDampersConserveMomentumAndNeverAddKineticEnergy) {
  for (const double h : {1e-4, 1e-2, 1e3}) {
    SCOPED_TRACE(h);
    Body body(testing::free_cube_scene(2, 1));
    testing::jiggle_free_nodes(body, 11, 0.005, 0.5);
    const Vec3 p0 = body.momentum_kg_m_per_s();
    const double ke0 = kinetic_energy_J(body);
    const auto x0 = body.x_m;
    EXPECT_GT(apply_spring_dampers_implicitly(body, h).iterations, 0);
    EXPECT_NEAR((body.momentum_kg_m_per_s() - p0).norm(), 0.0, 1e-12 * body.total_mass_kg() * 0.5);
    EXPECT_LT(kinetic_energy_J(body), ke0);
    EXPECT_EQ(body.x_m, x0);
  }
}

// Backward Euler for the dampers alone: M (v' − v) = h f_damp(v') on every
// free node, f_damp the dampers' force at the current positions (kinematic
// nodes at their own velocities), and with a mass damping folded into
// mass_scale, mass_scale M v' − M v = h f_damp(v'). The fixed face moves
// here (as a prescribed one does): its known velocities pull on the free
// nodes through the dampers. One Gauss–Seidel sweep spring by spring (the
// earlier method) left most of a smooth motion's damping out.
TEST(Forces, ImplicitDampersSolveTheBackwardEulerSystem) {
  for (const double h : {1e-3, 1e-2}) {
    for (const double mass_scale : {1.0, 1.25}) {
      SCOPED_TRACE(::testing::Message() << "h " << h << " mass_scale " << mass_scale);
      Body body = testing::jiggled_beam(7);
      int moving = 0;
      body.mesh().for_each_node([&](NodeId n, const mesh::Node&) {
        if (body.inv_mass_per_kg[n] != 0.0) return;
        body.v_m_per_s[n] = Vec3(0.02, -0.03 + 0.001 * (n % 7), 0.05);
        ++moving;
      });
      ASSERT_GT(moving, 0);
      const Body before = body;
      ImplicitDamperWork work;
      const ImplicitDamperSolve solve = mass_scale == 1.0
                                            ? apply_spring_dampers_implicitly(body, h)
                                            : apply_spring_dampers_implicitly(body, h, mass_scale, 1e-10, work);
      EXPECT_TRUE(solve.converged) << solve.relative_residual;
      std::vector<Vec3> with(body.x_m.size(), Vec3::Zero()), without(body.x_m.size(), Vec3::Zero());
      add_spring_forces(body, with, true);
      add_spring_forces(body, without, false);
      double residual = 0.0, scale = 0.0;
      body.mesh().for_each_node([&](NodeId n, const mesh::Node&) {
        if (body.inv_mass_per_kg[n] == 0.0) return;
        const Vec3 damper_N = with[n] - without[n];
        residual +=
            (mass_scale * body.mass_kg[n] * body.v_m_per_s[n] - body.mass_kg[n] * before.v_m_per_s[n] - h * damper_N)
                .squaredNorm();
        scale += (body.mass_kg[n] * before.v_m_per_s[n]).squaredNorm();
      });
      ASSERT_GT(scale, 0.0);
      EXPECT_LE(std::sqrt(residual / scale), 1e-8);
      EXPECT_EQ(body.x_m, before.x_m);
      body.mesh().for_each_node([&](NodeId n, const mesh::Node&) {
        if (body.inv_mass_per_kg[n] == 0.0) {
          EXPECT_EQ(body.v_m_per_s[n], before.v_m_per_s[n]) << "node " << n;
        }
      });
    }
  }
}

// With kinematic nodes (a fixed face, springs between two fixed nodes, a
// collapsed spring): kinematic velocities stay as they are, every velocity
// stays finite, and kinetic energy does not grow.
TEST(Forces, ImplicitDampersLeaveKinematicNodesAlone) {
  Body body = testing::jiggled_beam(7);
  const Body before = body;
  EXPECT_TRUE(apply_spring_dampers_implicitly(body, 1e-2).converged);
  std::size_t kinematic = 0;
  body.mesh().for_each_node([&](NodeId n, const mesh::Node&) {
    EXPECT_TRUE(body.v_m_per_s[n].allFinite()) << "node " << n;
    if (body.inv_mass_per_kg[n] == 0.0) {
      ++kinematic;
      EXPECT_EQ(body.v_m_per_s[n], before.v_m_per_s[n]) << "node " << n;
    }
  });
  EXPECT_GT(kinematic, 0u);
  EXPECT_LT(kinetic_energy_J(body), kinetic_energy_J(before));
}

// Σ ½ k (l − L)²: one spring of known stiffness, stretched or squashed by the
// same amount, stores the same energy; a rigidly moved body stores none.
TEST(Forces, ElasticEnergyIsHalfKTimesTheStretchSquared) {
  Body body(testing::free_cube_scene(1, 0));
  const EdgeId e = edge_of_unequal_masses(body);
  keep_only_spring(body, e);
  body.stiffness_N_per_m[e] = 200.0;
  const NodeId a = body.edge_a[e], b = body.edge_b[e];
  const Vec3 d = (body.rest_m[b] - body.rest_m[a]).normalized();
  for (const double stretch_m : {0.01, -0.01}) {
    body.x_m[b] = body.rest_m[b] + stretch_m * d;
    EXPECT_NEAR(elastic_energy_J(body), 0.5 * 200.0 * 1e-4, 1e-15) << stretch_m;
  }

  Body whole(testing::free_cube_scene(2, 1));
  const Eigen::Matrix3d rotation = Eigen::AngleAxisd(1.1, Vec3(0.2, 1.0, -0.4).normalized()).toRotationMatrix();
  whole.mesh().for_each_node(
      [&](NodeId n, const mesh::Node&) { whole.x_m[n] = rotation * whole.rest_m[n] + Vec3(1.0, 2.0, 3.0); });
  EXPECT_LT(elastic_energy_J(whole), 1e-24);
  stretch(whole, 0.01);
  EXPECT_GT(elastic_energy_J(whole), 1e-6);
}

TEST(Forces, KineticEnergyIsHalfMassTimesSpeedSquared) {
  Body body(testing::free_cube_scene(2, 1));
  const Vec3 v(0.3, -0.4, 1.2);  // |v| = 1.3
  body.mesh().for_each_node([&](NodeId n, const mesh::Node&) { body.v_m_per_s[n] = v; });
  EXPECT_NEAR(kinetic_energy_J(body), 0.5 * body.total_mass_kg() * 1.69, 1e-14);

  body.mesh().for_each_node([&](NodeId n, const mesh::Node&) { body.v_m_per_s[n].setZero(); });
  const NodeId one = node_at(body, Vec3(kCube_m, kCube_m, kCube_m));
  body.v_m_per_s[one] = v;
  EXPECT_NEAR(kinetic_energy_J(body), 0.5 * body.mass_kg[one] * 1.69, 1e-16);
}

// At rest, on a body refined to mixed depths (both orientations of tet),
// nothing is strained and nothing is inverted.
TEST(Forces, AtRestNoTetIsStrainedOrInverted) {
  const Body body = testing::randomly_refined_beam(23);
  int tets = 0;
  body.mesh().for_each_tet([&](TetId t, const mesh::Tet&) {
    EXPECT_NEAR(strain_energy_density_Pa(body, t), 0.0, 1e-20) << "tet " << t;
    EXPECT_NEAR(max_edge_stretch(body, t), 0.0, 1e-13) << "tet " << t;  // split nodes: mean of the ends, rounded
    ++tets;
  });
  EXPECT_GT(tets, 192);  // refined beyond the coarse 8x2x2 cubes
  EXPECT_EQ(inverted_tet_count(body), 0u);
}

// Uniaxial stretch (1 + ε) along x. A Kuhn tet's edges are one per axis, two
// face diagonals and the body diagonal; an edge with direction n gets
// l/L = sqrt(1 + (2ε + ε²) n_x²). The x axis edge has ε, the body diagonal
// f(1/3), and one face diagonal f(1/2) or, when x is the middle step of the
// tet's path, both. So D = (E/2) (ε² + m f(1/2)² + f(1/3)²), m = 1 or 2 —
// squared: a squash of ε stores as much as about a stretch. The depth-3 tets
// are the depth-0 ones halved: the same two values (level independence).
TEST(Forces, StrainEnergyDensityOfAUniaxialStretchIsHalfESumOfSquaredEdgeStrains) {
  for (const int depth : {0, 3}) {
    for (const double eps : {0.01, -0.01}) {
      SCOPED_TRACE(::testing::Message() << "depth " << depth << " strain " << eps);
      scene::Scene s = testing::free_cube_scene(1, depth);
      s.material.youngs_modulus_Pa = 2e4;
      Body body(s);
      stretch(body, eps);
      auto f = [&](double q) { return std::sqrt(1.0 + (2 * eps + eps * eps) * q) - 1.0; };
      const double one_diagonal = 0.5 * 2e4 * (eps * eps + f(0.5) * f(0.5) + f(1.0 / 3) * f(1.0 / 3));
      const double two_diagonals = 0.5 * 2e4 * (eps * eps + 2 * f(0.5) * f(0.5) + f(1.0 / 3) * f(1.0 / 3));
      int ones = 0, twos = 0;
      body.mesh().for_each_tet([&](TetId t, const mesh::Tet&) {
        const double d = strain_energy_density_Pa(body, t);
        if (std::abs(d - one_diagonal) < 1e-12 * one_diagonal)
          ++ones;
        else if (std::abs(d - two_diagonals) < 1e-12 * two_diagonals)
          ++twos;
        else
          ADD_FAILURE() << "tet " << t << ": " << d << " Pa is neither " << one_diagonal << " nor " << two_diagonals;
      });
      EXPECT_EQ(ones, 2 * twos);  // 4 of a cube's 6 paths have x first or last
      EXPECT_GT(twos, 0);
    }
  }
}

// Under a general linear deformation x = (I + εG) X the density is quadratic
// in ε: stretch and squash agree to O(ε), halving ε quarters it.
TEST(Forces, StrainEnergyDensityScalesWithTheStrainSquared) {
  const Body rest = testing::randomly_refined_beam(31, 4);
  Eigen::Matrix3d g;
  g << 0.3, -0.8, 0.1, 0.5, 0.2, -0.6, -0.4, 0.9, 0.7;
  auto deformed = [&](double eps) {
    Body body = rest;
    body.mesh().for_each_node(
        [&](NodeId n, const mesh::Node&) { body.x_m[n] = body.rest_m[n] + eps * g * body.rest_m[n]; });
    return body;
  };
  const Body stretched = deformed(1e-4), squashed = deformed(-1e-4), half = deformed(0.5e-4);
  rest.mesh().for_each_tet([&](TetId t, const mesh::Tet&) {
    const double d = strain_energy_density_Pa(stretched, t);
    ASSERT_GT(d, 1e-6) << "tet " << t;
    EXPECT_NEAR(strain_energy_density_Pa(squashed, t) / d, 1.0, 1e-3) << "tet " << t;
    EXPECT_NEAR(strain_energy_density_Pa(half, t) / d, 0.25, 1e-3) << "tet " << t;
  });
}

// The position-and-rest-length form gives exactly the body form, on a
// jiggled beam (a collapsed spring included) and on a refined one.
TEST(Forces, BothStrainEnergyDensityFormsAreBitIdentical) {
  Body refined = testing::randomly_refined_beam(37);
  testing::jiggle_free_nodes(refined, 41, 0.003, 0.0);
  for (const Body& body : {testing::jiggled_beam(13), refined}) {
    int nonzero = 0;
    body.mesh().for_each_tet([&](TetId t, const mesh::Tet& tet) {
      std::array<const Vec3*, 4> x{};
      for (int i = 0; i < 4; ++i) x[i] = &body.x_m[tet.v[i]];
      std::array<double, 6> rest{};
      for (int i = 0; i < 6; ++i)
        rest[i] =
            (body.rest_m[tet.v[mesh::kTetEdgeSlots[i][1]]] - body.rest_m[tet.v[mesh::kTetEdgeSlots[i][0]]]).norm();
      const double d = strain_energy_density_Pa(body, t);
      EXPECT_EQ(strain_energy_density_Pa(x, rest, body.scene().material.youngs_modulus_Pa), d) << "tet " << t;
      nonzero += d > 0.0;
    });
    EXPECT_GT(nonzero, 100);
  }
}

// The cube's corner c = (h, 0, 0) belongs to two tets, (0, c, (h,h,0), D)
// and (0, c, (h,0,h), D) with D = (h,h,h); c's opposite faces lie in the
// planes x = y and x = z. Moving c across one plane inverts one tet, onto it
// flattens it (counted too), across both inverts both.
TEST(Forces, InvertedTetCountCountsMirroredAndFlatTets) {
  Body body(testing::free_cube_scene(1, 0));
  ASSERT_EQ(body.mesh().tet_count(), 6u);
  EXPECT_EQ(inverted_tet_count(body), 0u);
  const NodeId c = node_at(body, Vec3(kCube_m, 0, 0));
  const struct {
    Vec3 at;
    std::size_t inverted;
  } cases[] = {{{0.2, 0.6, 0.0}, 1}, {{0.2, 0.2, 0.0}, 1}, {{-0.2, 0.6, 0.0}, 2}, {{0.9, 0.1, 0.05}, 0}};
  for (const auto& k : cases) {
    body.x_m[c] = kCube_m * k.at;
    EXPECT_EQ(inverted_tet_count(body), k.inverted) << "c at " << k.at.transpose();
  }
}

// Largest max(l/L, L/l) − 1: the x axis edge under a uniaxial stretch or
// squash (a squash to 99 % is 1/0.99 − 1), and under stretch x 1 % with
// squash y 3 % the y axis edge; a squash to 40 % is as far from rest as a
// stretch to 250 %.
TEST(Forces, MaxEdgeStretchIsTheLargestLengthRatioAwayFromRest) {
  Body body(testing::free_cube_scene(1, 0));
  const struct {
    double ex, ey, expected;
  } cases[] = {{0.01, 0.0, 0.01}, {-0.01, 0.0, 1 / 0.99 - 1}, {0.01, -0.03, 1 / 0.97 - 1}, {-0.6, 0.0, 1.5}};
  for (const auto& k : cases) {
    stretch(body, k.ex, k.ey);
    body.mesh().for_each_tet([&](TetId t, const mesh::Tet&) {
      EXPECT_NEAR(max_edge_stretch(body, t), k.expected, 1e-14) << "tet " << t << " x " << k.ex << " y " << k.ey;
    });
  }  // A collapsed spring is far from rest, but finitely so.
  EXPECT_TRUE(std::isfinite(stretch_from_strain(-1.0)));
  EXPECT_GE(stretch_from_strain(-1.0), 1.0 / kCollapsedSpringRatio - 1.0);
}

// Per-tet stiffness shares add up to the springs: in an affine field every
// tet sees the same F, and the tets' spring energies sum to the body's elastic
// energy (each spring's stretch is shared by all its tets). A refined beam
// mixes depths, so every tet type and boundary share takes part.
TEST(Forces, TetSpringEnergiesOfAnAffineFieldSumToTheElasticEnergy) {
  Body body = testing::randomly_refined_beam(7);
  Eigen::Matrix3d F;
  F << 1.004, 0.003, -0.002, 0.001, 0.997, 0.005, -0.003, 0.002, 1.006;  // stretches, shears, a small turn
  for (NodeId n = 0; n < body.x_m.size(); ++n) body.x_m[n] = F * body.rest_m[n];
  double sum_J = 0.0;
  for (const auto& [corners, depth] : mesh::sorted_live_tets(body.mesh()))
    sum_J += tet_spring_energy_J(body, corners, depth, F);
  const double elastic_J = elastic_energy_J(body);
  ASSERT_GT(elastic_J, 0.0);
  EXPECT_NEAR(sum_J, elastic_J, 1e-12 * elastic_J);
  // Corner order does not matter: the reversed corners give the same energy.
  const auto [corners, depth] = mesh::sorted_live_tets(body.mesh()).front();
  const std::array<NodeId, 4> reversed{corners[3], corners[2], corners[1], corners[0]};
  EXPECT_NEAR(tet_spring_energy_J(body, reversed, depth, F), tet_spring_energy_J(body, corners, depth, F),
              1e-15 * elastic_J);
}

}  // namespace
}  // namespace tissue::physics
