// Lanczos on S = W^½ K W^½ (W the inverse masses, zero on kinematic nodes:
// their rows drop out), which has the eigenvalues of M⁻¹K on the free
// nodes. No reorthogonalisation: it only matters for interior eigenvalues;
// the largest Ritz value of the tridiagonal T_k stays a lower bound of λmax.
#include "physics/frequency_estimate.hpp"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <random>

namespace tissue::physics {

int lanczos_iterations(std::size_t unknowns, double relative_gap, double failure_probability) {
  const double n = static_cast<double>(std::max<std::size_t>(unknowns, 1));
  // 1.648 √n e^(−√ε (2k − 1)) ≤ δ  ⇔  2k − 1 ≥ ln(1.648 √n / δ) / √ε.
  const double log_ratio = std::log(1.648 * std::sqrt(n) / failure_probability);
  return std::max(1, static_cast<int>(std::ceil((std::max(0.0, log_ratio) / std::sqrt(relative_gap) + 1.0) / 2.0)));
}

namespace {

double dot(const std::vector<Vec3>& p, const std::vector<Vec3>& q) {
  double sum = 0.0;
  for (std::size_t n = 0; n < p.size(); ++n) sum += p[n].dot(q[n]);
  return sum;
}

}  // namespace

RestFrequencyLanczos::RestFrequencyLanczos(const Body& body, double relative_gap, double failure_probability)
    : relative_gap_(relative_gap) {
  const std::size_t nodes = body.x_m.size(), free_nodes = free_node_count(body);
  sqrt_w_.resize(nodes);
  for (std::size_t n = 0; n < nodes; ++n) sqrt_w_[n] = std::sqrt(body.inv_mass_per_kg[n]);
  for (const EdgeId e : moving_springs(body)) {
    const NodeId a = body.edge_a[e], b = body.edge_b[e];
    springs_.push_back({a, b, body.stiffness_N_per_m[e], (body.rest_m[b] - body.rest_m[a]).normalized()});
  }
  if (free_nodes == 0 || springs_.empty()) {
    done_ = true;  // nothing oscillates: the estimate is zero
    return;
  }
  iterations_ = std::min<int>(lanczos_iterations(3 * free_nodes, relative_gap, failure_probability),
                              static_cast<int>(3 * free_nodes));

  // Start: a Gaussian vector on the free unknowns (uniform direction on the
  // sphere, as the probability bound assumes), from a fixed seed; Box–Muller
  // on mt19937_64 words so every standard library draws the same numbers.
  std::mt19937_64 rng(0x5eed1a2c705ull);
  const auto uniform = [&] { return (static_cast<double>(rng() >> 11) + 0.5) * 0x1p-53; };
  q_.assign(nodes, Vec3::Zero());
  q_prev_.assign(nodes, Vec3::Zero());
  z_.resize(nodes);
  scaled_.resize(nodes);
  for (std::size_t n = 0; n < nodes; ++n)
    for (int k = 0; k < 3; ++k) {
      const double g = std::sqrt(-2.0 * std::log(uniform())) * std::cos(6.283185307179586 * uniform());
      q_[n][k] = sqrt_w_[n] > 0.0 ? g : 0.0;
    }
  const double norm = std::sqrt(dot(q_, q_));
  for (Vec3& qi : q_) qi /= norm;
}

void RestFrequencyLanczos::apply() {
  for (std::size_t n = 0; n < q_.size(); ++n) scaled_[n] = sqrt_w_[n] * q_[n];
  std::fill(z_.begin(), z_.end(), Vec3::Zero());
  for (const Spring& s : springs_) {
    const Vec3 t = s.k_N_per_m * s.unit_d.dot(scaled_[s.a] - scaled_[s.b]) * s.unit_d;
    z_[s.a] += t;
    z_[s.b] -= t;
  }
  for (std::size_t n = 0; n < z_.size(); ++n) z_[n] *= sqrt_w_[n];
}

bool RestFrequencyLanczos::iterate(int iterations) {
  for (int i = 0; i < iterations && !done_; ++i) {
    apply();
    const double a = dot(q_, z_);
    const double beta_prev = beta_.empty() ? 0.0 : beta_.back();
    for (std::size_t n = 0; n < z_.size(); ++n) z_[n] -= a * q_[n] + beta_prev * q_prev_[n];
    alpha_.push_back(a);
    const double b = std::sqrt(dot(z_, z_));
    // An invariant subspace (exhausted, or the start vector lies in one):
    // T's eigenvalues are then exact eigenvalues; stop.
    if (!(b > 1e-14 * std::abs(a)) || iterations_run() >= iterations_) {
      done_ = true;
      break;
    }
    beta_.push_back(b);
    std::swap(q_prev_, q_);
    for (std::size_t n = 0; n < z_.size(); ++n) q_[n] = z_[n] / b;
  }
  return done_;
}

FrequencyEstimate RestFrequencyLanczos::estimate() const {
  FrequencyEstimate out;
  const Eigen::Index m = static_cast<Eigen::Index>(alpha_.size());
  if (m == 0) return out;
  const Eigen::VectorXd diagonal = Eigen::Map<const Eigen::VectorXd>(alpha_.data(), m);
  Eigen::VectorXd off(m - 1);
  for (Eigen::Index i = 0; i + 1 < m; ++i) off[i] = beta_[static_cast<std::size_t>(i)];
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> tridiagonal;
  tridiagonal.computeFromTridiagonal(diagonal, off, Eigen::EigenvaluesOnly);
  out.iterations = static_cast<int>(m);
  out.ritz_per_s2 = std::max(0.0, tridiagonal.eigenvalues().maxCoeff());
  out.bound_per_s2 = out.ritz_per_s2 / (1.0 - relative_gap_);
  return out;
}

FrequencyEstimate rest_frequency2_estimate(const Body& body, double relative_gap, double failure_probability) {
  RestFrequencyLanczos lanczos(body, relative_gap, failure_probability);
  while (!lanczos.iterate(64)) {
  }
  return lanczos.estimate();
}

}  // namespace tissue::physics
