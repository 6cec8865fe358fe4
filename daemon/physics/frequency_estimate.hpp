// A tight, probabilistically guaranteed upper bound on a body's highest
// mass-normalised stiffness λmax(M⁻¹K) at rest, by Lanczos.
//
// The guaranteed bounds the explicit rung starts from (Gershgorin, element:
// integrator.hpp) sit 1.5-1.7x above the true λmax on the shipped beams, so
// its sub-step is 0.77-0.83x the true limit before `substep_safety`. Lanczos
// from a random start gives a Ritz value θ ≤ λmax that converges quickly from
// below, and Kuczyński & Woźniakowski (SIAM J. Matrix Anal. Appl. 13(4),
// 1992, Thm. 4.2) bound how far below it can still be: after k iterations on
// n unknowns, P(θ < (1 − ε) λmax) ≤ 1.648 √n e^(−√ε (2k − 1)) over the start
// vector. So θ / (1 − ε) is an upper bound except with a probability chosen
// up front (1e-9 by default: 38-45 iterations from 10² to 10⁶ unknowns at
// ε = 0.1, i.e. a sub-step 0.95x the true limit instead of 0.77x; the
// explicit rung asks ε = 0.05: 54-64 iterations, 0.975x).
#pragma once

#include <cstddef>
#include <vector>

#include "physics/body.hpp"

namespace tissue::physics {

struct FrequencyEstimate {
  double ritz_per_s2 = 0.0;   // largest Ritz value θ: never above λmax
  double bound_per_s2 = 0.0;  // θ / (1 − ε): at least λmax, but with probability ≤ δ
  int iterations = 0;         // Lanczos iterations run (matrix-vector products)
};

// Lanczos iterations k after which θ / (1 − relative_gap) bounds λmax of an
// n-unknown symmetric matrix except with probability ≤ failure_probability.
int lanczos_iterations(std::size_t unknowns, double relative_gap, double failure_probability);

// λmax(M⁻¹K) [1/s²] over the free nodes (inverse mass > 0) at rest: K the
// springs' stiffness along their rest directions (what the element bound
// bounds), M the lumped masses. Deterministic (a fixed pseudo-random start).
// Zero when nothing is free or no spring acts.
FrequencyEstimate rest_frequency2_estimate(const Body& body, double relative_gap = 0.1,
                                           double failure_probability = 1e-9);

// The same estimate run a few iterations at a time (the explicit rung
// spreads it over steps, so no step pays for all of it). Holds its own copy
// of the springs and masses: the body may change or go away meanwhile.
class RestFrequencyLanczos {
 public:
  RestFrequencyLanczos(const Body& body, double relative_gap, double failure_probability);
  // Runs up to `iterations` more; returns done().
  bool iterate(int iterations);
  bool done() const { return done_; }
  int iterations_run() const { return static_cast<int>(alpha_.size()); }
  // The estimate from the iterations so far (final once done()).
  FrequencyEstimate estimate() const;

 private:
  struct Spring {
    NodeId a, b;
    double k_N_per_m;
    Vec3 unit_d;  // rest direction
  };
  void apply();  // z_ = W^½ K W^½ q_

  double relative_gap_;
  int iterations_ = 0;  // lanczos_iterations(...), capped at the unknowns
  bool done_ = false;
  std::vector<Spring> springs_;
  std::vector<double> sqrt_w_;
  std::vector<Vec3> q_, q_prev_, z_, scaled_;
  std::vector<double> alpha_, beta_;
};

}  // namespace tissue::physics
