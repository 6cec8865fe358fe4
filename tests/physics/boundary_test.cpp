#include "physics/boundary.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "physics/body.hpp"
#include "physics/physics_test_support.hpp"

namespace tissue::physics {
namespace {

using testing::box;

// The beam (x = 0 fixed) at depth 1, unloaded, with two prescribed regions:
// the free face x = 0.4 lifted 1 cm over a 0.2 s ramp, and the top edge line
// x = 0.2, z = 0.1 slid 3 mm along x from t = 0.1 s on (no ramp).
scene::Scene beam_with_prescribed() {
  scene::Scene s = testing::beam_scene();
  s.adaptivity.min_depth = 1;
  s.loads.clear();
  scene::PrescribedSpec lift{"lift", box({0.4, 0, 0}, {0.4, 0.1, 0.1}), {0, 0, 0.01}, {}};
  lift.profile.ramp_s = 0.2;
  scene::PrescribedSpec slide{"slide", box({0.2, 0, 0.1}, {0.2, 0.1, 0.1}), {0.003, 0, 0}, {}};
  slide.profile.start_s = 0.1;
  s.prescribed = {lift, slide};
  return s;
}

bool near(double a, double b) { return std::abs(a - b) < 1e-9; }
bool is_fixed_at_rest(const Vec3& p) { return near(p.x(), 0.0); }
bool is_lifted_at_rest(const Vec3& p) { return near(p.x(), 0.4); }
bool is_slid_at_rest(const Vec3& p) { return near(p.x(), 0.2) && near(p.z(), 0.1); }

// Where the profile puts node n at time t (rest position for free nodes).
Vec3 target_m(const Body& body, NodeId n, double t_s) {
  const Vec3& p = body.rest_m[n];
  if (is_lifted_at_rest(p)) return p + std::min(t_s / 0.2, 1.0) * Vec3(0, 0, 0.01);
  if (is_slid_at_rest(p)) return p + (t_s >= 0.1 ? 1.0 : 0.0) * Vec3(0.003, 0, 0);
  return p;
}

// The list holds exactly the fixed and prescribed nodes, ascending, found
// by their rest positions; whatever `out` held before is gone.
TEST(Boundary, KinematicNodesAreTheFixedAndPrescribedOnesAscending) {
  const Body body(beam_with_prescribed());
  std::vector<NodeId> expected;
  std::size_t fixed = 0, lifted = 0, slid = 0;
  body.mesh().for_each_node([&](NodeId n, const mesh::Node&) {
    const Vec3& p = body.rest_m[n];
    fixed += is_fixed_at_rest(p);
    lifted += is_lifted_at_rest(p);
    slid += is_slid_at_rest(p);
    if (is_fixed_at_rest(p) || is_lifted_at_rest(p) || is_slid_at_rest(p)) expected.push_back(n);
  });
  ASSERT_GT(fixed, 0u);
  ASSERT_GT(lifted, 0u);
  ASSERT_GT(slid, 0u);
  std::vector<NodeId> out = {123456, 7};
  kinematic_nodes(body, out);
  EXPECT_EQ(out, expected);
  EXPECT_TRUE(std::is_sorted(out.begin(), out.end()));
}

// Every node displaced and moving: a fixed node gets the velocity that takes
// it back to rest in dt, a prescribed one the velocity that lands it on
// rest + profile(t_next) d, a free node keeps its velocity. Both prescribed
// regions are checked before and after the slide starts and mid-ramp.
TEST(Boundary, KinematicVelocitiesLandEachNodeOnItsTargetAtTheNextTime) {
  for (const double t_next : {0.05, 0.15, 0.3}) {
    SCOPED_TRACE(t_next);
    Body body(beam_with_prescribed());
    const double dt = 0.01;
    const Vec3 marker(7.0, -7.0, 7.0);
    body.mesh().for_each_node([&](NodeId n, const mesh::Node&) {
      body.x_m[n] = body.rest_m[n] + Vec3(1e-3 * std::sin(n), 2e-3, -1e-3 * std::cos(n));
      body.v_m_per_s[n] = marker;
    });
    const Body before = body;
    set_kinematic_velocities(body, t_next, dt);
    std::size_t kinematic = 0;
    body.mesh().for_each_node([&](NodeId n, const mesh::Node&) {
      EXPECT_EQ(body.x_m[n], before.x_m[n]) << "node " << n;  // velocities only
      if (body.inv_mass_per_kg[n] > 0.0) {
        EXPECT_EQ(body.v_m_per_s[n], marker) << "free node " << n;
        return;
      }
      ++kinematic;
      const Vec3 landed = body.x_m[n] + dt * body.v_m_per_s[n];
      EXPECT_NEAR((landed - target_m(body, n, t_next)).norm(), 0.0, 1e-15) << "node " << n;
    });
    EXPECT_GT(kinematic, 0u);
  }
}

// A node already on its profile moves at the profile's rate: the ramp's
// d / ramp_s for the lifted face, and exactly zero for a fixed node at rest.
TEST(Boundary, NodesOnTheirProfileMoveAtItsRateAndFixedOnesStandStill) {
  Body body(beam_with_prescribed());
  const double t = 0.05, dt = 1e-3;
  body.mesh().for_each_node([&](NodeId n, const mesh::Node&) { body.x_m[n] = target_m(body, n, t); });
  set_kinematic_velocities(body, t + dt, dt);
  int lifted = 0, fixed = 0;
  body.mesh().for_each_node([&](NodeId n, const mesh::Node&) {
    if (is_lifted_at_rest(body.rest_m[n])) {
      EXPECT_NEAR((body.v_m_per_s[n] - Vec3(0, 0, 0.01 / 0.2)).norm(), 0.0, 1e-12) << "node " << n;
      ++lifted;
    } else if (is_fixed_at_rest(body.rest_m[n])) {
      EXPECT_EQ(body.v_m_per_s[n], Vec3::Zero()) << "node " << n;
      ++fixed;
    }
  });
  EXPECT_GT(lifted, 0);
  EXPECT_GT(fixed, 0);
}

// The list overload sets exactly what the all-nodes one does on the listed
// nodes, and touches no other node (listed free nodes included).
TEST(Boundary, TheListOverloadTouchesOnlyTheListedNodes) {
  Body all(beam_with_prescribed());
  const Vec3 marker(1.0, 2.0, 3.0);
  all.mesh().for_each_node([&](NodeId n, const mesh::Node&) {
    all.x_m[n] = all.rest_m[n] + Vec3(-1e-3, 1e-3 * n / 100.0, 5e-4);
    all.v_m_per_s[n] = marker;
  });
  Body listed = all;
  std::vector<NodeId> kinematic;
  kinematic_nodes(all, kinematic);
  std::vector<NodeId> half;  // every other kinematic node, plus one free node
  for (std::size_t i = 0; i < kinematic.size(); i += 2) half.push_back(kinematic[i]);
  NodeId free_node = mesh::kInvalidId;
  all.mesh().for_each_node([&](NodeId n, const mesh::Node&) {
    if (free_node == mesh::kInvalidId && all.inv_mass_per_kg[n] > 0.0) free_node = n;
  });
  half.push_back(free_node);

  set_kinematic_velocities(all, 0.17, 0.01);
  set_kinematic_velocities(listed, half, 0.17, 0.01);
  std::size_t changed = 0;
  all.mesh().for_each_node([&](NodeId n, const mesh::Node&) {
    const bool in_list = std::find(half.begin(), half.end(), n) != half.end();
    if (in_list) {
      EXPECT_EQ(listed.v_m_per_s[n], all.v_m_per_s[n]) << "listed node " << n;
      changed += listed.v_m_per_s[n] != marker;
    } else {
      EXPECT_EQ(listed.v_m_per_s[n], marker) << "unlisted node " << n;
    }
  });
  EXPECT_EQ(changed, half.size() - 1);  // all but the free node
  EXPECT_EQ(listed.v_m_per_s[free_node], marker);
}

// A load in a region with no surface triangle (a ball inside the beam) is
// shared by lumped mass; external forces are m g plus profile(t) times each
// node's share of the load.
TEST(Boundary, AVolumeLoadIsSharedByMassOnTopOfGravity) {
  scene::Scene s = testing::beam_scene();
  s.loads.clear();
  s.gravity_m_per_s2 = {0, 0, -9.81};
  scene::LoadSpec push{"push", testing::sphere({0.2, 0.05, 0.05}, 0.06), {0.0, 2.0, -4.0}, {}};
  push.profile.ramp_s = 0.1;
  s.loads.push_back(push);
  const Body body(s);
  LoadDistribution loads;
  loads.rebuild(body);

  double region_mass = 0.0;
  std::size_t region_nodes = 0;
  body.mesh().for_each_node([&](NodeId n, const mesh::Node&) {
    if ((body.rest_m[n] - Vec3(0.2, 0.05, 0.05)).norm() <= 0.06) {
      region_mass += body.mass_kg[n];
      ++region_nodes;
    }
  });
  ASSERT_GT(region_nodes, 2u);
  ASSERT_EQ(loads.shares(0).size(), region_nodes);
  double total_share = 0.0;
  for (const auto& [n, w] : loads.shares(0)) {
    EXPECT_NEAR(w, body.mass_kg[n] / region_mass, 1e-14) << "node " << n;
    total_share += w;
  }
  EXPECT_NEAR(total_share, 1.0, 1e-14);

  std::vector<Vec3> f;
  loads.external_forces(body, 0.05, f);  // half way up the ramp
  ASSERT_EQ(f.size(), body.x_m.size());
  std::vector<Vec3> expected(body.x_m.size());
  for (std::size_t n = 0; n < expected.size(); ++n) expected[n] = body.mass_kg[n] * Vec3(0, 0, -9.81);
  for (const auto& [n, w] : loads.shares(0)) expected[n] += 0.5 * w * Vec3(0.0, 2.0, -4.0);
  for (std::size_t n = 0; n < f.size(); ++n) EXPECT_NEAR((f[n] - expected[n]).norm(), 0.0, 1e-14) << "node " << n;
}

}  // namespace
}  // namespace tissue::physics
