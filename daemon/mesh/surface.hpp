// Boundary surface of the leaf tets: what clients draw and export.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "mesh/kuhn_mesh.hpp"

namespace tissue::mesh {

struct SurfaceMesh {
  // Mesh nodes on the surface, sorted by lattice key: the same mesh always
  // yields the same order, whatever split/merge history produced it.
  std::vector<NodeId> vertex_nodes;
  // Indices into vertex_nodes, counter-clockwise seen from outside, sorted.
  std::vector<std::array<std::uint32_t, 3>> triangles;
  // Bisection depth of the tet each triangle belongs to (for colouring).
  std::vector<std::uint8_t> triangle_depth;
  // The leaf tet each triangle is a face of (same order as `triangles`):
  // what per-triangle quantities such as strain energy density come from.
  std::vector<TetId> triangle_tet;
};

// Faces of leaf tets that lie in a box face plane, outward oriented.
// Overwrites `out`. Cost O(leaf tets + F log F) for F boundary faces.
void extract_surface(const KuhnMesh& mesh, SurfaceMesh* out);

}  // namespace tissue::mesh
