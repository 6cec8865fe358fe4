#include "mesh/surface.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <set>

#include "mesh/refine_ops.hpp"

namespace tissue::mesh {
namespace {

struct SurfaceFacts {
  bool every_directed_edge_once = true;  // closed and consistently oriented
  long long euler = 0;
  double area = 0;           // lattice units^2
  double signed_volume = 0;  // divergence theorem, lattice units^3
};

SurfaceFacts facts_of(const KuhnMesh& mesh, const SurfaceMesh& s) {
  SurfaceFacts f;
  std::map<std::pair<std::uint32_t, std::uint32_t>, int> directed;
  std::set<std::pair<std::uint32_t, std::uint32_t>> undirected;
  for (const auto& t : s.triangles) {
    for (int i = 0; i < 3; ++i) {
      const std::uint32_t a = t[i], b = t[(i + 1) % 3];
      ++directed[{a, b}];
      undirected.insert({std::min(a, b), std::max(a, b)});
    }
    std::array<std::array<double, 3>, 3> p{};
    for (int i = 0; i < 3; ++i)
      for (int a = 0; a < 3; ++a) p[i][a] = static_cast<double>(mesh.node(s.vertex_nodes[t[i]]).lattice[a]);
    const std::array<double, 3> u{p[1][0] - p[0][0], p[1][1] - p[0][1], p[1][2] - p[0][2]};
    const std::array<double, 3> v{p[2][0] - p[0][0], p[2][1] - p[0][1], p[2][2] - p[0][2]};
    const std::array<double, 3> n{u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]};
    f.area += 0.5 * std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    f.signed_volume += (p[0][0] * n[0] + p[0][1] * n[1] + p[0][2] * n[2]) / 6.0;
  }
  for (const auto& [e, count] : directed) {
    const bool twin = directed.count({e.second, e.first}) == 1;
    if (count != 1 || !twin) f.every_directed_edge_once = false;
  }
  f.euler = static_cast<long long>(s.vertex_nodes.size()) - static_cast<long long>(undirected.size()) +
            static_cast<long long>(s.triangles.size());
  return f;
}

// Every triangle names a live leaf tet that really owns that face: the tet's
// four nodes include the triangle's three, and its depth is the triangle's.
void expect_triangles_face_their_tets(const KuhnMesh& mesh, const SurfaceMesh& s) {
  ASSERT_EQ(s.triangle_tet.size(), s.triangles.size());
  std::size_t leaf_tets = 0;
  mesh.for_each_tet([&](TetId, const Tet&) { ++leaf_tets; });
  std::set<TetId> distinct;
  for (std::size_t i = 0; i < s.triangles.size(); ++i) {
    const TetId t = s.triangle_tet[i];
    ASSERT_TRUE(mesh.tet_alive(t)) << "triangle " << i;
    const Tet& tet = mesh.tet(t);
    for (const std::uint32_t v : s.triangles[i]) {
      const NodeId n = s.vertex_nodes[v];
      EXPECT_NE(std::find(tet.v.begin(), tet.v.end(), n), tet.v.end())
          << "triangle " << i << " vertex " << v << " is not a node of tet " << t;
    }
    EXPECT_EQ(tet.depth, s.triangle_depth[i]) << "triangle " << i;
    distinct.insert(t);
  }
  // Not one tet for everything: the faces are spread over the boundary tets.
  EXPECT_GT(distinct.size(), 1u);
  EXPECT_LE(distinct.size(), leaf_tets);
}

void expect_closed_box_surface(const KuhnMesh& mesh) {
  SurfaceMesh s;
  extract_surface(mesh, &s);
  const auto f = facts_of(mesh, s);
  EXPECT_TRUE(f.every_directed_edge_once);
  EXPECT_EQ(f.euler, 2);
  const LatticeDomain& d = mesh.domain();
  const double x = double(d.extent(0)), y = double(d.extent(1)), z = double(d.extent(2));
  EXPECT_NEAR(f.area, 2 * (x * y + y * z + z * x), 1e-6 * x * y);
  EXPECT_NEAR(f.signed_volume, x * y * z, 1e-6 * x * y * z) << "triangles must face outward";
  ASSERT_EQ(s.triangle_depth.size(), s.triangles.size());
  expect_triangles_face_their_tets(mesh, s);
}

TEST(Surface, CoarseBoxIsClosedOutwardWithEulerTwo) {
  KuhnMesh mesh({4, 4, 4, 0.025, 9});
  expect_closed_box_surface(mesh);
  SurfaceMesh s;
  extract_surface(mesh, &s);
  EXPECT_EQ(s.vertex_nodes.size(), 125u - 27u);  // all but the 3^3 interior nodes
  EXPECT_EQ(s.triangles.size(), 6u * 16u * 2u);
}

TEST(Surface, AdaptiveMeshSurfaceIsClosedAndOutward) {
  KuhnMesh mesh({3, 2, 1, 0.1, 9});
  refine_sphere(mesh, {{0.3, 0.0, 0.1}, 0.05}, 8);
  refine_box(mesh, {{0.0, 0.0, 0.0}, {0.1, 0.2, 0.02}}, 4);
  expect_closed_box_surface(mesh);
}

TEST(Surface, OrderIsStableAcrossDifferentHistories) {
  KuhnMesh a({2, 2, 1, 0.1, 9});
  KuhnMesh b({2, 2, 1, 0.1, 9});
  refine_sphere(a, {{0.2, 0.2, 0.1}, 0.03}, 7);
  // b reaches the same mesh after a detour (uniform refinement, merge, and
  // refinement in another order), so its ids differ.
  refine_uniform(b, 3);
  merge_all(b);
  refine_sphere(b, {{0.2, 0.2, 0.1}, 0.03}, 4);
  refine_sphere(b, {{0.2, 0.2, 0.1}, 0.03}, 7);
  SurfaceMesh sa, sb;
  extract_surface(a, &sa);
  extract_surface(b, &sb);
  ASSERT_EQ(sa.vertex_nodes.size(), sb.vertex_nodes.size());
  for (std::size_t i = 0; i < sa.vertex_nodes.size(); ++i)
    EXPECT_EQ(a.node_key(sa.vertex_nodes[i]), b.node_key(sb.vertex_nodes[i]));
  EXPECT_EQ(sa.triangles, sb.triangles);
  EXPECT_EQ(sa.triangle_depth, sb.triangle_depth);
}

}  // namespace
}  // namespace tissue::mesh
