// The integrator ladder users choose from (scene: integrator.kind):
//   explicit   — symplectic Euler with automatic sub-steps below a safe
//                stable bound; refuses when more than max_substeps are needed.
//   implicit   — backward Euler (Baraff & Witkin 1998) with the clamped spring
//                Hessian (Choi & Ko 2002), matrix-free PCG (Jacobi, or
//                two-level from 1,000 free nodes with cg_preconditioner:
//                auto), warm-started where that start beats zero.
//   projective — Liu et al. 2013 local/global springs with a prefactored
//                system, refactored once after each adaptation batch.
// Every integrator leaves the body untouched when a step fails (non-finite
// state, refused sub-stepping), and says why.
#pragma once

#include <array>
#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "physics/body.hpp"
#include "scene/scene.hpp"

namespace tissue::physics {

struct StepOutcome {
  bool ok = true;
  std::string error;          // set when !ok
  int substeps = 1;           // explicit
  int solver_iterations = 0;  // implicit CG / projective local-global
  // Implicit: CG's relative residual; projective: the estimated error of
  // the positions [m] (integrator_projective.cpp's stopping rule).
  double solver_residual = 0.0;
  // False when the solver stopped at integrator.cg_max_iterations before
  // reaching integrator.cg_tolerance: the step ran, less accurately.
  bool solver_converged = true;
  // Explicit: the sub-steps ran on the offset layout (a mesh of one depth;
  // integrator_explicit_offset.cpp) rather than the gathered stream.
  bool offset_layout = false;
  // Explicit: the step took fewer sub-steps than the margin allows, proved
  // stable by the measured deformation; rerun: it was run again with more.
  bool verified_substeps = false;
  bool rerun = false;
};

// Asked by a rung that steps on its own copy of the state (the explicit
// one), once its sub-steps have run and before it writes them to the body,
// with the step's sub-step count: the body still holds the state the step
// started from, drivers' velocities set. Simulation keeps that state here
// for the steps whose energy it will check, so the steps it does not check
// copy nothing (a copy of every node before every step was ~5 % of an R3
// float step).
class BeforeStore {
 public:
  virtual void before_store(const Body& body, int substeps) = 0;

 protected:
  ~BeforeStore() = default;
};

class Integrator {
 public:
  virtual ~Integrator() = default;
  // Advances positions and velocities by dt_s under per-node external forces
  // f_ext [N]. Kinematic nodes (inverse mass 0) move with their velocity.
  virtual StepOutcome step(Body& body, const std::vector<Vec3>& f_ext_N, double dt_s) = 0;
  // The mesh changed (split/merge): drop cached bounds and factorizations.
  virtual void mesh_changed() = 0;
  // The body's positions or velocities were set from outside the step (a
  // refused step's state restored, initial conditions): drop what was
  // measured on the state the integrator last left (the explicit rung's r).
  virtual void state_restored() {}
  virtual const char* name() const = 0;
  // For the next step() calls (nullptr: none). A rung that writes the body
  // as it goes (implicit, projective) never asks it.
  void set_before_store(BeforeStore* hook) { before_store_ = hook; }

 protected:
  BeforeStore* before_store_ = nullptr;
};

std::unique_ptr<Integrator> make_integrator(const scene::IntegratorSpec& spec, const scene::MaterialSpec& material);

// Safe explicit step [s]: h ≤ (2/ω)(√(1+ζ²) − ζ), ζ = γ/(2ω), from upper
// bounds on the highest mass-normalised stiffness ω² and damping rate γ: the
// smaller of a Gershgorin bound (ω² ≤ max_i 2 Σk / m_i, γ ≤ max_i 2 Σc / m_i)
// and the element bound below (γ ≤ max(c/k) · that). Stiffness-proportional
// damping shrinks it (ζ = βω/2 at the highest mode): heavily damped scenes
// belong on the implicit rung. Mass-proportional damping is integrated
// implicitly and does not limit it.
double explicit_stable_dt_s(const Body& body);
// The same bound, and what it would be without the spring dampers (to tell a
// user how much the damping costs the explicit rung).
struct ExplicitStableStep {
  double dt_s = 0.0;           // explicit_stable_dt_s
  double undamped_dt_s = 0.0;  // 2/ω from the same ω² bound
};
// frequency2_bound_per_s2: a further upper bound on λmax(M⁻¹K) to take when
// it is lower (the explicit rung's Lanczos bound, frequency_estimate.hpp);
// it tightens the damping bound too (γ ≤ max(c/k) λmax).
ExplicitStableStep explicit_stable_step(const Body& body, double frequency2_bound_per_s2 = INFINITY);

// The body's bounds the stable step is made of, computed once per mesh.
struct ExplicitBounds {
  double rest_per_s2 = 0.0;              // λmax(M⁻¹K) at rest: min(element, graph)
  double graph_per_s2 = 0.0;             // max_i 2 Σk / m_i (Gershgorin of M⁻¹ L_k)
  double damping_rate_per_s = 0.0;       // γ ≤ max_i 2 Σc / m_i
  double damping_per_stiffness_s = 0.0;  // max c / k over the springs
};
ExplicitBounds explicit_bounds(const Body& body);
// The stable step for a bound ω² ≤ frequency2_per_s2 (capped at the graph
// bound) and its damping rate γ ≤ min(damping_rate, max(c/k) · that).
ExplicitStableStep explicit_stable_step(const ExplicitBounds& bounds, double frequency2_per_s2);
// The stable step with every spring's stiffness within ±collapse_factor times
// its axial part (collapse_factor below): ω² ≤ collapse_factor · graph, the
// dampers' rate as at the graph cap (they act along their springs only).
ExplicitStableStep collapsed_stable_step(const ExplicitBounds& bounds, double collapse_factor);

// An upper bound on λmax(M⁻¹K(x)) of the deformed body, K(x) the springs'
// stiffness at the current state, from its rest bound and the largest
// relative displacement of a spring's ends, r = max |Δu| / L (Δu = u_b − u_a,
// u = x − X). A spring of length l along d̂ has stiffness
// k (d̂d̂ᵀ + (1 − L/l)(I − d̂d̂ᵀ)); it differs from its rest part k d̂₀d̂₀ᵀ by at
// most k (sin θ + |1 − L/l|) in norm, θ the angle it turned, and sin θ ≤ r,
// |1 − L/l| ≤ r / (1 − r). Summed over springs (each difference is at most
// that times k I on its two ends) and by Weyl's inequality:
//   λmax(M⁻¹K(x)) ≤ rest + ε · graph,   ε = r + r / (1 − r).
// And while no spring is shorter than half its rest length (r ≤ ½), every
// spring's stiffness lies between −k I and k I, so graph (a bound on
// M⁻¹ L_k ⊗ I) caps it. Beyond r = ½ a spring may collapse and no bound in r
// alone holds: the cap is returned there, and the explicit rung measures the
// shortest spring every step and takes collapsed_stable_step (below) instead,
// or refuses the step. The rest part counts rigid rotations as deformation (rotations do
// not change the spectrum), so the bound is loose where a body turns far.
double deformed_frequency2_bound_per_s2(double rest_per_s2, double graph_per_s2, double end_displacement_ratio);

// Beyond r = ½, where the bound above is only capped: a spring of length l
// has stiffness between −s k I and s k I with s = max(1, L/l − 1) (its
// transverse part k (1 − L/l) grows without bound as it collapses), so the
// graph bound times the largest s bounds λmax(M⁻¹K(x)) in magnitude. The
// shortest spring relative to its rest length, over springs with a free end
// (a spring between two kinematic nodes moves nothing), gives that s.
struct ShortestSpring {
  double length_ratio = INFINITY;  // l / L; 0 for a spring collapsed to a point
  NodeId a = 0, b = 0;             // its ends (when length_ratio is finite)
};
ShortestSpring shortest_spring(const Body& body);
// s = max(1, 1/ρ − 1) for a length ratio ρ = l/L; infinite at ρ = 0.
double collapse_factor(double length_ratio);

// An upper bound on the body's highest ω² = λmax(M⁻¹K) at rest [1/s²]: the
// largest λmax(K_t, M_t) of any tet, K_t its eq. (3) stiffness shares and M_t
// a quarter of its mass on each corner. Holds because K = Σ K_t and M = Σ M_t
// (the element eigenvalue theorem: a sum's Rayleigh quotient is at most the
// largest of its parts'); fixed nodes only lower the true value.
double element_frequency2_bound_per_s2(const Body& body);

// λmax(K_t, M_t) [1/s²] of the tet at `depth` with corners v.
double tet_frequency2_per_s2(const Body& body, const std::array<NodeId, 4>& v, int depth);

// True when every live node's position and velocity is finite and below
// 1e100 in magnitude: beyond that, squared lengths overflow and forces
// silently vanish, so such a state counts as diverged.
bool state_is_finite(const Body& body);

}  // namespace tissue::physics
