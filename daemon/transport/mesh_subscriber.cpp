#include "transport/mesh_subscriber.hpp"

#include <cmath>

namespace tissue::transport {

x3d::SurfaceFrame frame_from_mesh_arrays(double time_s, std::span<const float> vertex_m,
                                         std::span<const std::uint8_t> vertex_level,
                                         std::span<const std::int32_t> triangle_vertex,
                                         std::span<const float> triangle_strain) {
  if (!std::isfinite(time_s)) throw MeshRejected("non_finite", "time_s is not finite");
  if (vertex_m.size() % 3 != 0)
    throw MeshRejected("size", "vertex_m holds " + std::to_string(vertex_m.size()) + " values, not 3 per vertex");
  const std::size_t nv = vertex_m.size() / 3;
  if (!vertex_level.empty() && vertex_level.size() != nv)
    throw MeshRejected("size", "vertex_refinement_level holds " + std::to_string(vertex_level.size()) + " values for " +
                                   std::to_string(nv) + " vertices");
  if (triangle_vertex.size() % 3 != 0)
    throw MeshRejected(
        "size", "triangle_vertex holds " + std::to_string(triangle_vertex.size()) + " values, not 3 per triangle");
  const std::size_t nt = triangle_vertex.size() / 3;
  if (!triangle_strain.empty() && triangle_strain.size() != nt)
    throw MeshRejected("size", "triangle_strain_energy_density_J_per_m3 holds " +
                                   std::to_string(triangle_strain.size()) + " values for " + std::to_string(nt) +
                                   " triangles");
  x3d::SurfaceFrame f;
  f.time_s = time_s;
  f.vertices_m.resize(nv);
  for (std::size_t i = 0; i < nv; ++i)
    for (std::size_t a = 0; a < 3; ++a) {
      const float x = vertex_m[3 * i + a];
      if (!std::isfinite(x))
        throw MeshRejected("non_finite", "vertex " + std::to_string(i) + " has a non-finite coordinate");
      f.vertices_m[i][a] = static_cast<double>(x);
    }
  f.triangles.resize(nt);
  for (std::size_t t = 0; t < nt; ++t)
    for (std::size_t c = 0; c < 3; ++c) {
      const std::int32_t v = triangle_vertex[3 * t + c];
      if (v < 0 || static_cast<std::size_t>(v) >= nv)
        throw MeshRejected("index", "triangle " + std::to_string(t) + " uses vertex " + std::to_string(v) + " of " +
                                        std::to_string(nv));
      f.triangles[t][c] = static_cast<std::uint32_t>(v);
    }
  f.vertex_level.assign(vertex_level.begin(), vertex_level.end());
  // Strain-energy densities are finite and >= 0; anything else (an old or
  // foreign publisher) leaves the frame without strain rather than dropping it.
  bool strain_ok = !triangle_strain.empty();
  for (const float s : triangle_strain) strain_ok = strain_ok && std::isfinite(s) && s >= 0.0f;
  if (strain_ok) {
    f.triangle_strain_energy_J_per_m3.assign(triangle_strain.begin(), triangle_strain.end());
    // Sizes and indices were checked above: this cannot throw.
    f.vertex_strain_energy_Pa = x3d::vertex_strain_from_triangles(nv, f.triangles, f.triangle_strain_energy_J_per_m3);
  }
  return f;
}

}  // namespace tissue::transport
