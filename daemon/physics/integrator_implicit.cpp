#include <cmath>

#include "physics/forces.hpp"
#include "physics/integrator_impl.hpp"

namespace tissue::physics {

namespace {
double dot(const std::vector<Vec3>& a, const std::vector<Vec3>& b) {
  double s = 0.0;
  for (std::size_t i = 0; i < a.size(); ++i) s += a[i].dot(b[i]);
  return s;
}
}  // namespace

ImplicitIntegrator::ImplicitIntegrator(const scene::IntegratorSpec& spec, const scene::MaterialSpec& material)
    : spec_(spec), alpha_per_s_(material.rayleigh_alpha_per_s) {}

void ImplicitIntegrator::apply(const Body& body, const std::vector<Vec3>& p, std::vector<Vec3>& y) const {
  const std::size_t nodes = p.size();
  for (std::size_t n = 0; n < nodes; ++n) y[n] = body.mass_kg[n] * (1.0 + h_ * alpha_per_s_) * p[n];
  const std::size_t edges = block_.size();
  for (EdgeId e = 0; e < edges; ++e) {
    if (body.stiffness_N_per_m[e] == 0.0) continue;
    const NodeId a = body.edge_a[e], b = body.edge_b[e];
    const Vec3 q = block_[e] * (p[a] - p[b]);
    y[a] += q;
    y[b] -= q;
  }
  for (std::size_t n = 0; n < nodes; ++n)
    if (body.inv_mass_per_kg[n] == 0.0) y[n].setZero();  // kinematic rows are not unknowns
}

StepOutcome ImplicitIntegrator::step(Body& body, const std::vector<Vec3>& f_ext_N, double dt_s) {
  StepOutcome out;
  h_ = dt_s;
  const std::size_t nodes = body.x_m.size(), edges = body.stiffness_N_per_m.size();
  for (auto* v : {&force_, &rhs_, &r_, &z_, &p_, &ap_, &diag_inv_}) v->assign(nodes, Vec3::Zero());
  dv_.resize(nodes, Vec3::Zero());  // warm start keeps the last solution
  block_.resize(edges);
  save_.save(body);

  // Forces at the current state, and K v for the right-hand side.
  for (std::size_t n = 0; n < nodes; ++n) force_[n] = f_ext_N[n];
  add_spring_forces(body, force_);
  std::vector<Vec3>& kv = ap_;  // scratch until the CG loop needs it
  std::vector<Vec3>& diag = z_;
  for (std::size_t n = 0; n < nodes; ++n) {
    if (body.inv_mass_per_kg[n] != 0.0) force_[n] -= alpha_per_s_ * body.mass_kg[n] * body.v_m_per_s[n];
    diag[n].setConstant(body.mass_kg[n] * (1.0 + h_ * alpha_per_s_));
  }
  for (EdgeId e = 0; e < edges; ++e) {
    const double k = body.stiffness_N_per_m[e];
    if (k == 0.0) {
      block_[e].setZero();
      continue;
    }
    const NodeId a = body.edge_a[e], b = body.edge_b[e];
    const SpringFrame s = spring_frame(body, e);
    const Eigen::Matrix3d along = s.direction * s.direction.transpose();
    // Clamped Hessian: the transverse term only while stretched keeps the
    // system positive definite (Choi & Ko 2002).
    const double transverse = s.length_m > body.rest_length_m[e] ? 1.0 - body.rest_length_m[e] / s.length_m : 0.0;
    const Eigen::Matrix3d stiffness = k * (along + transverse * (Eigen::Matrix3d::Identity() - along));
    block_[e] = h_ * body.damping_N_s_per_m[e] * along + h_ * h_ * stiffness;
    const Vec3 q = stiffness * (body.v_m_per_s[a] - body.v_m_per_s[b]);
    kv[a] += q;
    kv[b] -= q;
    const Vec3 d = block_[e].diagonal();
    diag[a] += d;
    diag[b] += d;
  }
  for (std::size_t n = 0; n < nodes; ++n) {
    const bool free = body.inv_mass_per_kg[n] != 0.0;
    rhs_[n] = free ? Vec3(h_ * (force_[n] - h_ * kv[n])) : Vec3::Zero();
    diag_inv_[n] = free ? Vec3(diag[n].cwiseInverse()) : Vec3::Zero();
    if (!free) dv_[n].setZero();
  }

  // Jacobi-preconditioned CG, warm-started from the previous step's Δv.
  const double rhs_norm = std::sqrt(dot(rhs_, rhs_));
  if (!std::isfinite(rhs_norm)) {
    // Overflowing forces would otherwise read as "already converged".
    save_.restore(body);
    out.ok = false;
    out.error =
        "implicit integrator: forces are non-finite or beyond floating-point range; step rejected, "
        "previous state kept";
    return out;
  }
  apply(body, dv_, ap_);
  for (std::size_t n = 0; n < nodes; ++n) {
    r_[n] = rhs_[n] - ap_[n];
    z_[n] = diag_inv_[n].cwiseProduct(r_[n]);
    p_[n] = z_[n];
  }
  double rz = dot(r_, z_);
  double residual = rhs_norm > 0.0 ? std::sqrt(dot(r_, r_)) / rhs_norm : 0.0;
  int it = 0;
  while (residual > spec_.cg_tolerance && it < spec_.cg_max_iterations) {
    apply(body, p_, ap_);
    const double pap = dot(p_, ap_);
    if (!(pap > 0.0)) break;  // cannot happen for an SPD system; guards NaN
    const double step = rz / pap;
    for (std::size_t n = 0; n < nodes; ++n) {
      dv_[n] += step * p_[n];
      r_[n] -= step * ap_[n];
    }
    ++it;
    residual = std::sqrt(dot(r_, r_)) / rhs_norm;
    for (std::size_t n = 0; n < nodes; ++n) z_[n] = diag_inv_[n].cwiseProduct(r_[n]);
    const double rz_next = dot(r_, z_);
    const double beta = rz_next / rz;
    rz = rz_next;
    for (std::size_t n = 0; n < nodes; ++n) p_[n] = z_[n] + beta * p_[n];
  }
  out.solver_iterations = it;
  out.solver_residual = residual;

  for (std::size_t n = 0; n < nodes; ++n) {
    body.v_m_per_s[n] += dv_[n];
    body.x_m[n] += h_ * body.v_m_per_s[n];
  }
  if (!state_is_finite(body)) {
    save_.restore(body);
    std::fill(dv_.begin(), dv_.end(), Vec3::Zero());
    out.ok = false;
    out.error = "implicit integrator: state became non-finite; step rejected, previous state kept";
  }
  return out;
}

}  // namespace tissue::physics
