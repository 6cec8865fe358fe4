#include "physics/boundary.hpp"

#include <Eigen/Geometry>
#include <map>

#include "mesh/surface.hpp"

namespace tissue::physics {

namespace {

void set_kinematic_velocity(Body& body, NodeId n, double t_next_s, double dt_s) {
  if (body.kind[n] == NodeKind::kFixed) {
    body.v_m_per_s[n] = (body.rest_m[n] - body.x_m[n]) / dt_s;
  } else if (body.kind[n] == NodeKind::kPrescribed) {
    const auto& p = body.scene().prescribed[static_cast<std::size_t>(body.prescribed_index[n])];
    const Vec3 d(p.displacement_m[0], p.displacement_m[1], p.displacement_m[2]);
    body.v_m_per_s[n] = (body.rest_m[n] + p.profile.at(t_next_s) * d - body.x_m[n]) / dt_s;
  }
}

}  // namespace

void set_kinematic_velocities(Body& body, double t_next_s, double dt_s) {
  body.mesh().for_each_node([&](NodeId n, const mesh::Node&) { set_kinematic_velocity(body, n, t_next_s, dt_s); });
}

void set_kinematic_velocities(Body& body, const std::vector<NodeId>& kinematic, double t_next_s, double dt_s) {
  for (const NodeId n : kinematic) set_kinematic_velocity(body, n, t_next_s, dt_s);
}

void kinematic_nodes(const Body& body, std::vector<NodeId>& out) {
  out.clear();
  body.mesh().for_each_node([&](NodeId n, const mesh::Node&) {
    if (body.kind[n] == NodeKind::kFixed || body.kind[n] == NodeKind::kPrescribed) out.push_back(n);
  });
}

std::map<NodeId, double> load_node_weights(const Body& body, const mesh::SurfaceMesh& surface,
                                           const scene::Region& region) {
  const double tol = 1e-6 * body.mesh().lattice_unit_m();
  auto in_region = [&](NodeId n) {
    return region.contains({body.rest_m[n][0], body.rest_m[n][1], body.rest_m[n][2]}, tol);
  };
  std::map<NodeId, double> weight;  // ordered: deterministic sums
  for (const auto& tri : surface.triangles) {
    const NodeId a = surface.vertex_nodes[tri[0]], b = surface.vertex_nodes[tri[1]], c = surface.vertex_nodes[tri[2]];
    if (!in_region(a) || !in_region(b) || !in_region(c)) continue;
    const double area = 0.5 * (body.rest_m[b] - body.rest_m[a]).cross(body.rest_m[c] - body.rest_m[a]).norm();
    for (NodeId n : {a, b, c}) weight[n] += area / 3.0;
  }
  if (weight.empty())
    body.mesh().for_each_node([&](NodeId n, const mesh::Node&) {
      if (in_region(n)) weight[n] += body.mass_kg[n];
    });
  return weight;
}

void LoadDistribution::rebuild(const Body& body) {
  const auto& loads = body.scene().loads;
  shares_.assign(loads.size(), {});
  if (loads.empty()) return;
  mesh::SurfaceMesh surface;
  mesh::extract_surface(body.mesh(), &surface);
  for (std::size_t i = 0; i < loads.size(); ++i) {
    const std::map<NodeId, double> weight = load_node_weights(body, surface, loads[i].region);
    double total = 0.0;
    for (const auto& [n, w] : weight) total += w;
    for (const auto& [n, w] : weight) shares_[i].emplace_back(n, w / total);
  }
}

void LoadDistribution::external_forces(const Body& body, double t_s, std::vector<Vec3>& f_ext_N) const {
  const auto& g = body.scene().gravity_m_per_s2;
  const Vec3 gravity(g[0], g[1], g[2]);
  f_ext_N.resize(body.x_m.size());
  for (std::size_t n = 0; n < f_ext_N.size(); ++n) f_ext_N[n] = body.mass_kg[n] * gravity;
  const auto& loads = body.scene().loads;
  for (std::size_t i = 0; i < loads.size(); ++i) {
    const double scale = loads[i].profile.at(t_s);
    if (scale == 0.0) continue;
    const Vec3 total(loads[i].total_force_N[0], loads[i].total_force_N[1], loads[i].total_force_N[2]);
    for (const auto& [n, w] : shares_[i]) f_ext_N[n] += scale * w * total;
  }
}

}  // namespace tissue::physics
