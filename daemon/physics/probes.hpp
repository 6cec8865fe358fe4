// Probes: rest-space points whose displacement is reported, interpolated
// linearly (barycentric) inside the leaf tet that contains them at rest.
#pragma once

#include <array>
#include <cstdint>
#include <string>

#include "physics/body.hpp"

namespace tissue::physics {

// How far outside the object's box a probe may lie and still be taken for a
// point on it, relative to the box's largest extent: rounding of a point
// given on the surface (0.2 + 1e-17 for a 0.2 m face). The scene check
// accepts a probe up to this far out (scene_yaml.cpp), and the Simulation
// moves such a probe onto the box before locating it (simulation.cpp), with
// twice this room there: the check measures the box as cubes x cube_size_m,
// the Simulation as the mesh holds it (lattice units x the unit's length),
// and the two may differ in the last bit.
inline constexpr double kProbeOutsideBoxTolerance = 1e-9;

class Probe {
 public:
  Probe(std::string name, const Vec3& rest_m) : name_(std::move(name)), rest_m_(rest_m) {}
  const std::string& name() const { return name_; }
  const Vec3& rest_m() const { return rest_m_; }
  // Displacement [m]; re-locates the containing tet when the mesh changed.
  Vec3 displacement_m(const Body& body);

 private:
  void locate(const Body& body);
  // Whether the cached tet still holds the probe; records the mesh's
  // topology version when it does.
  bool cache_valid(const Body& body);

  std::string name_;
  Vec3 rest_m_;
  TetId tet_ = mesh::kInvalidId;
  std::array<NodeId, 4> nodes_{};
  std::array<mesh::Vec3i, 4> corners_{};  // lattice points of nodes_ when located
  std::array<double, 4> bary_{};
  std::uint64_t topology_version_ = 0;  // of the mesh the cache was last checked on
};

// Barycentric coordinates of p in the tet (a, b, c, d).
std::array<double, 4> barycentric(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& d);

}  // namespace tissue::physics
