// Axis-aligned bounds of a snapshot's vertices, as every mesh message carries
// them (zeros for an empty mesh). One definition for the LCM and DDS encoders.
#pragma once

#include <algorithm>
#include <array>
#include <limits>

#include "service/sim_thread.hpp"

namespace tissue::transport {

struct MeshBounds {
  std::array<double, 3> min_m{}, max_m{};
};

inline MeshBounds mesh_bounds(const service::MeshSnapshot& s) {
  MeshBounds b;
  if (s.vertices_m.empty()) return b;
  b.min_m.fill(std::numeric_limits<double>::infinity());
  b.max_m.fill(-std::numeric_limits<double>::infinity());
  for (const auto& v : s.vertices_m)
    for (int a = 0; a < 3; ++a) {
      b.min_m[a] = std::min(b.min_m[a], v[a]);
      b.max_m[a] = std::max(b.max_m[a], v[a]);
    }
  return b;
}

// The level of vertex i; a snapshot whose level array is short (a bug, never
// a crash) sends 0.
inline std::uint8_t vertex_level(const service::MeshSnapshot& s, std::size_t i) {
  return i < s.vertex_level.size() ? s.vertex_level[i] : std::uint8_t{0};
}

// Strain-energy density of the tet behind triangle i (J/m^3); a snapshot
// without strain (empty, or short: a bug, never a crash) sends 0.
inline float triangle_strain(const service::MeshSnapshot& s, std::size_t i) {
  return i < s.triangle_strain_energy_J_per_m3.size() ? s.triangle_strain_energy_J_per_m3[i] : 0.0f;
}

}  // namespace tissue::transport
