// ContactRenderer: god-object proxy + virtual coupling against one LocalModel.
//
// Geometry (Zilles & Salisbury 1995; Ruspini 1997), frictionless:
//   - The patch is extrapolated to the tick time with its vertex velocities,
//     x_i(t) = x_i + v_i * tau, tau = clamp(t - built, 0, horizon): bounded, so
//     a late model never flies away.
//   - Free: the proxy is the device. Contact starts when the segment from the
//     previous proxy to the device crosses a triangle from its front (outward)
//     side to its back side. The test runs in each triangle's own moving frame
//     (start point shifted by the triangle's motion since the last tick), so a
//     fast device (5 mm per 1 ms tick) or a moving surface cannot tunnel
//     through a thin patch between two ticks. A device in front of the patch
//     at the last tick and at most a few millimetres behind it now has met
//     it too (a surface that moved past it between two models), but only
//     over the patch: where its closest patch point has patch triangles all
//     around, or the device is right above or below that point. The patch is
//     the piece of the surface the sim handed over (a closed surface's patch
//     has a border only where the sim stopped); beside it, behind a border
//     face's plane, the device is not under the patch and may be beside the
//     object (30 mm beside a cube's top edge the sim hands over the nearest
//     triangle alone, maybe a top one): it was captured on the border edge
//     and pulled in sideways with the device's whole force. So no contact
//     starts beside the patch, and a device that was in front is held to be
//     outside there until a model built around it says where the surface is.
//   - Touching: the proxy is the point of the patch closest to the device,
//     searched only over triangles whose front side faces the previous contact
//     point (so the proxy cannot jump to the far side of a thin object), with
//     faces, edges and vertices handled by the closest-point regions. Contact
//     with a rigid patch ends when the device is on the outer side of that
//     feature, judged with the angle-weighted pseudo-normal (Baerentzen &
//     Aanaes 2005), which is well defined on edges and vertices too (a
//     deformed patch holds it a little longer, see below).
//   - Past the border: the patch is a window the sim cut around the tool, and
//     a touching hand that slides past its border (faster than the models
//     follow it: 0.3 m/s over the 0.1 s a model may be old takes it 10 mm past
//     a 20 mm patch) is over surface that goes on. The proxy goes on along the
//     plane through the border point c with its normal (first-order
//     extrapolation of the surface), so the force stays along that normal and
//     from the hand's depth alone; held on the border edge, it dragged the
//     hand back sideways with k_v times the overshoot. The contact point (and
//     the nodes the sim pushes) stays c. (The deformable proxy below moves
//     along the normal from the hand anyway; only the bound that follows is
//     new to it.) Not continuous on a curved patch: the plane is that of c's
//     feature, and it turns in one step where c passes from a border edge to a
//     border vertex and on to the next border edge (the edge's face normal,
//     the vertex's pseudo-normal, the next face's normal; on a convex ridge
//     the facing filter above keeps c on the face it came from until that
//     face's border edge ends, so both steps come within a tick or two). The
//     proxy steps by up to the hand's distance from c times the angle turned:
//     a hand 5 mm past the border of a ridge of slope 0.3, 2.6 mm deep,
//     crossing it at 40 um a tick, felt (-0.31, 0, 1.04) -> (0, 0, 1.04) ->
//     (0.26, 0, 0.86) N in single ticks (the force turns by the angle between
//     the faces). Known and left so: blending the two border edges' normals
//     across the vertex's region does not help (held on the first face by that
//     filter, c reaches the vertex only where the hand already lies in the
//     next edge's region, so there is no stretch to blend across), and a
//     continuous proxy needs the god-object carried on over the extended faces
//     and the lines where they meet, more than a first-order guess the next
//     model replaces is worth. Not without end: beside an object's edge there
//     is no surface. No farther past the border than the distance from the
//     point the sim built the patch around (position_ref_m) to c, at most the
//     patch's width (its farthest vertex from c: a deformed model's
//     position_ref_m is where the last contact was, which may lie off this
//     patch). Where position_ref_m lies on the border itself (a tool beside
//     the surface gets the nearest triangle alone, built around its nearest
//     point) that is about zero there. Beyond, the proxy stays at that reach,
//     so the hand feels a tug back of k_v times its overshoot besides the
//     force from its depth; it is not let go (a hand that still presses, let
//     go, lost its whole force at once and went on into the object, deeper
//     than the next model captures). The sim builds the next model around the
//     proxy, covering about as much around it: where the surface goes on, the
//     contact goes on with it; where the hand slid off an edge, the edge is in
//     it and its pseudo-normal lets the hand go.
//
// Deformable object (LocalModel::in_contact): the patch is the surface as the
// sim last left it under force_ref; pushing harder displaces the contact point
// per the linearisation f(x) = F0 + K_c (x - x0) (f: force on the object).
// The contact is frictionless, so the tool pushes along the contact normal n
// only and the material under it slides sideways freely (until it carries no
// sideways force): the object resists along n with
//       k = k_nn - k_tn^T K_tt^+ k_tn,
// K_c's normal stiffness with its sideways block condensed out (n, t1, t2
// frame). A series solve with the whole K_c pushed the hand sideways where
// K_c couples normal and sideways (an anisotropic lattice's compliance: the
// 6-tet split is not symmetric), and that part dropped in one tick at the
// release (0.108 N for K_c = [[300,0,200],[0,300,0],[200,0,900]] N/m,
// f0 = 0.8 N, k_v = 400 N/m). The proxy is the massless point between the
// coupling spring and the object, at height s above x0 where the two balance:
//       k_v (h - s) = f0_n + k s,   h = n . (x_dev - x0),  f0_n = n . F0,
// i.e. the coupling and the object act in series (pressing a flat patch with
// K_c = k I gives k_v k / (k_v + k)); the proxy is x_dev + (s - h) n. x0
// slides with the geometric contact point along the surface (the sim
// re-anchors it every step anyway). The contact is unilateral: if the solve
// would PULL on the object (k_v (h - s) >= 0), the object is not being pushed
// and the proxy falls back to the surface point c.
//
// Release from a deformed patch: under F0 the patch is pressed in, and the
// object's own surface (where f = 0) lies -f0_n / k above it; there the
// solve still pushes k_v f0 / (k_v + k) with the device on the patch (f0 =
// -f0_n). So the contact is held above the patch for as long as the solve
// pushes and ends where that force reaches zero: the force is continuous
// through the patch and at the release. A free device that was clear of that
// region at the last tick and is inside it now meets the object there, so
// the way back in is the same. k is at least f0 / kMaxHeldHeight_m, so that
// height is at most kMaxHeldHeight_m: a K_c near zero (an eigenvalue clamped
// to 0, an object with no fixed node) would put it metres away, and a
// contact let go at a fixed height instead dropped the whole force there
// (0.5 N for f0 = 0.5 N).
//
// Force on the device (scene frame, before safety):
//       F = k_v (p - x_dev) - b_v (n . (v_dev - v_surface)) n
// The damper acts only in contact and only along the normal (a frictionless
// coupling must not drag sideways); it works on the velocity relative to the
// touched surface. The normal component of F is clamped to >= 0: a contact can
// push the tool out but never pull it in.
//
// No threads, no I/O, no allocation: all scratch space is inside the object.
#pragma once

#include <Eigen/Geometry>  // cross products
#include <array>
#include <cstdint>

#include "haptics/local_model.hpp"

namespace tissue::haptics {

struct RenderParams {
  double coupling_stiffness_N_per_m = 400.0;  // k_v, already clamped to the device's max stiffness
  double coupling_damping_N_s_per_m = 1.0;    // b_v
  double max_stiffness_N_per_m = 1000.0;      // K_c eigenvalues are clamped to [0, this]
  double extrapolation_horizon_s = 0.02;      // patch motion is extrapolated at most this far
};

struct RenderOutput {
  Vec3 force_on_device_N = Vec3::Zero();  // scene frame, before safety
  Vec3 proxy_m = Vec3::Zero();
  Vec3 surface_point_m = Vec3::Zero();  // geometric contact point c (on the patch)
  Vec3 normal = Vec3::Zero();           // outward contact normal (zero when free)
  bool contact = false;
  bool compliant = false;  // the deformable (K_c) solution set the proxy
  std::array<std::uint32_t, 3> contact_node{};
  std::array<double, 3> contact_weight{};
};

// A model the renderer may bind: counts in range, triangle indices valid,
// every number finite, vertex and reference coordinates within 1e6 m and
// vertex speeds within 1e6 m/s (so the geometry's products cannot overflow). The haptic loop drops models that fail
// this.
bool local_model_is_valid(const LocalModel& model) noexcept;

class ContactRenderer {
 public:
  // A deformed patch holds the contact at most this far above it (see the
  // top of the file): the object is felt at least as stiff as f0 / this
  // (150 N/m under the default 3 N force limit), so its force reaches zero
  // within it; a K_c near zero would hold the contact metres above the patch.
  static constexpr double kMaxHeldHeight_m = 0.02;

  explicit ContactRenderer(const RenderParams& params = {});

  // Binds a validated model (nullptr: no model, render zero force). The model
  // must stay alive and unchanged while bound. The proxy state is kept.
  void set_model(const LocalModel* model) noexcept;
  const LocalModel* model() const noexcept { return model_; }
  // Continue the proxy of another renderer (a new model version arrived): the
  // contact state and the proxy's world position carry over.
  void carry_state_from(const ContactRenderer& other) noexcept;
  // Forget contact; the proxy jumps to the device on the next render.
  void reset() noexcept;

  RenderOutput render(std::int64_t now_ns, const Vec3& device_m, const Vec3& device_velocity_m_per_s) noexcept;

  // K_c after symmetrisation and eigenvalue clamping.
  const Mat3& contact_stiffness_N_per_m() const noexcept { return contact_stiffness_N_per_m_; }
  bool touching() const noexcept { return touching_; }
  const Vec3& proxy_m() const noexcept { return proxy_m_; }

 private:
  struct Closest {
    int triangle = -1;
    double distance2 = 0.0;
    Vec3 point = Vec3::Zero();
    std::array<double, 3> weight{};
    int feature_a = -1, feature_b = -1;  // patch vertices of the feature: face (-1,-1), edge (a,b), vertex (a,-1)
  };

  void extrapolate(std::int64_t now_ns) noexcept;
  bool find_entry(const Vec3& from_m, const Vec3& to_m, Vec3* hit_m) const noexcept;
  Closest closest_facing(const Vec3& device_m, const Vec3& reference_m, bool filter) const noexcept;
  Vec3 pseudo_normal(const Closest& c) const noexcept;
  // Whether the patch has triangles all around c's feature (a face, an edge
  // two triangles share, a vertex with a closed fan), i.e. it is not on the
  // patch's border, where the pseudo-normal lacks the faces beyond it.
  bool surrounded(const Closest& c) const noexcept;
  // How far past the border feature c the surface is taken to go on along
  // its plane (top of the file).
  double border_reach_m(const Closest& c) const noexcept;
  Vec3 surface_velocity(const Closest& c) const noexcept;
  // The deformable proxy (top of the file) for contact normal n: true, with
  // *proxy_m, when the model is in contact and the solve pushes into the
  // object.
  bool compliant_proxy(const Vec3& device_m, const Vec3& n, Vec3* proxy_m) const noexcept;

  RenderParams params_;
  const LocalModel* model_ = nullptr;
  Mat3 contact_stiffness_N_per_m_ = Mat3::Zero();

  // Per-tick patch (extrapolated) and last tick's, for the moving-frame entry test.
  std::array<Vec3, LocalModel::kMaxPatchVertices> vertex_m_{};
  std::array<Vec3, LocalModel::kMaxPatchVertices> previous_vertex_m_{};
  std::array<Vec3, LocalModel::kMaxPatchTriangles> normal_{};
  std::array<bool, LocalModel::kMaxPatchTriangles> degenerate_{};
  bool have_previous_vertices_ = false;
  bool surface_moving_ = false;  // tau below the horizon: vertex velocities apply

  // Proxy state.
  bool initialised_ = false;
  bool touching_ = false;
  // Free, with the device in front of the patch at the last tick: a surface
  // that has it just behind at this tick met it (render).
  bool outside_ = false;
  // Free, in front of the patch and out of reach of the deformed object at
  // the last tick: a device within its reach now has come back to it.
  bool clear_ = false;
  Vec3 proxy_m_ = Vec3::Zero();
  Vec3 surface_point_m_ = Vec3::Zero();  // last geometric contact point c
  int contact_triangle_ = -1;            // in the bound model; -1 after a model switch
  std::array<double, 3> contact_weight_{};
};

}  // namespace tissue::haptics
