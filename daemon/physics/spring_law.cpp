#include "physics/spring_law.hpp"

#include <cmath>
#include <stdexcept>
#include <string>

namespace tissue::physics {

std::int64_t isotropic_edge_weight_e4(int depth, std::int64_t length2, std::int64_t longest2) {
  // 24 * (l / l_max)² is an integer for every Kuhn-lattice edge.
  const std::int64_t r = 24 * length2;
  auto is = [&](std::int64_t num) { return r == num * longest2; };
  switch (depth % 3) {
    case 0:  // TYPE I: axis, face diagonal, body diagonal (the refinement edge)
      if (is(8)) return 5525;
      if (is(16)) return 14847;
      if (is(24)) return 13729;
      break;
    case 1:  // TYPE II: half body diagonal, axis, face diagonal (refinement)
      if (is(9)) return 9507;
      if (is(12)) return 10754;
      if (is(24)) return 9971;
      break;
    case 2:  // TYPE III: half axis, half face diagonal, half body diagonal, axis (refinement)
      if (is(6)) return 9481;
      if (is(12)) return 10074;
      if (is(18)) return 10444;
      if (is(24)) return 9481;
      break;
    default:
      break;
  }
  throw std::logic_error("isotropic_edge_weight: edge length ratio² " + std::to_string(length2) + "/" +
                         std::to_string(longest2) + " does not occur in a depth-" + std::to_string(depth) + " tet");
}

double isotropic_edge_weight(int depth, std::int64_t length2, std::int64_t longest2) {
  return static_cast<double>(isotropic_edge_weight_e4(depth, length2, longest2)) /
         static_cast<double>(kEdgeWeightScale);
}

std::int64_t edge_weight_e4(scene::StiffnessLaw law, int depth, std::int64_t length2, std::int64_t longest2) {
  return law == scene::StiffnessLaw::kPaper ? kEdgeWeightScale : isotropic_edge_weight_e4(depth, length2, longest2);
}

double edge_weight(scene::StiffnessLaw law, int depth, std::int64_t length2, std::int64_t longest2) {
  return static_cast<double>(edge_weight_e4(law, depth, length2, longest2)) / static_cast<double>(kEdgeWeightScale);
}

double paper_closed_form_stiffness_N_per_m(double youngs_modulus_Pa, double coarse_cube_m, int level) {
  const double h = coarse_cube_m * std::pow(2.0, -(level / 3));                                // eq. (7)
  const double a = level % 3 == 0 ? std::sqrt(3.0) : (level % 3 == 1 ? std::sqrt(2.0) : 1.0);  // eq. (10)
  const double b = level % 3 == 0 ? 1.0 : 1.0 / 3.0;                                           // eq. (11)
  const double length = a * h, volume = b * h * h * h;                                         // eqs. (8), (9)
  return youngs_modulus_Pa * volume / (length * length);                                       // eq. (5)
}

double spring_damping_N_s_per_m(const scene::MaterialSpec& material, double stiffness_N_per_m, double mass_a_kg,
                                double mass_b_kg, double rest_length_m) {
  if (material.damping == scene::DampingLaw::kPaper)
    return 2.0 * std::sqrt(stiffness_N_per_m * (mass_a_kg + mass_b_kg)) / rest_length_m;  // eq. (4)
  return material.rayleigh_beta_s * stiffness_N_per_m;
}

}  // namespace tissue::physics
