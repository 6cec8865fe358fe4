#include "transport/lcm_messages.hpp"

#include "transport/mesh_bounds.hpp"

namespace tissue::transport {

void to_message(const service::MeshSnapshot& s, std::int64_t sequence, tissue_lcm::tissue::surface_mesh* out) {
  const auto n = static_cast<std::int32_t>(s.vertices_m.size());
  const auto t = static_cast<std::int32_t>(s.triangles.size());
  out->time_s = s.sim_time_s;
  out->sequence_number = sequence;
  out->vertex_count = n;
  out->vertex_coordinate_count = 3 * n;
  out->vertex_m.resize(3 * static_cast<std::size_t>(n));
  out->vertex_refinement_level.resize(static_cast<std::size_t>(n));
  for (std::int32_t i = 0; i < n; ++i) {
    for (int a = 0; a < 3; ++a) out->vertex_m[3 * i + a] = static_cast<float>(s.vertices_m[i][a]);
    out->vertex_refinement_level[i] = static_cast<std::int8_t>(vertex_level(s, static_cast<std::size_t>(i)));
  }
  out->triangle_count = t;
  out->triangle_index_count = 3 * t;
  out->triangle_vertex.resize(3 * static_cast<std::size_t>(t));
  for (std::int32_t i = 0; i < t; ++i)
    for (int k = 0; k < 3; ++k) out->triangle_vertex[3 * i + k] = static_cast<std::int32_t>(s.triangles[i][k]);
  out->triangle_strain_energy_density_J_per_m3.resize(static_cast<std::size_t>(t));
  for (std::int32_t i = 0; i < t; ++i)
    out->triangle_strain_energy_density_J_per_m3[i] = triangle_strain(s, static_cast<std::size_t>(i));
  const MeshBounds bounds = mesh_bounds(s);
  for (int a = 0; a < 3; ++a) {
    out->bounds_min_m[a] = bounds.min_m[a];
    out->bounds_max_m[a] = bounds.max_m[a];
  }
}

tissue_lcm::tissue::sim_stats to_message(const service::SimStatus& s, std::int64_t sequence) {
  tissue_lcm::tissue::sim_stats m{};
  m.time_s = s.sim_time_s;
  m.sequence_number = sequence;
  m.real_time_factor = s.real_time_factor;
  m.step_ms = s.step_ms_last;
  m.node_count = static_cast<std::int32_t>(s.nodes);
  m.tet_count = static_cast<std::int32_t>(s.tets);
  m.spring_count = static_cast<std::int32_t>(s.springs);
  m.refine_count = s.refines;
  m.merge_count = s.merges;
  m.kinetic_energy_J = s.kinetic_energy_J;
  m.elastic_energy_J = s.elastic_energy_J;
  return m;
}

tissue_lcm::tissue::haptic_state haptic_message(const service::SimStatus& s, std::int64_t sequence) {
  tissue_lcm::tissue::haptic_state m{};
  m.time_s = s.sim_time_s;
  m.sequence_number = sequence;
  for (int a = 0; a < 3; ++a) {
    m.device_position_m[a] = s.device_position_m[a];
    m.proxy_position_m[a] = s.proxy_position_m[a];
    m.force_N[a] = s.force_on_device_N[a];
  }
  m.in_contact = s.tool_contact;
  m.local_model_version = static_cast<std::int64_t>(s.tick_model_version);
  return m;
}

}  // namespace tissue::transport
