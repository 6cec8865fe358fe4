#include "mesh/refine_ops.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "mesh/mesh_test_support.hpp"

namespace tissue::mesh {
namespace {

TEST(RefineOps, UniformRefinementReachesExactlyTheDepth) {
  KuhnMesh mesh({3, 2, 1, 0.1, 9});
  for (int depth : {1, 2, 4, 6}) {
    refine_uniform(mesh, depth);
    mesh.for_each_tet([&](TetId, const Tet& t) { EXPECT_EQ(t.depth, depth); });
    EXPECT_EQ(mesh.tet_count(), 36u << depth);
  }
  // Level 6 of 3x2x1 cubes is 12x8x4 cubes: (13*9*5) nodes.
  EXPECT_EQ(mesh.node_count(), 13u * 9u * 5u);
  EXPECT_TRUE(testing::check_conformity(mesh).problems.empty());
}

TEST(RefineOps, SphereRefinementIsLocal) {
  // A long bar: refining at one end must leave the far end coarse.
  KuhnMesh mesh({8, 1, 1, 0.1, 9});
  const int splits = refine_sphere(mesh, {{0.8, 0.05, 0.05}, 0.04}, 6);
  EXPECT_GT(splits, 0);
  int deep_near = 0;
  mesh.for_each_tet([&](TetId t, const Tet& tet) {
    const RegionBox b = tet_bounds_m(mesh, t);
    if (b.max_m[0] <= 0.5) {
      EXPECT_EQ(tet.depth, 0) << "refinement leaked far from the region";
    }
    if (tet.depth >= 6) ++deep_near;
  });
  EXPECT_GT(deep_near, 0);
  // Every tet whose bounds meet the sphere is at least at the requested depth.
  mesh.for_each_tet([&](TetId t, const Tet& tet) {
    const RegionBox b = tet_bounds_m(mesh, t);
    double d2 = 0;
    const std::array<double, 3> c{0.8, 0.05, 0.05};
    for (int a = 0; a < 3; ++a) {
      const double q = std::clamp(c[a], b.min_m[a], b.max_m[a]) - c[a];
      d2 += q * q;
    }
    if (d2 <= 0.04 * 0.04) {
      EXPECT_GE(tet.depth, 6);
    }
  });
  EXPECT_TRUE(testing::check_conformity(mesh).problems.empty());
  EXPECT_TRUE(testing::check_bookkeeping(mesh).empty());
}

TEST(RefineOps, BoxRefinementAndMergeAll) {
  KuhnMesh mesh({2, 2, 2, 0.1, 9});
  const auto coarse = testing::mesh_sets(mesh);
  refine_box(mesh, {{0.0, 0.0, 0.0}, {0.05, 0.2, 0.2}}, 5);
  mesh.for_each_tet([&](TetId t, const Tet& tet) {
    if (tet_bounds_m(mesh, t).min_m[0] <= 0.05) {
      EXPECT_GE(tet.depth, 5);
    }
  });
  EXPECT_TRUE(testing::check_conformity(mesh).problems.empty());
  const std::size_t split_nodes = mesh.node_count() - coarse.nodes.size();
  EXPECT_GT(split_nodes, 0u);
  EXPECT_EQ(static_cast<std::size_t>(merge_all(mesh)), split_nodes);  // one merge per split node
  EXPECT_EQ(testing::mesh_sets(mesh), coarse);
}

TEST(RefineOps, RejectsDepthOutsideTheRangeAndBadRadius) {
  KuhnMesh mesh({1, 1, 1, 0.1, 6});
  EXPECT_THROW(refine_uniform(mesh, 7), std::invalid_argument);
  EXPECT_THROW(refine_uniform(mesh, -1), std::invalid_argument);
  EXPECT_THROW(refine_sphere(mesh, {{0, 0, 0}, NAN}, 3), std::invalid_argument);
  EXPECT_THROW(refine_sphere(mesh, {{0, 0, 0}, -1.0}, 3), std::invalid_argument);
  EXPECT_EQ(mesh.tet_count(), 6u);
}

// refine_ops.hpp: a tet touches a region when its bounding box meets it, a
// shared face included. A box that is only the plane x = 0.05 between the
// two cubes touches every tet of both (each Kuhn tet spans its cube).
TEST(RefineOps, ABoxTouchingTetsOnlyAlongAFaceRefinesThem) {
  KuhnMesh mesh({2, 1, 1, 0.05, 3});
  refine_box(mesh, {{0.05, 0.0, 0.0}, {0.05, 0.05, 0.05}}, 1);
  int left = 0, right = 0;
  mesh.for_each_tet([&](TetId t, const Tet& tet) {
    EXPECT_GE(tet.depth, 1) << "tet " << t;
    (tet_bounds_m(mesh, t).max_m[0] <= 0.05 ? left : right) += 1;
  });
  EXPECT_EQ(left, 12);
  EXPECT_EQ(right, 12);
  EXPECT_TRUE(testing::check_conformity(mesh).problems.empty());
}

}  // namespace
}  // namespace tissue::mesh
