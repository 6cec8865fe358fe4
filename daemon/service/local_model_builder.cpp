#include "service/local_model_builder.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace tissue::service {

using physics::Vec3;

void LocalModelBuilder::refresh_surface(const physics::Simulation& sim) {
  // The mesh's own version (unique across meshes, bumped by every change),
  // as the surface snapshot uses: counts of splits and merges would repeat
  // for another simulation handed to the same builder.
  const std::uint64_t revision = sim.body().mesh().topology_version();
  if (surface_known_ && revision == surface_revision_) return;
  mesh::extract_surface(sim.body().mesh(), &surface_);
  contact_.mesh_changed();
  surface_revision_ = revision;
  surface_known_ = true;
}

void LocalModelBuilder::build(physics::Simulation& sim, const PatchQuery& query, haptics::LocalModel* out,
                              bool frozen) {
  if (!sim.has_tool()) throw std::logic_error("LocalModelBuilder: the scene has no tool");
  refresh_surface(sim);
  const physics::Body& body = sim.body();
  const scene::ToolSpec& tool = *sim.scene().tool;
  const auto& tri = surface_.triangles;
  const auto& nodes = surface_.vertex_nodes;
  auto pos = [&](std::uint32_t surface_vertex) -> const Vec3& { return body.x_m[nodes[surface_vertex]]; };

  // Nearest surface point, and each triangle's distance for the patch.
  by_distance_.clear();
  haptics::TriangleClosest nearest{Vec3::Zero(), {1.0, 0.0, 0.0}, 0, -1};
  std::uint32_t nearest_tri = 0;
  double nearest_d = std::numeric_limits<double>::infinity();
  for (std::uint32_t t = 0; t < tri.size(); ++t) {
    const haptics::TriangleClosest cp =
        haptics::closest_point_on_triangle(query.tool_m, pos(tri[t][0]), pos(tri[t][1]), pos(tri[t][2]));
    const double d = (cp.point_m - query.tool_m).norm();
    if (d < nearest_d) {
      nearest_d = d;
      nearest = cp;
      nearest_tri = t;
    }
    if (d <= tool.patch_radius_m) by_distance_.emplace_back(d, t);
  }
  surface_distance_m_ = nearest_d;
  if (by_distance_.empty() && !tri.empty()) by_distance_.emplace_back(nearest_d, nearest_tri);
  std::sort(by_distance_.begin(), by_distance_.end());

  // Patch: nearest triangles first while both capacities hold.
  patch_index_.assign(nodes.size(), -1);
  out->vertex_count = 0;
  out->triangle_count = 0;
  for (const auto& [d, t] : by_distance_) {
    if (out->triangle_count == haptics::LocalModel::kMaxPatchTriangles) break;
    int needed = 0;
    for (std::uint32_t v : tri[t]) needed += patch_index_[v] < 0 ? 1 : 0;
    if (out->vertex_count + needed > haptics::LocalModel::kMaxPatchVertices) continue;
    std::array<std::int32_t, 3> local{};
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t v = tri[t][k];
      if (patch_index_[v] < 0) {
        const int i = out->vertex_count++;
        patch_index_[v] = i;
        out->vertex_m[i] = body.x_m[nodes[v]];
        // Frozen, the surface stands still: the velocities of the step
        // before the pause would have the haptic side extrapolate the patch
        // along them and damp against a surface that does not move.
        out->vertex_velocity_m_per_s[i] = frozen ? Vec3::Zero() : body.v_m_per_s[nodes[v]];
        out->vertex_node[i] = nodes[v];
      }
      local[k] = patch_index_[v];
    }
    out->triangle[out->triangle_count++] = local;
  }

  // Contact reference and stiffness.
  out->sim_time_s = sim.time_s();
  const Vec3 force_N = sim.tool_force_N();
  // Frozen, the body takes no force: a held tool force (pressed when the
  // simulation was paused) would have the haptic side render an object that
  // yields under the tool, though nothing under it ever moves.
  out->in_contact = !frozen && force_N.squaredNorm() > 0.0;
  std::uint32_t contact_node = nodes.empty() ? 0 : nodes[tri[nearest_tri][0]];
  if (out->in_contact) {
    Vec3 x0 = Vec3::Zero();
    double best_w = -1.0;
    for (int k = 0; k < 3; ++k) {
      x0 += query.contact_weight[k] * body.x_m[query.contact_node[k]];
      if (query.contact_weight[k] > best_w) {
        best_w = query.contact_weight[k];
        contact_node = query.contact_node[k];
      }
    }
    out->position_ref_m = x0;
    out->force_ref_N = force_N;
  } else {
    out->position_ref_m = nearest.point_m;
    out->force_ref_N.setZero();
    const int k =
        static_cast<int>(std::max_element(nearest.weight.begin(), nearest.weight.end()) - nearest.weight.begin());
    if (!tri.empty()) contact_node = nodes[tri[nearest_tri][k]];
  }
  const bool engaged = out->in_contact || nearest_d <= tool.engage_distance_m;
  out->contact_stiffness_N_per_m =
      engaged && !tri.empty() ? contact_.stiffness_N_per_m_at_node(body, contact_node) : physics::Mat3::Zero();
}

}  // namespace tissue::service
