// How far one run's displacement field is from a reference run's, when the
// two ran on different meshes of the same object (NUMERICS.md §4: adaptive
// or coarse meshes against the uniform mesh at the maximum depth).
//
// Each free node of the reference is located at rest inside a leaf tet of
// the other run's mesh and that run's displacement is interpolated there
// (barycentric, as probes are), so meshes that share no nodes compare. The
// error is the distance between the two displacements at those points,
// relative to the reference's largest displacement:
//   rms_rel = √(mean |u(p_i) − u_ref,i|²) / max_i |u_ref,i|,
//   max_rel = max |u(p_i) − u_ref,i| / max_i |u_ref,i|.
// Kinematic reference nodes (fixed, prescribed) are not compared: their
// displacement is set by the scene, not computed.
#pragma once

#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "physics/body.hpp"

namespace tissue::physics {

// A run's state reduced to what the comparison needs: per node its rest
// position, displacement and whether it is free; the leaf tets as indices
// into those arrays (compact: the body's dead node slots are left out).
struct DisplacementField {
  std::vector<Vec3> rest_m, u_m;
  std::vector<std::uint8_t> free;
  std::vector<std::array<int, 4>> tets;
};

DisplacementField capture_displacement_field(const Body& body);

struct FieldError {
  double rms_rel = NAN, max_rel = NAN;  // NaN when nothing compared or the reference did not move
  double reference_max_m = 0.0;         // max_i |u_ref,i| over all reference nodes
  std::size_t compared = 0;             // free reference nodes located in `test`
  std::size_t unlocated = 0;            // free reference nodes outside every tet of `test`
};

// `test` interpolated at every free node of `reference`. Bins over the
// reference nodes, each test tet visiting the bins its rest bounding box
// covers: O(nodes + tets) for meshes of one object.
FieldError compare_displacement_fields(const DisplacementField& reference, const DisplacementField& test);

// A point's displacement over time (a probe, sampled once per step) against
// a reference run's (NUMERICS.md §4, "for dynamics"): where the end states
// agree, an integrator that damps or shifts the motion on the way does not.
// The reference is interpolated linearly to each sample time inside its
// span; samples outside it are not compared. Both runs' times must increase.
//   rms_rel = √(mean |u(t_k) − u_ref(t_k)|²) / max_k |u_ref|,
//   max_rel = max |u(t_k) − u_ref(t_k)| / max_k |u_ref|.
struct TrajectoryError {
  double rms_rel = NAN, max_rel = NAN;  // NaN when nothing compared or the reference did not move
  double reference_max_m = 0.0;         // largest |u_ref| over the reference's samples
  std::size_t compared = 0;             // samples inside the reference's time span
};

TrajectoryError compare_trajectories(const std::vector<double>& reference_t_s, const std::vector<Vec3>& reference_u_m,
                                     const std::vector<double>& t_s, const std::vector<Vec3>& u_m);

}  // namespace tissue::physics
