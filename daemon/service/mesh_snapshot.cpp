#include "service/mesh_snapshot.hpp"

#include <algorithm>

#include "mesh/mesh_change.hpp"
#include "physics/forces.hpp"

namespace tissue::service {

namespace {

// After an extraction: the distinct tets behind the triangles, in order of
// first use (triangles are sorted by vertex, so neighbours stay close in
// memory). A tet shows up to three faces; slot_of_tet maps tet id -> slot and
// is reset entry by entry afterwards, so at steady sizes nothing allocates.
void index_surface_tets(const physics::Body& body, SnapshotScratch* scratch) {
  constexpr std::uint32_t kNoSlot = 0xffffffffu;
  const mesh::SurfaceMesh& surface = scratch->surface;
  if (scratch->slot_of_tet.size() < body.mesh().tet_capacity())
    scratch->slot_of_tet.resize(body.mesh().tet_capacity(), kNoSlot);
  scratch->tets.clear();
  scratch->triangle_slot.resize(surface.triangle_tet.size());
  for (std::size_t t = 0; t < surface.triangle_tet.size(); ++t) {
    const mesh::TetId tet = surface.triangle_tet[t];
    std::uint32_t& slot = scratch->slot_of_tet[tet];
    if (slot == kNoSlot) {
      slot = static_cast<std::uint32_t>(scratch->tets.size());
      SnapshotScratch::SurfaceTet entry;
      entry.tet = tet;
      entry.nodes = body.mesh().tet(tet).v;
      for (int i = 0; i < 6; ++i) {
        const mesh::NodeId a = entry.nodes[mesh::kTetEdgeSlots[i][0]], b = entry.nodes[mesh::kTetEdgeSlots[i][1]];
        entry.rest_length_m[i] = (body.rest_m[b] - body.rest_m[a]).norm();
      }
      scratch->tets.push_back(entry);
    }
    scratch->triangle_slot[t] = slot;
  }
  for (const SnapshotScratch::SurfaceTet& entry : scratch->tets) scratch->slot_of_tet[entry.tet] = kNoSlot;
}

// Each surface vertex's level: the deepest tet behind a triangle at it.
void surface_vertex_levels(const mesh::KuhnMesh& mesh, SnapshotScratch* scratch) {
  const mesh::SurfaceMesh& surface = scratch->surface;
  scratch->vertex_level.assign(surface.vertex_nodes.size(), 0);
  for (std::size_t t = 0; t < surface.triangles.size(); ++t) {
    const std::uint8_t depth = mesh.tet(surface.triangle_tet[t]).depth;
    for (const std::uint32_t v : surface.triangles[t])
      scratch->vertex_level[v] = std::max(scratch->vertex_level[v], depth);
  }
}

}  // namespace

void build_mesh_snapshot(const physics::Simulation& sim, SnapshotScratch* scratch, MeshSnapshot* out) {
  const physics::Body& body = sim.body();
  const mesh::KuhnMesh& mesh = body.mesh();
  if (scratch->topology_version != mesh.topology_version()) {
    mesh::extract_surface(mesh, &scratch->surface);
    index_surface_tets(body, scratch);
    surface_vertex_levels(mesh, scratch);
    scratch->topology_version = mesh.topology_version();
    ++scratch->extractions;
  }
  const mesh::SurfaceMesh& surface = scratch->surface;
  const std::size_t n = surface.vertex_nodes.size();
  out->sim_time_s = sim.time_s();
  // resize / assign keep capacity: steady sizes allocate nothing.
  out->vertices_m.resize(n);
  out->vertex_level.assign(scratch->vertex_level.begin(), scratch->vertex_level.end());
  for (std::size_t i = 0; i < n; ++i) {
    const physics::Vec3& x = body.x_m[surface.vertex_nodes[i]];
    out->vertices_m[i] = {x.x(), x.y(), x.z()};
  }
  out->triangles.assign(surface.triangles.begin(), surface.triangles.end());
  const double youngs_modulus_Pa = sim.scene().material.youngs_modulus_Pa;
  scratch->tet_strain_J_per_m3.resize(scratch->tets.size());
  for (std::size_t k = 0; k < scratch->tets.size(); ++k) {
    const SnapshotScratch::SurfaceTet& tet = scratch->tets[k];
    const std::array<const physics::Vec3*, 4> x{&body.x_m[tet.nodes[0]], &body.x_m[tet.nodes[1]],
                                                &body.x_m[tet.nodes[2]], &body.x_m[tet.nodes[3]]};
    scratch->tet_strain_J_per_m3[k] =
        static_cast<float>(physics::strain_energy_density_Pa(x, tet.rest_length_m, youngs_modulus_Pa));
  }
  out->triangle_strain_energy_J_per_m3.resize(scratch->triangle_slot.size());
  for (std::size_t t = 0; t < scratch->triangle_slot.size(); ++t)
    out->triangle_strain_energy_J_per_m3[t] = scratch->tet_strain_J_per_m3[scratch->triangle_slot[t]];
}

}  // namespace tissue::service
