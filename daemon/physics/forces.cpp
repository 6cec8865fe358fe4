#include "physics/forces.hpp"

#include <Eigen/Geometry>
#include <array>
#include <cmath>

namespace tissue::physics {

SpringFrame spring_frame(const Body& body, EdgeId e) {
  const NodeId a = body.edge_a[e], b = body.edge_b[e];
  Vec3 d = body.x_m[b] - body.x_m[a];
  const double l = d.norm();
  if (l > kCollapsedSpringRatio * body.rest_length_m[e]) return {d / l, l};
  d = body.rest_m[b] - body.rest_m[a];
  const double rest = d.norm();
  return {rest > 0.0 ? Vec3(d / rest) : Vec3::Zero(), l};
}

Vec3 spring_force_on_a_N(const Body& body, EdgeId e, bool with_damper) {
  const NodeId a = body.edge_a[e], b = body.edge_b[e];
  const SpringFrame s = spring_frame(body, e);
  const double closing_speed = with_damper ? (body.v_m_per_s[b] - body.v_m_per_s[a]).dot(s.direction) : 0.0;
  return (body.stiffness_N_per_m[e] * (s.length_m - body.rest_length_m[e]) +
          body.damping_N_s_per_m[e] * closing_speed) *
         s.direction;
}

void add_spring_forces(const Body& body, std::vector<Vec3>& f, bool with_dampers) {
  const std::size_t edges = body.stiffness_N_per_m.size();
  for (EdgeId e = 0; e < edges; ++e) {
    if (body.stiffness_N_per_m[e] == 0.0) continue;  // dead edge slot
    const Vec3 force_on_a = spring_force_on_a_N(body, e, with_dampers);
    f[body.edge_a[e]] += force_on_a;
    f[body.edge_b[e]] -= force_on_a;
  }
}

void apply_spring_dampers_implicitly(Body& body, double h_s) {
  const std::size_t edges = body.damping_N_s_per_m.size();
  for (EdgeId e = 0; e < edges; ++e) {
    const double c = body.damping_N_s_per_m[e];
    if (c == 0.0) continue;
    const NodeId a = body.edge_a[e], b = body.edge_b[e];
    const double wa = body.inv_mass_per_kg[a], wb = body.inv_mass_per_kg[b];
    const double w = wa + wb;
    if (w == 0.0) continue;  // both ends kinematic
    const Vec3 d = spring_frame(body, e).direction;
    const double u = (body.v_m_per_s[b] - body.v_m_per_s[a]).dot(d);
    const double impulse = (u / (1.0 + h_s * c * w) - u) / w;  // changes u by exactly that
    body.v_m_per_s[a] -= wa * impulse * d;
    body.v_m_per_s[b] += wb * impulse * d;
  }
}

double elastic_energy_J(const Body& body) {
  // Over the body's flat edge arrays, not the mesh's edge records: the
  // implicit rung's energy guard sums this after every step, and the records
  // (and their alive test) cost it a third more memory traffic. A dead slot
  // (a = b = 0, k = 0, rest 1) adds exactly +0.0, so the sum is bit-identical
  // to one over the live edges in the same order (the adaptation pass's).
  double energy = 0.0;
  const std::size_t edges = body.stiffness_N_per_m.size();
  for (EdgeId e = 0; e < edges; ++e) {
    const double stretch = (body.x_m[body.edge_b[e]] - body.x_m[body.edge_a[e]]).norm() - body.rest_length_m[e];
    energy += 0.5 * body.stiffness_N_per_m[e] * stretch * stretch;
  }
  return energy;
}

double kinetic_energy_J(const Body& body) {
  double energy = 0.0;
  body.mesh().for_each_node(
      [&](NodeId n, const mesh::Node&) { energy += 0.5 * body.mass_kg[n] * body.v_m_per_s[n].squaredNorm(); });
  return energy;
}

namespace {
// l / L − 1 of a tet's six edges, in kTetEdgeSlots order.
std::array<double, 6> tet_edge_strains(const Body& body, TetId t) {
  const auto& v = body.mesh().tet(t).v;
  std::array<double, 6> strain{};
  for (int i = 0; i < 6; ++i) {
    const NodeId a = v[mesh::kTetEdgeSlots[i][0]], b = v[mesh::kTetEdgeSlots[i][1]];
    strain[i] = (body.x_m[b] - body.x_m[a]).norm() / (body.rest_m[b] - body.rest_m[a]).norm() - 1.0;
  }
  return strain;
}
}  // namespace

double strain_energy_density_Pa(const Body& body, TetId t) {
  double sum = 0.0;
  for (double strain : tet_edge_strains(body, t)) sum += strain * strain;
  return 0.5 * body.scene().material.youngs_modulus_Pa * sum;
}

double strain_energy_density_Pa(const std::array<const Vec3*, 4>& x_m, const std::array<double, 6>& rest_length_m,
                                double youngs_modulus_Pa) {
  double sum = 0.0;
  for (int i = 0; i < 6; ++i) {
    // The operations of tet_edge_strains, in its order: bit-identical.
    const double strain =
        (*x_m[mesh::kTetEdgeSlots[i][1]] - *x_m[mesh::kTetEdgeSlots[i][0]]).norm() / rest_length_m[i] - 1.0;
    sum += strain * strain;
  }
  return 0.5 * youngs_modulus_Pa * sum;
}

std::size_t inverted_tet_count(const Body& body) {
  std::size_t inverted = 0;
  body.mesh().for_each_tet([&](TetId t, const mesh::Tet&) {
    const auto v = body.mesh().oriented_vertices(t);
    const Vec3 a = body.x_m[v[1]] - body.x_m[v[0]], b = body.x_m[v[2]] - body.x_m[v[0]],
               c = body.x_m[v[3]] - body.x_m[v[0]];
    if (a.dot(b.cross(c)) <= 0.0) ++inverted;
  });
  return inverted;
}

double max_edge_strain(const Body& body, TetId t) {
  double worst = 0.0;
  for (double strain : tet_edge_strains(body, t)) worst = std::max(worst, std::abs(strain));
  return worst;
}

}  // namespace tissue::physics
