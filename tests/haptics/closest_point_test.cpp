// haptics/closest_point.cpp: the closest point on a triangle, its weights
// and its Voronoi region (the contact renderer's face / edge / corner).
#include "haptics/closest_point.hpp"

#include <gtest/gtest.h>

#include <random>

namespace tissue::haptics {
namespace {

using Vec3 = Eigen::Vector3d;

TEST(ClosestPointOnTriangle, VertexEdgeAndFaceRegions) {
  const Vec3 a(0, 0, 0), b(1, 0, 0), c(0, 1, 0);
  EXPECT_EQ(closest_point_on_triangle(Vec3(-1, -1, 1), a, b, c).point_m, a);
  EXPECT_EQ(closest_point_on_triangle(Vec3(2, -0.5, 0), a, b, c).point_m, b);
  const TriangleClosest edge = closest_point_on_triangle(Vec3(0.5, -1, 3), a, b, c);
  EXPECT_NEAR((edge.point_m - Vec3(0.5, 0, 0)).norm(), 0.0, 1e-15);
  const TriangleClosest hyp = closest_point_on_triangle(Vec3(1, 1, 0), a, b, c);
  EXPECT_NEAR((hyp.point_m - Vec3(0.5, 0.5, 0)).norm(), 0.0, 1e-15);
  const TriangleClosest face = closest_point_on_triangle(Vec3(0.2, 0.3, -2), a, b, c);
  EXPECT_NEAR((face.point_m - Vec3(0.2, 0.3, 0)).norm(), 0.0, 1e-15);
  EXPECT_NEAR(face.weight[0], 0.5, 1e-15);
  EXPECT_NEAR(face.weight[1], 0.2, 1e-15);
  EXPECT_NEAR(face.weight[2], 0.3, 1e-15);
}

// Against brute force: no sampled point of the triangle is closer, and the
// weights reproduce the point.
TEST(ClosestPointOnTriangle, NoSampledPointIsCloser) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int trial = 0; trial < 200; ++trial) {
    const Vec3 a(u(rng), u(rng), u(rng)), b(u(rng), u(rng), u(rng)), c(u(rng), u(rng), u(rng)),
        p(2 * u(rng), 2 * u(rng), 2 * u(rng));
    const TriangleClosest cp = closest_point_on_triangle(p, a, b, c);
    EXPECT_LT((cp.weight[0] * a + cp.weight[1] * b + cp.weight[2] * c - cp.point_m).norm(), 1e-12);
    for (double w : cp.weight) EXPECT_GE(w, -1e-12);
    const double d = (cp.point_m - p).norm();
    for (int i = 0; i <= 20; ++i)
      for (int j = 0; i + j <= 20; ++j) {
        const Vec3 q = a + (b - a) * (i / 20.0) + (c - a) * (j / 20.0);
        EXPECT_GE((q - p).norm(), d - 1e-12);
      }
  }
}

// The region is the one the point lies in: a corner has one index, an edge
// two, the face none; and the weights vanish off it.
TEST(ClosestPointOnTriangle, NamesTheRegionItLiesIn) {
  const Vec3 a(0, 0, 0), b(1, 0, 0), c(0, 1, 0);
  const TriangleClosest corner = closest_point_on_triangle(Vec3(2, -0.5, 0), a, b, c);
  EXPECT_EQ(corner.feature_a, 1);
  EXPECT_EQ(corner.feature_b, -1);
  const TriangleClosest edge = closest_point_on_triangle(Vec3(1, 1, 0), a, b, c);
  EXPECT_EQ(edge.feature_a, 1);
  EXPECT_EQ(edge.feature_b, 2);
  EXPECT_EQ(edge.weight[0], 0.0);
  const TriangleClosest face = closest_point_on_triangle(Vec3(0.2, 0.3, -2), a, b, c);
  EXPECT_EQ(face.feature_a, -1);
  EXPECT_EQ(face.feature_b, -1);
  const TriangleClosest ac_edge = closest_point_on_triangle(Vec3(-1, 0.5, 0), a, b, c);
  EXPECT_EQ(ac_edge.feature_a, 0);
  EXPECT_EQ(ac_edge.feature_b, 2);
}

}  // namespace
}  // namespace tissue::haptics
