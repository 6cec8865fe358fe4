#include "mesh/surface.hpp"

#include <algorithm>
#include <numeric>

namespace tissue::mesh {

namespace {
// Outward faces of a positively oriented tet (v0, v1, v2, v3).
constexpr std::array<std::array<int, 3>, 4> kOutwardFaces{{{1, 2, 3}, {0, 3, 2}, {0, 1, 3}, {0, 2, 1}}};

struct Face {
  std::array<NodeId, 3> v;
  std::uint8_t depth;
  TetId tet;
};
struct Tri {
  std::array<std::uint32_t, 3> idx;
  std::uint8_t depth;
  TetId tet;
};
}  // namespace

void extract_surface(const KuhnMesh& mesh, SurfaceMesh* out) {
  const LatticeDomain& domain = mesh.domain();
  // Per-thread scratch, kept between calls: the sim thread extracts the
  // surface for every snapshot, and a steady surface then allocates nothing.
  thread_local std::vector<Face> faces;
  thread_local std::vector<Tri> tris;
  faces.clear();
  tris.clear();
  mesh.for_each_tet([&](TetId t, const Tet& tet) {
    // Cheap reject: a tet with no vertex on the boundary has no boundary face.
    bool any = false;
    for (NodeId n : tet.v)
      for (int a = 0; a < 3 && !any; ++a) any = domain.on_boundary(mesh.node(n).lattice, a);
    if (!any) return;
    const auto v = mesh.oriented_vertices(t);
    for (const auto& f : kOutwardFaces) {
      const Vec3i& p0 = mesh.node(v[f[0]]).lattice;
      const Vec3i& p1 = mesh.node(v[f[1]]).lattice;
      const Vec3i& p2 = mesh.node(v[f[2]]).lattice;
      for (int a = 0; a < 3; ++a) {
        if (domain.on_boundary(p0, a) && p0[a] == p1[a] && p0[a] == p2[a]) {
          faces.push_back({{v[f[0]], v[f[1]], v[f[2]]}, tet.depth, t});
          break;
        }
      }
    }
  });

  out->vertex_nodes.clear();
  for (const Face& f : faces) out->vertex_nodes.insert(out->vertex_nodes.end(), f.v.begin(), f.v.end());
  std::sort(out->vertex_nodes.begin(), out->vertex_nodes.end(),
            [&](NodeId a, NodeId b) { return mesh.node_key(a) < mesh.node_key(b); });
  out->vertex_nodes.erase(std::unique(out->vertex_nodes.begin(), out->vertex_nodes.end()), out->vertex_nodes.end());
  auto index_of = [&](NodeId n) {
    const Key k = mesh.node_key(n);
    auto it = std::lower_bound(out->vertex_nodes.begin(), out->vertex_nodes.end(), k,
                               [&](NodeId m, Key key) { return mesh.node_key(m) < key; });
    return static_cast<std::uint32_t>(it - out->vertex_nodes.begin());
  };

  tris.reserve(faces.size());
  for (const Face& f : faces) {
    std::array<std::uint32_t, 3> idx{index_of(f.v[0]), index_of(f.v[1]), index_of(f.v[2])};
    // Rotate (keeping orientation) so the smallest index leads: canonical form.
    std::rotate(idx.begin(), std::min_element(idx.begin(), idx.end()), idx.end());
    tris.push_back({idx, f.depth, f.tet});
  }
  std::sort(tris.begin(), tris.end(), [](const Tri& a, const Tri& b) { return a.idx < b.idx; });
  out->triangles.resize(tris.size());
  out->triangle_depth.resize(tris.size());
  out->triangle_tet.resize(tris.size());
  for (std::size_t i = 0; i < tris.size(); ++i) {
    out->triangles[i] = tris[i].idx;
    out->triangle_depth[i] = tris[i].depth;
    out->triangle_tet[i] = tris[i].tet;
  }
}

}  // namespace tissue::mesh
