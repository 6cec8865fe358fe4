// Whole-mesh and region refinement built on KuhnMesh::split/merge.
//
// A tet "touches" a region when its axis-aligned bounding box meets the
// region (closed sets). That is conservative by at most one tet layer, which
// is what a scene's "refine near here" means, and it needs no exact
// tet/sphere intersection.
#pragma once

#include <array>
#include <functional>

#include "mesh/kuhn_mesh.hpp"

namespace tissue::mesh {

struct RegionBox {
  std::array<double, 3> min_m{};
  std::array<double, 3> max_m{};
};

struct RegionSphere {
  std::array<double, 3> centre_m{};
  double radius_m = 0.0;
};

// Bounding box of a tet in metres.
RegionBox tet_bounds_m(const KuhnMesh& mesh, TetId t);

// Splits diamonds until every leaf tet for which `wants(t)` holds has depth >=
// `depth`. Returns the number of diamonds split (closure included). Throws
// std::invalid_argument if depth is outside [0, max_depth].
int refine_where(KuhnMesh& mesh, int depth, const std::function<bool(const KuhnMesh&, TetId)>& wants,
                 MeshChangeLog* log = nullptr);

int refine_uniform(KuhnMesh& mesh, int depth, MeshChangeLog* log = nullptr);
int refine_box(KuhnMesh& mesh, const RegionBox& box, int depth, MeshChangeLog* log = nullptr);
int refine_sphere(KuhnMesh& mesh, const RegionSphere& sphere, int depth, MeshChangeLog* log = nullptr);

// Merges every split diamond, finest first, back to the 6-tet cubes.
// Returns the number of diamonds merged.
int merge_all(KuhnMesh& mesh, MeshChangeLog* log = nullptr);

}  // namespace tissue::mesh
