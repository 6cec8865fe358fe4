// --beam-theory: the model error. The static tip of the PERFORMANCE.md beam
// (0.4 x 0.1 x 0.1 m, E = 5e4 Pa, 0.05 N on the free face) at uniform depths,
// both stiffness laws, against Euler-Bernoulli and Timoshenko beam theory.
#pragma once

#include <cmath>
#include <cstddef>
#include <string>

#include "app/trade_options.hpp"
#include "physics/simulation.hpp"
#include "scene/scene.hpp"

namespace tissue::app {

// The beam's static tip deflection under 0.05 N [m] by beam theory.
struct BeamTheory {
  double euler_bernoulli_m, timoshenko_m;
};

// Euler-Bernoulli F L^3 / (3 E I) and Timoshenko, which adds the shear
// deflection F L / (kappa G A) with nu = 1/4 (the eq. (3) springs' Poisson
// ratio) and Cowper's kappa for a rectangular section.
BeamTheory beam_theory_tip();

// Static equilibrium by implicit Euler at a large step, until the force
// residual over the free nodes is below tol_rel of the load.
struct StaticResult {
  physics::Vec3 tip_centre = physics::Vec3::Zero(), tip_bottom = physics::Vec3::Zero();
  double residual_rel = NAN;
  long steps = 0;
  double wall_s = 0.0;
  std::size_t nodes = 0, tets = 0;
  bool ok = true;
  std::string error;
};

// |sum of external and spring forces| over the free nodes [N]: zero at rest.
double force_residual_N(const physics::Simulation& sim);

// `s` stepped to rest (implicit Euler, dt 0.05 s, CG to 1e-10) in batches of
// 10 steps, at most max_steps; probe 0 is the tip centre, 1 the bottom edge.
StaticResult solve_static(scene::Scene s, long max_steps, double tol_rel);

// Throws std::invalid_argument naming --beam-depth when the beam at a depth
// up to max_depth is one the scene checks refuse: 8 x 2 x 2 cubes hold 192 ·
// 2^depth tets, so depth 17 (2.5e7) passes the mesh budget and 20 asked for
// ~40 GB. The table's runs are checked before the first.
void check_beam_depth(int max_depth);

// Prints the table: per law and uniform depth 0..--beam-depth, the bending
// tip against theory and the finest depth, and an axial check.
void run_beam_theory(const TradeOptions& o);

}  // namespace tissue::app
