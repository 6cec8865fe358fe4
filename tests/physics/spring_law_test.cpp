#include "physics/spring_law.hpp"

#include <gtest/gtest.h>

#include "physics/body.hpp"
#include "physics/forces.hpp"
#include "physics/physics_test_support.hpp"

namespace tissue::physics {
namespace {

// Eq. (3) with w = 1 equals the paper's closed form (5) on the refinement edge
// of every complete interior diamond, at every level of the cycle.
TEST(SpringLaw, EquationThreeMatchesClosedFormFiveOnInteriorRefinementEdges) {
  for (int level = 0; level <= 5; ++level) {
    scene::Scene s = testing::free_cube_scene(3, level);
    s.object.cube_size_m = 0.1;
    s.adaptivity.enabled = true;  // a lattice one level finer, so level's diamonds have centres
    s.adaptivity.max_depth = level + 1;
    s.material.stiffness = scene::StiffnessLaw::kPaper;
    Body body(s);
    const mesh::KuhnMesh& m = body.mesh();
    const double expected = paper_closed_form_stiffness_N_per_m(s.material.youngs_modulus_Pa, 0.1, level);
    int compared = 0;
    m.for_each_tet([&](TetId t, const mesh::Tet&) {
      const mesh::Key d = m.diamond_of(t);
      const mesh::DiamondInfo info = m.diamond_info(d);
      const int full = info.phase == 0 ? 6 : (info.phase == 1 ? 4 : 8);
      if (mesh::diamond_tet_count(m.domain(), info) != full) return;  // boundary-reduced
      EXPECT_NEAR(body.stiffness_N_per_m[m.find_edge(d)] / expected, 1.0, 1e-12) << "level " << level;
      ++compared;
    });
    EXPECT_GT(compared, 0) << "level " << level;
  }
}

// With eq. (3) a uniform dilation stores 3 ε² E V: bulk modulus exactly 2E/3.
// The isotropic weights keep Σ w = 6 per tet, so they keep that too.
TEST(SpringLaw, UniformDilationGivesBulkModulusTwoThirdsE) {
  for (auto law : {scene::StiffnessLaw::kPaper, scene::StiffnessLaw::kIsotropic}) {
    for (int depth : {0, 1, 2, 3}) {
      scene::Scene s = testing::free_cube_scene(2, depth);
      s.material.stiffness = law;
      Body body(s);
      const double eps = 1e-3;
      body.mesh().for_each_node([&](NodeId n, const mesh::Node&) { body.x_m[n] = (1.0 + eps) * body.rest_m[n]; });
      const double volume = 0.1 * 0.1 * 0.1;
      const double bulk = 2.0 * s.material.youngs_modulus_Pa / 3.0;
      const double expected = 0.5 * bulk * (3 * eps) * (3 * eps) * volume;
      EXPECT_NEAR(elastic_energy_J(body) / expected, 1.0, 1e-4) << "depth " << depth;
    }
  }
}

// Bodies sum springs from the integer weights 10⁴ w; the double weight (the
// tet shares' energy sums use it) is the decimal's nearest double, exactly.
TEST(SpringLaw, IsotropicWeightsFollowTheTypeTable) {
  const auto expect_weight = [](int depth, std::int64_t length2, std::int64_t longest2, std::int64_t e4, double w) {
    EXPECT_EQ(isotropic_edge_weight_e4(depth, length2, longest2), e4) << depth << " " << length2 << "/" << longest2;
    EXPECT_EQ(isotropic_edge_weight(depth, length2, longest2), w) << depth << " " << length2 << "/" << longest2;
    EXPECT_EQ(edge_weight(scene::StiffnessLaw::kIsotropic, depth, length2, longest2), w);
  };
  // TYPE I: axis, face diagonal, body diagonal (squared lengths 1, 2, 3 of 3).
  expect_weight(0, 1, 3, 5525, 0.5525);
  expect_weight(3, 2, 3, 14847, 1.4847);
  expect_weight(6, 3, 3, 13729, 1.3729);
  // TYPE II: half body 3/4, axis 1, face diagonal 2 (of 2).
  expect_weight(1, 3, 8, 9507, 0.9507);
  expect_weight(4, 1, 2, 10754, 1.0754);
  expect_weight(1, 2, 2, 9971, 0.9971);
  // TYPE III: half axis, half face, half body, axis (1, 2, 3, 4 of 4).
  expect_weight(2, 1, 4, 9481, 0.9481);
  expect_weight(2, 2, 4, 10074, 1.0074);
  expect_weight(5, 3, 4, 10444, 1.0444);
  expect_weight(2, 4, 4, 9481, 0.9481);
  EXPECT_THROW(isotropic_edge_weight(0, 1, 4), std::logic_error);
  EXPECT_THROW(isotropic_edge_weight_e4(0, 1, 4), std::logic_error);
  EXPECT_EQ(edge_weight(scene::StiffnessLaw::kPaper, 0, 1, 3), 1.0);
  EXPECT_EQ(edge_weight_e4(scene::StiffnessLaw::kPaper, 0, 1, 3), kEdgeWeightScale);
}

TEST(SpringLaw, DampingLaws) {
  scene::MaterialSpec m;
  m.rayleigh_beta_s = 0.02;
  EXPECT_DOUBLE_EQ(spring_damping_N_s_per_m(m, 50.0, 1.0, 2.0, 0.5), 1.0);
  m.damping = scene::DampingLaw::kPaper;
  // Eq. (4): 2 sqrt(k (m_i + m_j)) / L.
  EXPECT_DOUBLE_EQ(spring_damping_N_s_per_m(m, 50.0, 1.0, 1.0, 0.5), 2.0 * 10.0 / 0.5);
  // Both end masses count: unequal ends, 2 sqrt(2 (1 + 7)) / 0.5 = 16.
  EXPECT_DOUBLE_EQ(spring_damping_N_s_per_m(m, 2.0, 1.0, 7.0, 0.5), 16.0);
  EXPECT_DOUBLE_EQ(spring_damping_N_s_per_m(m, 2.0, 7.0, 1.0, 0.5), 16.0);
}

// Eq. (2): a quarter of each incident tet's mass. A corner node of one cube
// of 6 Kuhn tets (each 1/6 of the cube; a corner on the main diagonal is in
// all six: six_volume = 6 x 1 in lattice units) holds a quarter of the cube.
TEST(SpringLaw, NodeMassIsAQuarterOfItsTetsMass) {
  const double unit_m = 0.01, rho = 100.0;
  const double cube_kg = rho * unit_m * unit_m * unit_m;
  EXPECT_DOUBLE_EQ(node_mass_kg(rho, 6, unit_m), cube_kg / 4.0);
  EXPECT_DOUBLE_EQ(node_mass_kg(rho, 1, unit_m), cube_kg / 24.0);  // one tet
  EXPECT_EQ(node_mass_kg(rho, 0, unit_m), 0.0);
}

}  // namespace
}  // namespace tissue::physics
