#include <cmath>

#include "physics/forces.hpp"
#include "physics/integrator_impl.hpp"

namespace tissue::physics {

ProjectiveIntegrator::ProjectiveIntegrator(const scene::IntegratorSpec& spec, const scene::MaterialSpec& material)
    : spec_(spec), alpha_per_s_(material.rayleigh_alpha_per_s) {}

void ProjectiveIntegrator::factor(const Body& body, double dt_s) {
  // Global matrix M/h² + Σ_e k_e A_eᵀA_e over the free nodes (the same for x,
  // y and z). Its pattern changes with every split/merge, so it is rebuilt
  // and refactored once per adaptation batch, not per operation.
  const std::size_t nodes = body.x_m.size();
  dof_of_node_.assign(nodes, -1);
  node_of_dof_.clear();
  for (NodeId n = 0; n < nodes; ++n)
    if (body.inv_mass_per_kg[n] != 0.0) {
      dof_of_node_[n] = static_cast<int>(node_of_dof_.size());
      node_of_dof_.push_back(n);
    }
  const int dofs = static_cast<int>(node_of_dof_.size());
  std::vector<Eigen::Triplet<double>> triplets;
  triplets.reserve(static_cast<std::size_t>(dofs) + 4 * body.mesh().edge_count());
  const double inv_h2 = 1.0 / (dt_s * dt_s);
  for (int i = 0; i < dofs; ++i) triplets.emplace_back(i, i, body.mass_kg[node_of_dof_[i]] * inv_h2);
  body.mesh().for_each_edge([&](EdgeId e, const mesh::Edge&) {
    const double k = body.stiffness_N_per_m[e];
    const int a = dof_of_node_[body.edge_a[e]], b = dof_of_node_[body.edge_b[e]];
    if (a >= 0) triplets.emplace_back(a, a, k);
    if (b >= 0) triplets.emplace_back(b, b, k);
    if (a >= 0 && b >= 0) {
      triplets.emplace_back(a, b, -k);
      triplets.emplace_back(b, a, -k);
    }
  });
  Eigen::SparseMatrix<double> system(dofs, dofs);
  system.setFromTriplets(triplets.begin(), triplets.end());
  solver_.compute(system);
  factor_valid_ = solver_.info() == Eigen::Success;
  factored_dt_s_ = dt_s;
  factored_version_ = body.parameters_version();
}

StepOutcome ProjectiveIntegrator::step(Body& body, const std::vector<Vec3>& f_ext_N, double dt_s) {
  StepOutcome out;
  // The body's version changes with every split, merge and parameter
  // rebuild, so a caller that adapts it without mesh_changed() still gets a
  // system of the right size (a stale one would index past its numbering).
  if (!factor_valid_ || factored_dt_s_ != dt_s || factored_version_ != body.parameters_version()) factor(body, dt_s);
  if (!factor_valid_) {
    out.ok = false;
    out.error = "projective integrator: factorisation of the global system failed";
    return out;
  }
  save_.save(body);
  const std::size_t nodes = body.x_m.size();
  const int dofs = static_cast<int>(node_of_dof_.size());
  const double h = dt_s, inv_h2 = 1.0 / (h * h);
  inertial_.resize(nodes);
  x_prev_ = body.x_m;
  // Inertial target y = x + h v + h² M⁻¹ f_ext; kinematic nodes move with
  // their velocity and act as known positions in the global solve.
  for (std::size_t n = 0; n < nodes; ++n)
    inertial_[n] = body.x_m[n] + h * body.v_m_per_s[n] + h * h * body.inv_mass_per_kg[n] * f_ext_N[n];
  // Start the local/global descent from whichever of y and x_n (kinematic
  // nodes moved) has the lower objective ½|x − y|²_M / h² + E_el(x): next to
  // a fixed face y can be hugely stretched in a stiff material, and a capped
  // number of iterations would not recover from it.
  auto objective = [&]() {
    double inertia = 0.0;
    for (std::size_t n = 0; n < nodes; ++n) inertia += body.mass_kg[n] * (body.x_m[n] - inertial_[n]).squaredNorm();
    return 0.5 * inertia * inv_h2 + elastic_energy_J(body);
  };
  for (std::size_t n = 0; n < nodes; ++n)
    if (body.inv_mass_per_kg[n] == 0.0) body.x_m[n] = inertial_[n];
  const double from_current = objective();
  for (std::size_t n = 0; n < nodes; ++n) body.x_m[n] = inertial_[n];
  if (from_current < objective())
    for (std::size_t n = 0; n < nodes; ++n)
      if (body.inv_mass_per_kg[n] != 0.0) body.x_m[n] = x_prev_[n];
  rhs_.resize(dofs, 3);
  solution_.resize(dofs, 3);
  // Stopping rule. Local/global descent converges linearly, at a rate ρ that
  // nears 1 for stiff material and long steps; a small change per iteration
  // then does not mean a small error. So the error is estimated from the
  // change and the rate measured between iterations, ρ/(1−ρ)·change (the
  // a-posteriori bound of a contraction), and held to cg_tolerance times the
  // scale of what the step does: the larger of the nodes' motion over the
  // step and their displacement from rest. (An absolute tolerance of
  // cg_tolerance · cube size stopped after one iteration at E = 1e9 Pa,
  // dt = 1/30 s, where the whole motion was 13 cube-size tolerances: the tip
  // was 43 % short.) Rounding ends it too: a change below 1e-12 cube sizes
  // is a fixed point (the rate measured there is noise), and the scale has a
  // floor of 1e-9 cube sizes, so a body at rest is not chased into it.
  const double cube_m = body.mesh().lattice_unit_m() * body.mesh().domain().coarse_cube();
  int it = 0;
  double change = INFINITY, previous_change = INFINITY, error_m = INFINITY, scale_m = 0.0;
  const auto converged = [&] { return error_m <= spec_.cg_tolerance * std::max(scale_m, 1e-9 * cube_m); };
  while (it < spec_.cg_max_iterations && !converged()) {
    for (int i = 0; i < dofs; ++i)
      rhs_.row(i) = (body.mass_kg[node_of_dof_[i]] * inv_h2 * inertial_[node_of_dof_[i]]).transpose();
    // Local step: each spring's projection onto its rest length.
    body.mesh().for_each_edge([&](EdgeId e, const mesh::Edge&) {
      const double k = body.stiffness_N_per_m[e];
      const NodeId na = body.edge_a[e], nb = body.edge_b[e];
      const SpringFrame s = spring_frame(body, e);
      const Vec3 d = -body.rest_length_m[e] * s.direction;  // target for x_a − x_b
      const int a = dof_of_node_[na], b = dof_of_node_[nb];
      if (a >= 0) rhs_.row(a) += (k * d).transpose();
      if (b >= 0) rhs_.row(b) -= (k * d).transpose();
      if (a >= 0 && b < 0) rhs_.row(a) += (k * body.x_m[nb]).transpose();
      if (b >= 0 && a < 0) rhs_.row(b) += (k * body.x_m[na]).transpose();
    });
    solution_ = solver_.solve(rhs_);
    change = 0.0;
    scale_m = 0.0;
    for (int i = 0; i < dofs; ++i) {
      const NodeId n = node_of_dof_[i];
      const Vec3 next = solution_.row(i).transpose();
      change = std::max(change, (next - body.x_m[n]).cwiseAbs().maxCoeff());
      scale_m = std::max(
          scale_m, std::max((next - x_prev_[n]).cwiseAbs().maxCoeff(), (next - body.rest_m[n]).cwiseAbs().maxCoeff()));
      body.x_m[n] = next;
    }
    // The first iteration has no rate yet: its change is its error estimate.
    const double rate = it == 0 ? 1.0 : change / previous_change;
    error_m = it == 0 ? change : (rate < 1.0 ? change * rate / (1.0 - rate) : INFINITY);
    if (change <= 1e-12 * cube_m) error_m = 0.0;  // a fixed point, to rounding
    previous_change = change;
    ++it;
  }
  out.solver_iterations = it;
  out.solver_residual = error_m;
  out.solver_converged = converged();
  for (std::size_t n = 0; n < nodes; ++n) {
    if (body.inv_mass_per_kg[n] == 0.0) continue;
    body.v_m_per_s[n] = (body.x_m[n] - x_prev_[n]) / h;
  }
  // The local/global solve has no dampers; apply them (and the mass
  // damping) implicitly to the new velocities: the next step's inertial
  // target carries them into the positions. (Re-deriving positions from the
  // damped velocities was tried and diverged: the positions stay those of
  // the solve.) A damper solve short of cg_tolerance makes the step
  // unconverged, as the local/global iterations' do (reports count both).
  const ImplicitDamperSolve dampers =
      apply_spring_dampers_implicitly(body, h, 1.0 + h * alpha_per_s_, spec_.cg_tolerance, dampers_);
  out.solver_converged = out.solver_converged && dampers.converged;

  if (!state_is_finite(body)) {
    save_.restore(body);
    out.ok = false;
    out.error = "projective integrator: state became non-finite; step rejected, previous state kept";
  }
  return out;
}

std::unique_ptr<Integrator> make_integrator(const scene::IntegratorSpec& spec, const scene::MaterialSpec& material) {
  switch (spec.kind) {
    case scene::IntegratorKind::kExplicit:
      return std::make_unique<ExplicitIntegrator>(spec, material);
    case scene::IntegratorKind::kImplicit:
      return std::make_unique<ImplicitIntegrator>(spec, material, ImplicitIntegrator::Matvec::kMatrixFree,
                                                  detected_simd(), implicit_preconditioner(spec.cg_preconditioner));
    case scene::IntegratorKind::kProjective:
      return std::make_unique<ProjectiveIntegrator>(spec, material);
  }
  return nullptr;
}

}  // namespace tissue::physics
