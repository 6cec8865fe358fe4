#include "service/mesh_snapshot.hpp"

#include "physics/forces.hpp"

namespace tissue::service {

void build_mesh_snapshot(const physics::Simulation& sim, SnapshotScratch* scratch, MeshSnapshot* out) {
  const physics::Body& body = sim.body();
  const mesh::KuhnMesh& mesh = body.mesh();
  if (scratch->topology_version != mesh.topology_version()) {
    mesh::extract_surface(mesh, &scratch->surface);
    scratch->topology_version = mesh.topology_version();
    ++scratch->extractions;
  }
  const mesh::SurfaceMesh& surface = scratch->surface;
  const std::size_t n = surface.vertex_nodes.size();
  out->sim_time_s = sim.time_s();
  // resize / assign keep capacity: steady sizes allocate nothing.
  out->vertices_m.resize(n);
  out->vertex_level.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    const physics::Vec3& x = body.x_m[surface.vertex_nodes[i]];
    out->vertices_m[i] = {x.x(), x.y(), x.z()};
    out->vertex_level[i] = mesh.node(surface.vertex_nodes[i]).depth;
  }
  out->triangles.assign(surface.triangles.begin(), surface.triangles.end());
  const std::size_t nt = surface.triangle_tet.size();
  out->triangle_strain_energy_J_per_m3.resize(nt);
  for (std::size_t t = 0; t < nt; ++t)
    out->triangle_strain_energy_J_per_m3[t] =
        static_cast<float>(physics::strain_energy_density_Pa(body, surface.triangle_tet[t]));
}

}  // namespace tissue::service
