// What crosses between the sim thread and the 1 kHz haptic thread.
//
// LocalModel (sim -> haptic, newest wins): the linearised neighbourhood of the
// tool, rebuilt by the sim thread after every step (NUMERICS.md §5):
//   - the surface patch near the tool: positions and velocities at sim_time_s,
//     outward-oriented triangles (indices into the patch);
//   - the contact linearisation: while the tool touches the object, the force
//     the tool must apply TO THE OBJECT to hold the contact point at x is
//         f(x) = force_ref_N + contact_stiffness_N_per_m * (x - position_ref_m)
//     (contact_stiffness is the 3x3 static condensation K_c = C_cc^-1 at the
//     contact node; it is symmetric positive definite). Before contact,
//     position_ref_m is the surface point nearest the tool and force_ref_N = 0.
// ToolSample (haptic -> sim, SPSC ring, one per tick): what the haptic loop did,
// so the sim can apply the equal and opposite force to the mesh.
//
// Both are fixed-size and never allocate: the haptic thread copies them by
// value. Units are in the names; frames are the object's (scene) frame.
#pragma once

#include <Eigen/Core>
#include <array>
#include <cstdint>

namespace tissue::haptics {

using Vec3 = Eigen::Vector3d;
using Mat3 = Eigen::Matrix3d;

struct LocalModel {
  static constexpr int kMaxPatchVertices = 96;
  static constexpr int kMaxPatchTriangles = 160;

  // Eigen leaves fixed-size vectors uninitialised even under {}: zero them,
  // so an unused or unset slot is never garbage.
  LocalModel() {
    vertex_m.fill(Vec3::Zero());
    vertex_velocity_m_per_s.fill(Vec3::Zero());
  }

  std::uint64_t version = 0;  // 0: no model yet (render zero force)
  double sim_time_s = 0.0;    // simulated time the model describes
  std::int64_t built_ns = 0;  // steady_clock time when the sim published it

  // Surface patch near the tool.
  int vertex_count = 0;
  int triangle_count = 0;
  std::array<Vec3, kMaxPatchVertices> vertex_m{};
  std::array<Vec3, kMaxPatchVertices> vertex_velocity_m_per_s{};
  std::array<std::uint32_t, kMaxPatchVertices> vertex_node{};  // mesh node id of each patch vertex
  std::array<std::array<std::int32_t, 3>, kMaxPatchTriangles>
      triangle{};  // outward (counter-clockwise seen from outside)

  // Contact linearisation (see above).
  bool in_contact = false;  // the sim applied a tool force in the step this model describes
  Vec3 position_ref_m = Vec3::Zero();
  Vec3 force_ref_N = Vec3::Zero();
  Mat3 contact_stiffness_N_per_m = Mat3::Zero();
};

struct ToolSample {
  std::int64_t time_ns = 0;                     // steady_clock time of the tick
  Vec3 device_position_m = Vec3::Zero();        // where the user's hand is
  Vec3 proxy_position_m = Vec3::Zero();         // god-object: on or outside the surface
  Vec3 force_on_device_N = Vec3::Zero();        // what was rendered (after safety)
  Vec3 force_on_object_N = Vec3::Zero();        // what the tool pushes on the object (0 when not in contact)
  std::array<std::uint32_t, 3> contact_node{};  // mesh nodes of the touched triangle
  std::array<double, 3> contact_weight{};       // barycentric weights, sum 1 (0 when not in contact)
  bool contact = false;
  std::uint64_t model_version = 0;  // LocalModel version the tick rendered against
  // The device delivered a new sample this tick and the loop accepted it, so
  // device_position_m is that sample and not the last one held (no sample,
  // or a rejected one). Recorded (/haptic/device_fresh) so that a replay
  // spreads each step over the time the loop measured it over live.
  bool device_fresh = false;

  // Fixed-size Eigen members never throw on copy, but do not say so; the
  // lock-free ring requires it to be stated.
  ToolSample& operator=(const ToolSample&) noexcept = default;
};

}  // namespace tissue::haptics
