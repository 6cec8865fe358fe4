// haptics/closest_point.cpp: the closest point on a triangle, its weights
// and its Voronoi region (the contact renderer's face / edge / corner).
#include "haptics/closest_point.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <utility>
#include <vector>

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

// Found by the review of the haptic proxy path: a triangle with two corners
// at one point divided 0 by 0 (v = d1 / (d1 - d3)) and gave a NaN point and
// NaN weights. A triangle with no area is its edges: the closest point is
// the closest on them, with weights >= 0 that sum to 1.
TEST(ClosestPointOnTriangle, TrianglesWithNoAreaGiveTheClosestPointOnTheirEdges) {
  const Vec3 a(0, 0, 0), b(1, 0, 0), c(0, 1, 0), mid(0.5, 0, 0), far(2, 0, 0);
  struct Case {
    Vec3 a, b, c;
  };
  const std::vector<Case> degenerate{
      {a, a, c},   {a, c, a},   {c, a, a},      // two corners at one point
      {a, a, a},                                // all three
      {a, mid, b}, {a, b, mid}, {mid, far, a},  // on a line
  };
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-2.0, 2.0);
  for (std::size_t k = 0; k < degenerate.size(); ++k) {
    const Case& t = degenerate[k];
    for (int trial = 0; trial < 200; ++trial) {
      const Vec3 p(u(rng), u(rng), u(rng));
      const TriangleClosest cp = closest_point_on_triangle(p, t.a, t.b, t.c);
      ASSERT_TRUE(cp.point_m.allFinite()) << "case " << k << " p " << p.transpose();
      double sum = 0.0;
      for (double w : cp.weight) {
        ASSERT_TRUE(std::isfinite(w)) << "case " << k;
        EXPECT_GE(w, 0.0) << "case " << k;
        sum += w;
      }
      EXPECT_NEAR(sum, 1.0, 1e-12) << "case " << k;
      EXPECT_LT((cp.weight[0] * t.a + cp.weight[1] * t.b + cp.weight[2] * t.c - cp.point_m).norm(), 1e-12);
      // No point of the three edges is closer.
      const double d = (cp.point_m - p).norm();
      for (const auto& [from, to] : {std::pair{t.a, t.b}, std::pair{t.a, t.c}, std::pair{t.b, t.c}})
        for (int i = 0; i <= 100; ++i) EXPECT_GE((from + (to - from) * (i / 100.0) - p).norm(), d - 1e-12);
    }
  }
  // The first one the review found: a = b, the tool above the middle of edge ac.
  const TriangleClosest cp = closest_point_on_triangle(Vec3(0.3, 0.5, 1.0), a, a, c);
  EXPECT_TRUE(cp.point_m.isApprox(Vec3(0, 0.5, 0), 1e-15)) << cp.point_m.transpose();
  EXPECT_EQ(cp.weight[1], 0.0);
  EXPECT_NEAR(cp.weight[0], 0.5, 1e-15);
  EXPECT_NEAR(cp.weight[2], 0.5, 1e-15);
}

}  // namespace
}  // namespace tissue::haptics
