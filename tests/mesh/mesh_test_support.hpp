// Independent checks of a KuhnMesh, recomputed from scratch from the leaf
// tets only (no use of the mesh's incremental bookkeeping).
#pragma once

#include <map>
#include <set>
#include <string>
#include <vector>

#include "mesh/kuhn_mesh.hpp"

namespace tissue::mesh::testing {

struct ConformityReport {
  std::size_t interior_faces = 0;
  std::size_t boundary_faces = 0;
  std::vector<std::string> problems;  // empty when conforming
};

// Every interior face shared by exactly two leaf tets, every unshared face in a
// box face plane, positive volumes summing exactly to the box volume.
ConformityReport check_conformity(const KuhnMesh& mesh);

// Recomputes per-node and per-edge 6V sums, the edge set and the node set from
// the leaf tets, and compares them with the mesh's incremental values.
std::vector<std::string> check_bookkeeping(const KuhnMesh& mesh);

// Canonical sets for comparing two meshes: node keys, edge keys, and tets as
// sorted vertex-key quadruples.
struct MeshSets {
  std::set<Key> nodes;
  std::set<Key> edges;
  std::set<std::array<Key, 4>> tets;
  bool operator==(const MeshSets&) const = default;
};
MeshSets mesh_sets(const KuhnMesh& mesh);

// Euclidean edge lengths (lattice units) of a tet, sorted ascending.
std::array<double, 6> sorted_edge_lengths(const KuhnMesh& mesh, TetId t);

// Signed 6V in lattice units from coordinates.
long long signed_six_volume(const KuhnMesh& mesh, const std::array<NodeId, 4>& v);

}  // namespace tissue::mesh::testing
