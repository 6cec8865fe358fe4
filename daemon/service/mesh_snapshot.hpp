// The surface handed from the sim thread to everything off the hot threads
// (publishers, recorder, export): what it holds and how it is built.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "mesh/surface.hpp"
#include "physics/simulation.hpp"

namespace tissue::service {

// The surface as the sim thread last saw it. Positions in the scene frame.
struct MeshSnapshot {
  std::uint64_t sequence = 0;  // 0: none yet
  double sim_time_s = 0.0;
  std::vector<std::array<double, 3>> vertices_m;
  std::vector<std::array<std::uint32_t, 3>> triangles;  // counter-clockwise seen from outside
  // Per vertex, the bisection depth of the finest surface tet at it (0: the
  // starting Kuhn tets), so a colouring shows where the mesh is refined; the
  // depth of the diamond that made the node would show a lattice corner
  // inside a refined region as 0.
  std::vector<std::uint8_t> vertex_level;
  // Strain-energy density of the leaf tet behind each triangle, J/m^3 (= Pa),
  // one per triangle; empty when not computed.
  std::vector<float> triangle_strain_energy_J_per_m3;
};

// What the builder keeps between snapshots: the surface of the topology it
// last saw. Extraction walks every leaf tet and sorts the boundary faces;
// between splits and merges only positions and strain change, so the
// surface is reused while the mesh's topology_version() stays the same.
// Strain needs, per triangle, the tet behind it: the distinct surface tets
// with their nodes and rest edge lengths are kept too (rest lengths change
// only with the topology), so a snapshot evaluates each tet once and takes
// no square roots of rest vectors.
struct SnapshotScratch {
  mesh::SurfaceMesh surface;
  std::uint64_t topology_version = 0;  // 0: nothing extracted yet
  std::uint64_t extractions = 0;       // how often the surface was rebuilt (diagnostics, tests)
  struct SurfaceTet {
    mesh::TetId tet;
    std::array<mesh::NodeId, 4> nodes;
    std::array<double, 6> rest_length_m;  // mesh::kTetEdgeSlots order
  };
  std::vector<SurfaceTet> tets;              // distinct tets behind the triangles
  std::vector<std::uint32_t> triangle_slot;  // triangle -> index into tets
  std::vector<float> tet_strain_J_per_m3;    // per snapshot, per entry of tets
  std::vector<std::uint32_t> slot_of_tet;    // tet id -> slot while indexing; all "none" between
  std::vector<std::uint8_t> vertex_level;    // per surface vertex (MeshSnapshot::vertex_level), per topology
};

// Fills `out` (all but `sequence`) from the simulation's current state.
// Reuses the storage of `out` and `scratch`: at steady sizes it allocates
// nothing, so the sim thread can call it between steps.
void build_mesh_snapshot(const physics::Simulation& sim, SnapshotScratch* scratch, MeshSnapshot* out);

}  // namespace tissue::service
