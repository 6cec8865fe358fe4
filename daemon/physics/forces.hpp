// Internal forces and energies of the mass-spring body (MuJoCo's "passive"
// stage): springs along every mesh edge with a damper in parallel.
#pragma once

#include <algorithm>
#include <array>
#include <vector>

#include "physics/body.hpp"

namespace tissue::physics {

// Below this fraction of its rest length a spring counts as collapsed (its
// ends on one point): its current direction means nothing there, so every
// kernel (scalar and SIMD, explicit and implicit) takes the rest direction
// instead and no force divides by a vanishing length.
constexpr double kCollapsedSpringRatio = 1e-9;

// Unit direction a→b of a spring and its length; for a spring squashed below
// kCollapsedSpringRatio of its rest length (collapsed nodes) the rest
// direction stands in, so no force ever divides by zero.
struct SpringFrame {
  Vec3 direction;
  double length_m;
};
SpringFrame spring_frame(const Body& body, EdgeId e);

// Force [N] spring e (and, with_damper, its damper at the current
// velocities) exerts on its end a; its end b gets the opposite.
Vec3 spring_force_on_a_N(const Body& body, EdgeId e, bool with_damper = true);

// Adds spring forces [N] of every live edge into `f` (indexed by node; must
// already hold body.x_m.size() entries); with `with_dampers` also the
// dampers' forces at the current velocities.
void add_spring_forces(const Body& body, std::vector<Vec3>& f_N, bool with_dampers = true);

// Scratch space of apply_spring_dampers_implicitly, kept by its caller so
// that a step allocates nothing once the mesh has stopped growing.
struct ImplicitDamperWork {
  std::vector<Vec3> direction;        // per edge: the spring's unit direction
  std::vector<Vec3> rhs, r, q;        // per node, kg m/s: b, the residual b − A v, A p
  std::vector<Vec3> z, p;             // per node, m/s: the preconditioned residual, the search direction
  std::vector<Vec3> inv_diag;         // per node, 1/kg: the Jacobi preconditioner
  std::vector<NodeId> component;      // union–find over the dampers between free nodes
  std::vector<unsigned char> tied;    // in a set with a damper to a kinematic node
  std::vector<double> set_mass_kg;    // per set, at its root
  std::vector<Vec3> set_lost_kg_m_s;  // per set, at its root: −Σ r, the momentum the residual leaves out
};
struct [[nodiscard]] ImplicitDamperSolve {
  int iterations = 0;
  double relative_residual = 0.0;  // |b − A v| / |b − A v₀| at the end, v₀ = v / mass_scale
  bool converged = true;           // not stopped at kDamperSolveMaxIterations short of the tolerance
};

// Applies the spring dampers (and a mass damping folded into `mass_scale`)
// implicitly over a time h: solves (mass_scale M + h C) v' = M v for the free
// nodes' velocities, C the dampers' matrix (c d dᵀ per spring, d its
// direction now), the kinematic nodes' velocities known; positions are not
// touched. Jacobi-preconditioned conjugate gradients from v₀ = v /
// mass_scale (the answer without spring dampers) until the residual is
// `relative_tolerance` times the first one, b − A v₀ = −h C v₀ (the part the
// dampers act on: a drifting body's bulk momentum does not loosen it), at
// most kDamperSolveMaxIterations (the system's condition number is at most
// 1 + h c (1/m_a + 1/m_b) times the springs at a node). The dampers change
// no momentum (C's rows sum to zero; a free body's to rounding), so the free
// nodes' momentum ends divided by mass_scale (the mass damping), and kinetic
// energy does not grow beyond the residual, however stiff the damping or
// long the step.
// (One Gauss–Seidel sweep spring by spring, which it replaced, relaxed each
// spring locally and gave a cantilever's slow swing a fifth of its Rayleigh
// damping: the projective rung overshot, tip −11.1 mm at 20 ms against
// explicit's −9.7 and implicit's −9.1.)
constexpr int kDamperSolveMaxIterations = 500;
ImplicitDamperSolve apply_spring_dampers_implicitly(Body& body, double h_s, double mass_scale,
                                                    double relative_tolerance, ImplicitDamperWork& work);
// The same with its own scratch space, mass_scale 1 and a tolerance of 1e-10
// (tests, tools).
ImplicitDamperSolve apply_spring_dampers_implicitly(Body& body, double h_s);

// Σ ½ k (l − L)² over live edges [J].
double elastic_energy_J(const Body& body);
// Σ ½ m v² over live nodes [J].
double kinetic_energy_J(const Body& body);
// The spring energy [J] of one tet's stiffness shares (Body::tet_edge_shares_m3,
// corners in any order) when its rest shape is mapped by F: its part of
// elastic_energy_J in an affine field. A split changes the energy by exactly
// Σ children − parent of this at the parent's F (README, "Energy across mesh
// changes"); the body's positions are not read.
double tet_spring_energy_J(const Body& body, const std::array<NodeId, 4>& corners, int depth, const Eigen::Matrix3d& F);

// Per-tet strain-energy density [Pa] with the square the paper's eq. (1)
// omits: D_T = (1/V_T) Σ_e ½ k_e^T (l_e − L_e)² with k_e^T = E V_T / L_e², i.e.
// (E/2) Σ_e ε_e²: level independent, so one threshold serves every depth.
double strain_energy_density_Pa(const Body& body, TetId t);
// The same density from a tet's four node positions and its six rest edge
// lengths (mesh::kTetEdgeSlots order), bit-identical to the form above: for
// callers that keep the rest lengths of tets they evaluate again and again
// (the surface snapshot), saving the rest-length square roots.
double strain_energy_density_Pa(const std::array<const Vec3*, 4>& x_m, const std::array<double, 6>& rest_length_m,
                                double youngs_modulus_Pa);
// Tets whose current signed volume is <= 0 (inverted or flat). Springs are
// blind to inversion (a mirrored tet has no spring energy), so this count is
// reported, not corrected.
std::size_t inverted_tet_count(const Body& body);

// How far a spring of strain l/L − 1 is from its rest length as a ratio,
// max(l/L, L/l) − 1: a spring at 40 % of its length is as far (1.5) as one
// stretched to 2.5×. (|l/L − 1|, used before, never passed 1 for any
// compression, so a stretch_ratio of 2 refined none.) A spring collapsed
// below kCollapsedSpringRatio counts as that ratio, not as infinity.
inline double stretch_from_strain(double strain) {
  const double ratio = 1.0 + strain;  // l/L
  if (ratio >= 1.0) return strain;
  return 1.0 / std::max(ratio, kCollapsedSpringRatio) - 1.0;
}

// Largest max(l/L, L/l) − 1 over a tet's edges (the stretch criterion:
// refine when it exceeds stretch_ratio − 1).
double max_edge_stretch(const Body& body, TetId t);

}  // namespace tissue::physics
