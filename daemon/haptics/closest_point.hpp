// Closest point to `p` on triangle (a, b, c), with its barycentric weights and
// the Voronoi region it lies in (Ericson, Real-Time Collision Detection,
// §5.1.5). One implementation for the haptic contact renderer (which needs
// the region: a face, an edge or a corner) and the service's local-model
// builder (the nearest surface point to the tool). No allocation: it runs
// in the 1 kHz tick.
#pragma once

#include <Eigen/Core>
#include <array>

namespace tissue::haptics {

struct TriangleClosest {
  Eigen::Vector3d point_m;
  std::array<double, 3> weight;  // of a, b, c; point_m = Σ weight · corner
  // Local corner indices 0..2 of the region: face (-1, -1), edge (a, b),
  // corner (a, -1).
  int feature_a, feature_b;
};

TriangleClosest closest_point_on_triangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                          const Eigen::Vector3d& c);

}  // namespace tissue::haptics
