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

namespace {

bool is_free(const Body& body, NodeId n) { return body.inv_mass_per_kg[n] != 0.0; }

// out = (mass_scale M + h C) v over the free nodes; kinematic entries of v
// are taken as zero (their known velocities are on the right-hand side) and
// those of out are zero.
void apply_damped_mass(const Body& body, double h_s, double mass_scale, const std::vector<Vec3>& direction,
                       const std::vector<Vec3>& v, std::vector<Vec3>& out) {
  const std::size_t nodes = v.size();
  for (NodeId n = 0; n < nodes; ++n)
    out[n] = is_free(body, n) ? Vec3(mass_scale * body.mass_kg[n] * v[n]) : Vec3::Zero();
  const std::size_t edges = body.damping_N_s_per_m.size();
  for (EdgeId e = 0; e < edges; ++e) {
    const double c = body.damping_N_s_per_m[e];
    if (c == 0.0) continue;
    const NodeId a = body.edge_a[e], b = body.edge_b[e];
    const bool free_a = is_free(body, a), free_b = is_free(body, b);
    const Vec3& d = direction[e];
    const Vec3 va = free_a ? v[a] : Vec3::Zero(), vb = free_b ? v[b] : Vec3::Zero();
    const Vec3 f = (h_s * c * d.dot(va - vb)) * d;  // h × the damper's force on b, −that on a
    if (free_a) out[a] += f;
    if (free_b) out[b] -= f;
  }
}

NodeId find(std::vector<NodeId>& parent, NodeId n) {
  while (parent[n] != n) n = parent[n] = parent[parent[n]];  // path halving
  return n;
}

void join(std::vector<NodeId>& parent, NodeId a, NodeId b) {
  a = find(parent, a);
  b = find(parent, b);
  if (a != b) parent[std::max(a, b)] = std::min(a, b);
}

double dot_free(const Body& body, const std::vector<Vec3>& x, const std::vector<Vec3>& y) {
  double sum = 0.0;
  for (NodeId n = 0; n < x.size(); ++n)
    if (is_free(body, n)) sum += x[n].dot(y[n]);
  return sum;
}

// The springs' directions; b = M v plus, for a damper to a kinematic node,
// that node's known share; the Jacobi preconditioner, per component
// 1 / (mass_scale m + h Σ c d_i²) (the 3×3 blocks mass_scale m I + h Σ c d dᵀ
// inverted saved 6 % of the iterations and cost more time: the shipped
// cantilever on the projective rung, 33.3 against 35.6 per step, 0.52 against
// 0.47 s of 1.2); the sets of free nodes joined by dampers
// (union–find) and which of them a damper ties to a kinematic node.
void set_up_damper_solve(const Body& body, double h_s, double mass_scale, ImplicitDamperWork& work) {
  const std::size_t nodes = body.v_m_per_s.size(), edges = body.damping_N_s_per_m.size();
  work.direction.resize(edges);
  for (auto* v : {&work.rhs, &work.r, &work.z, &work.p, &work.q, &work.set_lost_kg_m_s}) v->resize(nodes);
  work.inv_diag.resize(nodes);
  work.component.resize(nodes);
  work.tied.assign(nodes, 0);
  for (NodeId n = 0; n < nodes; ++n) {
    const bool free = is_free(body, n);
    work.rhs[n] = free ? Vec3(body.mass_kg[n] * body.v_m_per_s[n]) : Vec3::Zero();
    work.inv_diag[n] = Vec3::Constant(free ? mass_scale * body.mass_kg[n] : 0.0);
    work.component[n] = n;
  }
  for (EdgeId e = 0; e < edges; ++e) {
    const double c = body.damping_N_s_per_m[e];
    if (c == 0.0) continue;
    const NodeId a = body.edge_a[e], b = body.edge_b[e];
    const Vec3 d = spring_frame(body, e).direction;
    work.direction[e] = d;
    const bool free_a = is_free(body, a), free_b = is_free(body, b);
    const Vec3 diagonal = h_s * c * d.cwiseProduct(d);
    if (free_a) work.inv_diag[a] += diagonal;
    if (free_b) work.inv_diag[b] += diagonal;
    if (free_a && free_b) join(work.component, a, b);
    if (free_a && !free_b) {
      work.rhs[a] += (h_s * c * d.dot(body.v_m_per_s[b])) * d;
      work.tied[a] = 1;
    }
    if (free_b && !free_a) {
      work.rhs[b] += (h_s * c * d.dot(body.v_m_per_s[a])) * d;
      work.tied[b] = 1;
    }
  }
  for (NodeId n = 0; n < nodes; ++n)
    if (is_free(body, n)) work.inv_diag[n] = work.inv_diag[n].cwiseInverse();
}

// A set of free nodes joined by dampers changes its momentum by −Σ r /
// mass_scale over it (C's rows sum to zero), a residual's worth, unless a
// damper ties it to a kinematic node (then the world takes momentum anyway).
// Spread that back over the set uniformly: its uniform motion is in C's null
// space, so the damping stays as solved and a free body keeps its momentum to
// rounding, step after step. `r` must be the true residual b − A v (CG's
// updated one drifts from it when the system is stiff).
void restore_momentum(const Body& body, double mass_scale, ImplicitDamperWork& work, std::vector<Vec3>& v) {
  const std::size_t nodes = v.size();
  work.set_mass_kg.assign(nodes, 0.0);
  for (NodeId n = 0; n < nodes; ++n) work.set_lost_kg_m_s[n] = Vec3::Zero();
  for (NodeId n = 0; n < nodes; ++n) {
    if (!is_free(body, n)) continue;
    const NodeId root = find(work.component, n);
    work.set_lost_kg_m_s[root] += work.r[n];
    work.set_mass_kg[root] += body.mass_kg[n];
    if (work.tied[n]) work.tied[root] = 1;
  }
  for (NodeId n = 0; n < nodes; ++n) {
    if (!is_free(body, n)) continue;
    const NodeId root = find(work.component, n);
    if (!work.tied[root]) v[n] += work.set_lost_kg_m_s[root] / (mass_scale * work.set_mass_kg[root]);
  }
}
}  // namespace

ImplicitDamperSolve apply_spring_dampers_implicitly(Body& body, double h_s, double mass_scale,
                                                    double relative_tolerance, ImplicitDamperWork& work) {
  set_up_damper_solve(body, h_s, mass_scale, work);
  // Preconditioned conjugate gradients on the free nodes, from v /
  // mass_scale (the answer without spring dampers).
  const std::size_t nodes = body.v_m_per_s.size();
  std::vector<Vec3>& v = body.v_m_per_s;
  for (NodeId n = 0; n < nodes; ++n)
    if (is_free(body, n)) v[n] /= mass_scale;
  apply_damped_mass(body, h_s, mass_scale, work.direction, v, work.q);
  for (NodeId n = 0; n < nodes; ++n) {
    work.r[n] = work.rhs[n] - work.q[n];
    work.z[n] = work.inv_diag[n].cwiseProduct(work.r[n]);
    work.p[n] = work.z[n];
  }
  ImplicitDamperSolve out;
  double rz = dot_free(body, work.r, work.z);
  double r_norm = std::sqrt(dot_free(body, work.r, work.r));
  const double r0_norm = r_norm;
  bool at_rounding = false;
  while (r_norm > relative_tolerance * r0_norm && out.iterations < kDamperSolveMaxIterations) {
    apply_damped_mass(body, h_s, mass_scale, work.direction, work.p, work.q);
    const double pq = dot_free(body, work.p, work.q);
    if (!(pq > 0.0)) {  // the residual is at rounding
      at_rounding = true;
      break;
    }
    const double step = rz / pq;
    for (NodeId n = 0; n < nodes; ++n) {
      if (!is_free(body, n)) continue;
      v[n] += step * work.p[n];
      work.r[n] -= step * work.q[n];
      work.z[n] = work.inv_diag[n].cwiseProduct(work.r[n]);
    }
    const double rz_next = dot_free(body, work.r, work.z);
    const double beta = rz_next / rz;
    rz = rz_next;
    for (NodeId n = 0; n < nodes; ++n)
      if (is_free(body, n)) work.p[n] = work.z[n] + beta * work.p[n];
    r_norm = std::sqrt(dot_free(body, work.r, work.r));
    ++out.iterations;
  }
  apply_damped_mass(body, h_s, mass_scale, work.direction, v, work.q);
  for (NodeId n = 0; n < nodes; ++n) work.r[n] = work.rhs[n] - work.q[n];
  out.relative_residual = r0_norm > 0.0 ? std::sqrt(dot_free(body, work.r, work.r)) / r0_norm : 0.0;
  // Converged unless stopped at the cap (the true residual can sit above the
  // tolerance at rounding: a first residual that is rounding itself).
  out.converged = at_rounding || r_norm <= relative_tolerance * r0_norm;
  restore_momentum(body, mass_scale, work, v);
  return out;
}

ImplicitDamperSolve apply_spring_dampers_implicitly(Body& body, double h_s) {
  ImplicitDamperWork work;
  return apply_spring_dampers_implicitly(body, h_s, 1.0, 1e-10, work);
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

double tet_spring_energy_J(const Body& body, const std::array<NodeId, 4>& corners, int depth,
                           const Eigen::Matrix3d& F) {
  const std::array<double, 6> shares_m3 = body.tet_edge_shares_m3(corners, depth);
  double energy_J = 0.0;
  for (int i = 0; i < 6; ++i) {
    const Vec3 rest_m =
        body.rest_m[corners[mesh::kTetEdgeSlots[i][1]]] - body.rest_m[corners[mesh::kTetEdgeSlots[i][0]]];
    const double rest_length_m = rest_m.norm(), stretch_m = (F * rest_m).norm() - rest_length_m;
    energy_J += 0.5 * body.scene().material.youngs_modulus_Pa * shares_m3[i] / (rest_length_m * rest_length_m) *
                stretch_m * stretch_m;
  }
  return energy_J;
}

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

double max_edge_stretch(const Body& body, TetId t) {
  double worst = 0.0;
  for (double strain : tet_edge_strains(body, t)) worst = std::max(worst, stretch_from_strain(strain));
  return worst;
}

}  // namespace tissue::physics
