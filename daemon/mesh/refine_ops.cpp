#include "mesh/refine_ops.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace tissue::mesh {

RegionBox tet_bounds_m(const KuhnMesh& mesh, TetId t) {
  RegionBox b;
  b.min_m = {INFINITY, INFINITY, INFINITY};
  b.max_m = {-INFINITY, -INFINITY, -INFINITY};
  for (NodeId n : mesh.tet(t).v) {
    const auto p = mesh.node_position_m(n);
    for (int a = 0; a < 3; ++a) {
      b.min_m[a] = std::min(b.min_m[a], p[a]);
      b.max_m[a] = std::max(b.max_m[a], p[a]);
    }
  }
  return b;
}

int refine_where(KuhnMesh& mesh, int depth, const std::function<bool(const KuhnMesh&, TetId)>& wants,
                 MeshChangeLog* log) {
  if (depth < 0 || depth > mesh.spec().max_depth)
    throw std::invalid_argument("refine: depth " + std::to_string(depth) +
                                " is outside [0, max_depth = " + std::to_string(mesh.spec().max_depth) + "]");
  int splits = 0;
  std::vector<Key> pending;
  // Each pass deepens every wanted shallow tet by at least one level, so at
  // most `depth` passes run. Keys are sorted so the result is deterministic.
  for (;;) {
    pending.clear();
    mesh.for_each_tet([&](TetId t, const Tet& tet) {
      if (tet.depth < depth && wants(mesh, t)) pending.push_back(mesh.diamond_of(t));
    });
    if (pending.empty()) break;
    std::sort(pending.begin(), pending.end());
    pending.erase(std::unique(pending.begin(), pending.end()), pending.end());
    for (Key d : pending) splits += mesh.split(d, log);
  }
  return splits;
}

int refine_uniform(KuhnMesh& mesh, int depth, MeshChangeLog* log) {
  return refine_where(
      mesh, depth, [](const KuhnMesh&, TetId) { return true; }, log);
}

int refine_box(KuhnMesh& mesh, const RegionBox& box, int depth, MeshChangeLog* log) {
  return refine_where(
      mesh, depth,
      [&box](const KuhnMesh& m, TetId t) {
        const RegionBox b = tet_bounds_m(m, t);
        for (int a = 0; a < 3; ++a)
          if (b.max_m[a] < box.min_m[a] || b.min_m[a] > box.max_m[a]) return false;
        return true;
      },
      log);
}

int refine_sphere(KuhnMesh& mesh, const RegionSphere& sphere, int depth, MeshChangeLog* log) {
  if (!(sphere.radius_m >= 0.0) || !std::isfinite(sphere.radius_m))
    throw std::invalid_argument("refine_sphere: radius_m must be finite and >= 0");
  return refine_where(
      mesh, depth,
      [&sphere](const KuhnMesh& m, TetId t) {
        const RegionBox b = tet_bounds_m(m, t);
        double d2 = 0.0;
        for (int a = 0; a < 3; ++a) {
          const double c = std::clamp(sphere.centre_m[a], b.min_m[a], b.max_m[a]);
          d2 += (c - sphere.centre_m[a]) * (c - sphere.centre_m[a]);
        }
        return d2 <= sphere.radius_m * sphere.radius_m;
      },
      log);
}

int merge_all(KuhnMesh& mesh, MeshChangeLog* log) {
  std::vector<std::pair<int, Key>> split_nodes;  // (-depth, key): finest first
  mesh.for_each_node([&](NodeId n, const Node& node) {
    if (node.edge_a != kInvalidId) split_nodes.emplace_back(-static_cast<int>(node.depth), mesh.node_key(n));
  });
  std::sort(split_nodes.begin(), split_nodes.end());
  for (const auto& [neg_depth, key] : split_nodes) mesh.merge(key, log);
  return static_cast<int>(split_nodes.size());
}

}  // namespace tissue::mesh
