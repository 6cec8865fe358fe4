// Backward Euler (Baraff & Witkin 1998) with the clamped spring Hessian (Choi
// & Ko 2002): solve (M' − h D − h² K) Δv = h (f + h K v), M' = (1 + h α) M, by
// Jacobi-preconditioned CG warm-started from the last step's Δv.
//
// Cost is the CG matvec: per spring per iteration two gathers, two scatters
// and ~20 flops. Measured with bench/physics_bench (Release, 2-core Debian 12
// box shared with builds, so median thread-CPU time per step; exact-geometry
// beam stand-ins for PERFORMANCE.md's R2 = 7,056 / R3 = 52,344 springs, cg20,
// dt = 1 ms): before 1.04 / 7.80 ms, after 0.82 / 6.3 ms (117–125 ns per
// spring per step, was 150–190; ~11x an explicit sub-step, was 15–19x).
// What the numbers supported:
//  - Compact blocks: B = along d̂d̂ᵀ + iso I stored as d̂ and two scalars in
//    one 48 B record with the two unknown ids, streamed in edge order (was
//    ids, stiffness and a 72 B Matrix3d from four arrays, 15 flops/product).
//  - Dead and fully kinematic springs dropped once when the list is built;
//    unknowns numbered compactly (free nodes only, kinematic ends point at a
//    sink slot whose p stays zero): no per-matvec stiffness test or masking.
//  - Forces, K v, the blocks and the Jacobi diagonal in one pass over edges.
//  - CG fused: p = z + βp with ap = M'p in one node pass; dv, r, z and both
//    dots in one; scratch resized only, never re-zeroed. pᵀAp from a node
//    pass after the spring loop: accumulating dpᵀB dp inside the spring loop
//    was 10% slower (6.3 vs 7.2 ms at R3).
//  - The spring loop is instruction-bound (~50 scalar SSE2 instructions, ~4 ns
//    per spring per matvec, IPC ~3.5); hand-written scalar code ran the same
//    as Eigen's. Going further needs AVX2/FMA (a build-flag decision) or
//    fewer iterations.
//  - Assembled block-CSR (full symmetric 3x3 blocks, row-wise gather, no
//    scatter) lost at both sizes: 0.97 / 8.6 ms vs 0.82 / 6.5 ms matrix-free
//    (BM_ImplicitMatvec): the assembly is an extra pass and each edge is read
//    twice as a 76 B entry. Kept as an option; a test checks they agree.
//  - Block-Jacobi (3x3 per node) needed more iterations than Jacobi at the
//    1e-6 tolerance (R2 38.8 -> 42.5, R3 77.5 -> 80.3), so Jacobi stays.
// Everything is sequential in a fixed order: bit-identical reruns.
#include <cmath>
#include <limits>

#include "physics/forces.hpp"
#include "physics/integrator_impl.hpp"

namespace tissue::physics {

ImplicitIntegrator::ImplicitIntegrator(const scene::IntegratorSpec& spec, const scene::MaterialSpec& material,
                                       Matvec matvec)
    : spec_(spec), alpha_per_s_(material.rayleigh_alpha_per_s), matvec_(matvec) {}

double ImplicitIntegrator::apply_matrix_free() {
  double pap = 0.0;
  const Vec3* p = p_.data();
  Vec3* ap = ap_.data();
  for (const Spring& s : springs_) {
    const Vec3 d(s.d[0], s.d[1], s.d[2]);
    const Vec3 dp = p[s.a] - p[s.b];
    const double along = d.dot(dp);
    const Vec3 q = (s.along * along) * d + s.iso * dp;
    ap[s.a] += q;
    ap[s.b] -= q;
  }
  for (std::uint32_t i = 0; i < unknowns_; ++i) pap += p[i].dot(ap[i]);
  return pap;
}

double ImplicitIntegrator::apply_assembled() {
  double pap = 0.0;
  const Vec3* p = p_.data();
  for (std::uint32_t i = 0; i < unknowns_; ++i) {
    Vec3 y = diag_block_[i] * p[i];
    for (std::uint32_t k = row_start_[i]; k < row_start_[i + 1]; ++k) y.noalias() += off_block_[k] * p[col_[k]];
    ap_[i] = y;
    pap += p[i].dot(y);
  }
  ap_[unknowns_].setZero();
  return pap;
}

double ImplicitIntegrator::apply(bool update_p, double beta) {
  if (matvec_ == Matvec::kAssembledBlockCsr) {
    if (update_p)
      for (std::uint32_t i = 0; i < unknowns_; ++i) p_[i] = z_[i] + beta * p_[i];
    return apply_assembled();
  }
  for (std::uint32_t i = 0; i < unknowns_; ++i) {
    if (update_p) p_[i] = z_[i] + beta * p_[i];
    ap_[i] = mass_[i] * p_[i];
  }
  ap_[unknowns_].setZero();  // the sink collects kinematic ends' shares; never read
  return apply_matrix_free();
}

void ImplicitIntegrator::assemble() {
  const std::uint32_t sink = unknowns_;
  row_start_.assign(unknowns_ + 2, 0);
  for (const Spring& s : springs_) {
    if (s.a != sink && s.b != sink) {
      ++row_start_[s.a + 2];
      ++row_start_[s.b + 2];
    }
  }
  for (std::uint32_t i = 0; i < unknowns_; ++i) row_start_[i + 2] += row_start_[i + 1];
  col_.resize(row_start_[unknowns_ + 1]);
  off_block_.resize(row_start_[unknowns_ + 1]);
  diag_block_.resize(unknowns_ + 1);
  for (std::uint32_t i = 0; i < unknowns_; ++i) diag_block_[i] = mass_[i] * Eigen::Matrix3d::Identity();
  diag_block_[sink].setZero();  // collects kinematic ends' shares; never read
  // row_start_[i + 1] is the fill cursor of row i; it ends at row i + 1's start.
  for (const Spring& s : springs_) {
    const Vec3 d(s.d[0], s.d[1], s.d[2]);
    const Eigen::Matrix3d block = s.along * d * d.transpose() + s.iso * Eigen::Matrix3d::Identity();
    diag_block_[s.a] += block;
    diag_block_[s.b] += block;
    if (s.a != sink && s.b != sink) {
      col_[row_start_[s.a + 1]] = s.b;
      off_block_[row_start_[s.a + 1]++] = -block;
      col_[row_start_[s.b + 1]] = s.a;
      off_block_[row_start_[s.b + 1]++] = -block;
    }
  }
}

void ImplicitIntegrator::system_product(const std::vector<Vec3>& p_by_node, std::vector<Vec3>& y_by_node) {
  y_by_node.assign(p_by_node.size(), Vec3::Zero());
  if (p_.empty()) return;  // no step yet: no system
  for (std::uint32_t i = 0; i < unknowns_; ++i) p_[i] = p_by_node[node_of_unknown_[i]];
  p_[unknowns_].setZero();
  apply(false, 0.0);
  for (std::uint32_t i = 0; i < unknowns_; ++i) y_by_node[node_of_unknown_[i]] = ap_[i];
}

StepOutcome ImplicitIntegrator::step(Body& body, const std::vector<Vec3>& f_ext_N, double dt_s) {
  StepOutcome out;
  h_ = dt_s;
  const double h = h_;
  const std::size_t nodes = body.x_m.size(), edges = body.stiffness_N_per_m.size();
  save_.save(body);

  // Unknowns: the free nodes, numbered in node order; the rest share the sink.
  constexpr std::uint32_t kNone = std::numeric_limits<std::uint32_t>::max();
  unknown_of_node_.resize(nodes);
  node_of_unknown_.clear();
  for (NodeId n = 0; n < nodes; ++n) {
    unknown_of_node_[n] = body.inv_mass_per_kg[n] != 0.0 ? static_cast<std::uint32_t>(node_of_unknown_.size()) : kNone;
    if (unknown_of_node_[n] != kNone) node_of_unknown_.push_back(n);
  }
  unknowns_ = static_cast<std::uint32_t>(node_of_unknown_.size());
  const std::uint32_t sink = unknowns_;
  for (auto& u : unknown_of_node_)
    if (u == kNone) u = sink;
  const std::size_t slots = unknowns_ + 1u;
  for (auto* v : {&diag_inv_, &force_, &kv_, &rhs_, &dv_, &r_, &z_, &p_, &ap_}) v->resize(slots);
  mass_.resize(slots);
  dv_by_node_.resize(nodes, Vec3::Zero());  // warm start, by node id across mesh changes

  const double mass_scale = 1.0 + h * alpha_per_s_;
  for (std::uint32_t i = 0; i < unknowns_; ++i) {
    const NodeId n = node_of_unknown_[i];
    mass_[i] = body.mass_kg[n] * mass_scale;
    force_[i] = f_ext_N[n] - alpha_per_s_ * body.mass_kg[n] * body.v_m_per_s[n];
    kv_[i].setZero();
    diag_inv_[i].setConstant(mass_[i]);  // the diagonal, inverted below
  }
  // One pass over the edges: spring and damper forces, K v, the compact
  // blocks and the diagonal. The sink slot collects shares nobody reads.
  springs_.clear();
  for (EdgeId e = 0; e < edges; ++e) {
    const double k = body.stiffness_N_per_m[e];
    if (k == 0.0) continue;  // dead edge slot
    const NodeId na = body.edge_a[e], nb = body.edge_b[e];
    const std::uint32_t a = unknown_of_node_[na], b = unknown_of_node_[nb];
    if (a == sink && b == sink) continue;  // both ends kinematic: no unknown
    const SpringFrame s = spring_frame(body, e);
    const Vec3& d = s.direction;
    const double c = body.damping_N_s_per_m[e], rest = body.rest_length_m[e];
    const Vec3 dv_ab = body.v_m_per_s[na] - body.v_m_per_s[nb];
    const Vec3 force_on_a = (k * (s.length_m - rest) - c * dv_ab.dot(d)) * d;  // as add_spring_forces
    force_[a] += force_on_a;
    force_[b] -= force_on_a;
    // Clamped Hessian: the transverse term only while stretched keeps the
    // system positive definite (Choi & Ko 2002).
    const double transverse = s.length_m > rest ? 1.0 - rest / s.length_m : 0.0;
    const double k_along = k * (1.0 - transverse), k_iso = k * transverse;
    const Vec3 q = (k_along * d.dot(dv_ab)) * d + k_iso * dv_ab;
    kv_[a] += q;
    kv_[b] -= q;
    const double along = h * c + h * h * k_along, iso = h * h * k_iso;
    const Vec3 block_diag = (along * d.cwiseAbs2()).array() + iso;
    diag_inv_[a] += block_diag;
    diag_inv_[b] += block_diag;
    springs_.push_back({a, b, {d.x(), d.y(), d.z()}, along, iso});
  }
  for (std::uint32_t i = 0; i < unknowns_; ++i) {
    rhs_[i] = h * (force_[i] - h * kv_[i]);
    diag_inv_[i] = diag_inv_[i].cwiseInverse();
    dv_[i] = dv_by_node_[node_of_unknown_[i]];
  }
  for (auto* v : {&diag_inv_, &rhs_, &dv_, &r_, &z_, &p_, &ap_}) (*v)[sink].setZero();
  mass_[sink] = 0.0;
  if (matvec_ == Matvec::kAssembledBlockCsr) assemble();

  double rhs_sq = 0.0;
  for (std::uint32_t i = 0; i < unknowns_; ++i) rhs_sq += rhs_[i].squaredNorm();
  const double rhs_norm = std::sqrt(rhs_sq);
  if (!std::isfinite(rhs_norm)) {
    // Overflowing forces would otherwise read as "already converged".
    save_.restore(body);
    out.ok = false;
    out.error =
        "implicit integrator: forces are non-finite or beyond floating-point range; step rejected, "
        "previous state kept";
    return out;
  }

  // Jacobi-preconditioned CG from the previous step's Δv.
  std::copy(dv_.begin(), dv_.begin() + unknowns_, p_.begin());
  apply(false, 0.0);
  double rz = 0.0, rr = 0.0;
  for (std::uint32_t i = 0; i < unknowns_; ++i) {
    r_[i] = rhs_[i] - ap_[i];
    z_[i] = diag_inv_[i].cwiseProduct(r_[i]);
    p_[i] = z_[i];
    rz += r_[i].dot(z_[i]);
    rr += r_[i].squaredNorm();
  }
  double residual = rhs_norm > 0.0 ? std::sqrt(rr) / rhs_norm : 0.0;
  double beta = 0.0;
  int it = 0;
  while (residual > spec_.cg_tolerance && it < spec_.cg_max_iterations) {
    const double pap = apply(it > 0, beta);  // p = z + βp fused into the matvec's node pass
    if (!(pap > 0.0)) break;                 // cannot happen for an SPD system; guards NaN
    const double step = rz / pap;
    double rz_next = 0.0;
    rr = 0.0;
    for (std::uint32_t i = 0; i < unknowns_; ++i) {
      dv_[i] += step * p_[i];
      r_[i] -= step * ap_[i];
      z_[i] = diag_inv_[i].cwiseProduct(r_[i]);
      rz_next += r_[i].dot(z_[i]);
      rr += r_[i].squaredNorm();
    }
    ++it;
    residual = std::sqrt(rr) / rhs_norm;
    beta = rz_next / rz;
    rz = rz_next;
  }
  out.solver_iterations = it;
  out.solver_residual = residual;

  for (std::uint32_t i = 0; i < unknowns_; ++i) {
    const NodeId n = node_of_unknown_[i];
    dv_by_node_[n] = dv_[i];
    body.v_m_per_s[n] += dv_[i];
  }
  for (std::size_t n = 0; n < nodes; ++n) body.x_m[n] += h * body.v_m_per_s[n];  // kinematic: own velocity
  if (!state_is_finite(body)) {
    save_.restore(body);
    std::fill(dv_by_node_.begin(), dv_by_node_.end(), Vec3::Zero());
    out.ok = false;
    out.error = "implicit integrator: state became non-finite; step rejected, previous state kept";
  }
  return out;
}

}  // namespace tissue::physics
