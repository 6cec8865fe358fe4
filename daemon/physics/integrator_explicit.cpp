#include <algorithm>
#include <cmath>
#include <sstream>

#include "physics/forces.hpp"
#include "physics/integrator.hpp"
#include "physics/integrator_impl.hpp"

namespace tissue::physics {

Simd detected_simd() {
#if defined(__x86_64__)
  static const Simd simd = __builtin_cpu_supports("avx2") ? Simd::kAvx2 : Simd::kScalar;
  return simd;
#else
  return Simd::kScalar;
#endif
}

double explicit_stable_dt_s(const Body& body) {
  const std::size_t nodes = body.x_m.size();
  std::vector<double> sum_k(nodes, 0.0), sum_c(nodes, 0.0);
  body.mesh().for_each_edge([&](EdgeId e, const mesh::Edge& edge) {
    sum_k[edge.a] += body.stiffness_N_per_m[e];
    sum_k[edge.b] += body.stiffness_N_per_m[e];
    sum_c[edge.a] += body.damping_N_s_per_m[e];
    sum_c[edge.b] += body.damping_N_s_per_m[e];
  });
  double omega2 = 0.0, gamma = 0.0;
  for (std::size_t n = 0; n < nodes; ++n) {
    if (body.inv_mass_per_kg[n] == 0.0) continue;  // kinematic nodes do not oscillate
    omega2 = std::max(omega2, 2.0 * sum_k[n] * body.inv_mass_per_kg[n]);
    gamma = std::max(gamma, 2.0 * sum_c[n] * body.inv_mass_per_kg[n]);
  }
  if (omega2 <= 0.0) return gamma > 0.0 ? 2.0 / gamma : INFINITY;
  const double omega = std::sqrt(omega2);
  const double zeta = gamma / (2.0 * omega);
  return 2.0 / omega * (std::sqrt(1.0 + zeta * zeta) - zeta);
}

bool state_is_finite(const Body& body) {
  constexpr double kLimit = 1e100;
  bool finite = true;
  body.mesh().for_each_node([&](NodeId n, const mesh::Node&) {
    finite = finite && body.x_m[n].cwiseAbs().maxCoeff() < kLimit && body.v_m_per_s[n].cwiseAbs().maxCoeff() < kLimit;
  });
  return finite;  // NaN fails every comparison, so it is caught too
}

ExplicitIntegrator::ExplicitIntegrator(const scene::IntegratorSpec& spec, const scene::MaterialSpec& material)
    : spec_(spec), alpha_per_s_(material.rayleigh_alpha_per_s) {}

StepOutcome ExplicitIntegrator::step(Body& body, const std::vector<Vec3>& f_ext_N, double dt_s) {
  if (!bound_valid_) {
    stable_dt_s_ = explicit_stable_dt_s(body);
    bound_valid_ = true;
  }
  StepOutcome out;
  const double limit = spec_.substep_safety * stable_dt_s_;
  const double needed = std::ceil(dt_s / limit);
  if (!(needed <= spec_.max_substeps)) {
    std::ostringstream os;
    os << "explicit integrator: dt_s = " << dt_s << " needs " << needed << " sub-steps (stable sub-step " << limit
       << " s), more than integrator.max_substeps = " << spec_.max_substeps
       << "; lower dt_s, raise max_substeps, or use the implicit integrator";
    out.ok = false;
    out.error = os.str();
    return out;
  }
  out.substeps = std::max(1, static_cast<int>(needed));
  const double h = dt_s / out.substeps;
  save_.save(body);
  force_.resize(body.x_m.size());
  const std::size_t nodes = body.x_m.size();
  for (int s = 0; s < out.substeps; ++s) {
    for (std::size_t n = 0; n < nodes; ++n) force_[n] = f_ext_N[n];
    add_spring_forces(body, force_);
    // Symplectic Euler (kick, then drift). Spring dampers are explicit so
    // every mode gets its exact Rayleigh ratio; the stable bound accounts for
    // them. Mass-proportional damping is taken implicitly (free of any bound).
    for (std::size_t n = 0; n < nodes; ++n) {
      const double w = body.inv_mass_per_kg[n];
      if (w != 0.0) body.v_m_per_s[n] = (body.v_m_per_s[n] + h * w * force_[n]) / (1.0 + h * alpha_per_s_);
      body.x_m[n] += h * body.v_m_per_s[n];
    }
  }
  if (!state_is_finite(body)) {
    save_.restore(body);
    out.ok = false;
    out.error = "explicit integrator: state became non-finite; step rejected, previous state kept";
  }
  return out;
}

}  // namespace tissue::physics
