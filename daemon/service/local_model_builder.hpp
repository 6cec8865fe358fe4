// Builds the LocalModel the 1 kHz haptic loop renders against (see
// haptics/local_model.hpp) from the simulation's current state around the
// tool, after every sim step:
//   - the surface patch: surface triangles with a vertex within
//     tool.patch_radius_m of the tool, nearest first, up to the model's fixed
//     capacity, with positions, velocities and mesh node ids;
//   - the contact reference: while the tool pushes (the simulation holds a
//     tool force), the pushed point (the force's barycentric point) and that
//     force; otherwise the surface point nearest the tool and zero force;
//   - K_c, the static condensation at the contact node, only while the tool
//     is within tool.engage_distance_m of the surface (it costs three sparse
//     back-substitutions, and a refactorisation after a mesh change).
// A frozen build (the paused simulation: not stepped, taking no force)
// describes the surface as a rigid wall standing still: zero velocities, no
// contact reference (in_contact false, force_ref zero, position_ref the
// nearest surface point), whatever force the simulation still holds.
// Runs on the sim thread; allocates only when the mesh changed.
#pragma once

#include <cstdint>

#include "haptics/closest_point.hpp"
#include "haptics/local_model.hpp"
#include "mesh/surface.hpp"
#include "physics/contact_stiffness.hpp"
#include "physics/simulation.hpp"

namespace tissue::service {

struct PatchQuery {
  physics::Vec3 tool_m = physics::Vec3::Zero();  // tool tip (the proxy) in the scene frame
  // The touched triangle's nodes and weights when the tool pushes (from the
  // newest ToolSample); ignored when the simulation holds no tool force.
  std::array<std::uint32_t, 3> contact_node{};
  std::array<double, 3> contact_weight{};
};

class LocalModelBuilder {
 public:
  // Fills everything in `out` but version and built_ns (the publisher's).
  // Requires a scene with a tool. `frozen`: see above.
  void build(physics::Simulation& sim, const PatchQuery& query, haptics::LocalModel* out, bool frozen = false);

  // Distance from the tool to the surface at the last build [m].
  double surface_distance_m() const { return surface_distance_m_; }
  int factorizations() const { return contact_.factorizations(); }

 private:
  void refresh_surface(const physics::Simulation& sim);

  mesh::SurfaceMesh surface_;
  bool surface_known_ = false;
  std::uint64_t surface_revision_ = 0;  // mesh topology_version() when surface_ was extracted
  physics::ContactStiffness contact_;
  std::vector<std::pair<double, std::uint32_t>> by_distance_;  // (distance, triangle)
  std::vector<std::int32_t> patch_index_;                      // surface vertex -> patch vertex, -1
  double surface_distance_m_ = 0.0;
};

}  // namespace tissue::service
