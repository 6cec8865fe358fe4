#include "transport/dds_messages.hpp"

#include "transport/mesh_bounds.hpp"

#include <algorithm>
#include <limits>

namespace tissue::transport {

void to_dds(const service::MeshSnapshot& s, std::int64_t sequence, ::tissue::surface_mesh* out) {
  const std::size_t n = s.vertices_m.size();
  const std::size_t t = s.triangles.size();
  out->time_s(s.sim_time_s);
  out->sequence_number(sequence);
  std::vector<float>& xyz = out->vertex_m();
  std::vector<std::uint8_t>& level = out->vertex_refinement_level();
  xyz.resize(3 * n);
  level.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    for (std::size_t a = 0; a < 3; ++a) xyz[3 * i + a] = static_cast<float>(s.vertices_m[i][a]);
    level[i] = vertex_level(s, i);
  }
  std::vector<std::int32_t>& tri = out->triangle_vertex();
  tri.resize(3 * t);
  for (std::size_t i = 0; i < t; ++i)
    for (std::size_t k = 0; k < 3; ++k) tri[3 * i + k] = static_cast<std::int32_t>(s.triangles[i][k]);
  std::vector<float>& strain = out->triangle_strain_energy_density_J_per_m3();
  strain.resize(t);
  for (std::size_t i = 0; i < t; ++i) strain[i] = triangle_strain(s, i);
  const MeshBounds b = mesh_bounds(s);
  out->bounds_min_m(b.min_m);
  out->bounds_max_m(b.max_m);
}

::tissue::sim_stats to_dds_stats(const service::SimStatus& s, std::int64_t sequence) {
  ::tissue::sim_stats m;
  m.time_s(s.sim_time_s);
  m.sequence_number(sequence);
  m.real_time_factor(s.real_time_factor);
  m.step_ms(s.step_ms_last);
  m.node_count(static_cast<std::int32_t>(s.nodes));
  m.tet_count(static_cast<std::int32_t>(s.tets));
  m.spring_count(static_cast<std::int32_t>(s.springs));
  m.refine_count(s.refines);
  m.merge_count(s.merges);
  m.kinetic_energy_J(s.kinetic_energy_J);
  m.elastic_energy_J(s.elastic_energy_J);
  return m;
}

::tissue::haptic_state to_dds_haptic(const service::SimStatus& s, std::int64_t sequence) {
  ::tissue::haptic_state m;
  m.time_s(s.sim_time_s);
  m.sequence_number(sequence);
  m.device_position_m(s.device_position_m);
  m.proxy_position_m(s.proxy_position_m);
  m.force_N(s.force_on_device_N);
  m.in_contact(s.tool_contact);
  m.local_model_version(static_cast<std::int64_t>(s.tick_model_version));
  return m;
}

}  // namespace tissue::transport
