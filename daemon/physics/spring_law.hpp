// Mass-spring parameters of the seed paper, §3.3, with the corrections of
// shared/design/NUMERICS.md §2:
// - masses by eq. (2): m_i = rho * Σ V_T / 4 over incident tets;
// - stiffness by eq. (3) as per-tet shares, k_e = E * Σ_T w_T,e V_T / L_e²
//   (not the closed form (5), which is right only for refinement edges of
//   complete interior diamonds); w = 1 is the paper's law, the per-type
//   weights make each lattice level isotropic (E_x within a few % at levels
//   3N, 3N+1, 3N+2 instead of 1.36E / 0.95E / 1.03E);
// - damping: Rayleigh c_e = beta * k_e (modal ratio independent of the
//   refinement) by default; the paper's eq. (4) c = 2 sqrt(k (m_i + m_j)) / L
//   is kept for comparison: its units are kg/(m s), so its effect depends on
//   the unit system (about 80x critical in SI at L = 2.5 cm).
#pragma once

#include <cstdint>

#include "scene/scene.hpp"

namespace tissue::physics {

// The weights are given to four decimals, so 10⁴ w is an integer: springs
// sum integer shares 10⁴ w · 6V (Body), exactly, in any order.
inline constexpr std::int64_t kEdgeWeightScale = 10000;

// 10⁴ × the weight w of an edge inside a tet at bisection `depth` for the
// isotropic law. The edge's role is identified exactly from its squared
// lattice length relative to the tet's longest edge. Throws std::logic_error
// for a length ratio no Kuhn tet has.
std::int64_t isotropic_edge_weight_e4(int depth, std::int64_t length2, std::int64_t longest2);
// w itself: the integer / 10⁴, which is the nearest double to the decimal.
double isotropic_edge_weight(int depth, std::int64_t length2, std::int64_t longest2);

std::int64_t edge_weight_e4(scene::StiffnessLaw law, int depth, std::int64_t length2, std::int64_t longest2);
double edge_weight(scene::StiffnessLaw law, int depth, std::int64_t length2, std::int64_t longest2);

// Eq. (3) for one edge from its weighted incident volume Σ w V [m³].
// Eq. (2): a node's mass is a quarter of the mass of every tet around it,
// from the node's six-fold volume sum in lattice units (exact integers, so
// the same after any split and merge) and the lattice unit's length.
// Multiplied left to right, each partial product lies between the density x
// six-volume and the result: the scene check (scene_yaml.cpp, kMinCubeScale)
// bounds both, so none overflows or vanishes. The order is kept as it was so
// that ordinary scenes give the same bits as before.
inline double node_mass_kg(double density_kg_per_m3, std::int64_t six_volume, double lattice_unit_m) {
  return density_kg_per_m3 * static_cast<double>(six_volume) * lattice_unit_m * lattice_unit_m * lattice_unit_m / 24.0;
}

inline double spring_stiffness_N_per_m(double youngs_modulus_Pa, double weighted_volume_m3, double rest_length_m) {
  return youngs_modulus_Pa * weighted_volume_m3 / (rest_length_m * rest_length_m);
}

// Eq. (5), the paper's closed form for a level-n refinement edge of a complete
// interior diamond: k(n) = E V(n) / L(n)², V(n) = B h³, L(n) = A h (eqs. 7-11).
// Only a test oracle: eq. (3) equals it for those edges with w = 1.
double paper_closed_form_stiffness_N_per_m(double youngs_modulus_Pa, double coarse_cube_m, int level);

// Damper of one spring.
double spring_damping_N_s_per_m(const scene::MaterialSpec& material, double stiffness_N_per_m, double mass_a_kg,
                                double mass_b_kg, double rest_length_m);

}  // namespace tissue::physics
