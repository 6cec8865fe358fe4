#include "haptics/contact_renderer.hpp"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <limits>

#include "haptics/closest_point.hpp"

namespace tissue::haptics {
namespace {

// A reference point this far behind a face's plane is on the other side of
// the object (0.1 um: far above rounding, far below any tissue thickness).
constexpr double kBehindTolerance_m = 1e-7;
// Entry points this close outside a triangle still count as inside it, so a
// device crossing exactly through a shared edge or vertex is not missed.
constexpr double kBarycentricTolerance = 1e-9;
constexpr double kDegenerateArea2_m4 = 1e-30;
// A surface met between two ticks or two models (a sim step: 1 ms) has moved
// at most this far past the tool: 5 m/s for a millisecond. A tool deeper
// behind the surface did not meet it; it is left free, as one that starts
// inside.
constexpr double kCaptureDepth_m = 0.005;
// A device this close (sideways) to the line through a patch border point
// along its normal is still over the patch: rounding, far below any tool.
constexpr double kFootprintTolerance_m = 1e-7;
// A patch vertex, its velocity and the contact reference are bounded, not just
// finite: the closest-point and normal arithmetic takes products of squared
// coordinates, and 1e80 m made them inf - inf = NaN, which became a NaN proxy
// and NaN contact weights in the tool samples (and an unreadable recording).
// 1000 km and 1000 km/s are far beyond any tissue model, and even extrapolated
// over the longest allowed horizon (stale_model_s <= 60 s) the squares stay
// far below the double range.
constexpr double kMaxModelCoordinate_m = 1e6;
constexpr double kMaxModelSpeed_m_per_s = 1e6;

double angle_between(const Vec3& u, const Vec3& v) { return std::atan2(u.cross(v).norm(), u.dot(v)); }

}  // namespace

bool local_model_is_valid(const LocalModel& m) noexcept {
  if (m.vertex_count < 0 || m.vertex_count > LocalModel::kMaxPatchVertices) return false;
  if (m.triangle_count < 0 || m.triangle_count > LocalModel::kMaxPatchTriangles) return false;
  if (!std::isfinite(m.sim_time_s)) return false;
  // Every coefficient compared on its own: a comparison with NaN is false, so
  // NaN and infinity are refused too (maxCoeff() may skip a NaN).
  const auto bounded = [](const Vec3& v, double bound) { return (v.array().abs() <= bound).all(); };
  for (int i = 0; i < m.vertex_count; ++i)
    if (!bounded(m.vertex_m[i], kMaxModelCoordinate_m) ||
        !bounded(m.vertex_velocity_m_per_s[i], kMaxModelSpeed_m_per_s))
      return false;
  for (int t = 0; t < m.triangle_count; ++t)
    for (std::int32_t v : m.triangle[t])
      if (v < 0 || v >= m.vertex_count) return false;
  return bounded(m.position_ref_m, kMaxModelCoordinate_m) && m.force_ref_N.allFinite() &&
         m.contact_stiffness_N_per_m.allFinite();
}

ContactRenderer::ContactRenderer(const RenderParams& params) : params_(params) {}

void ContactRenderer::set_model(const LocalModel* model) noexcept {
  model_ = model;
  contact_triangle_ = -1;  // triangle indices of another model mean nothing here
  have_previous_vertices_ = false;
  contact_stiffness_N_per_m_.setZero();
  if (!model) return;
  // K_c is SPD by contract; rounding or a bad linearisation must not make the
  // rendering active (negative stiffness) or exceed the device's stiffness.
  const Mat3 symmetric = 0.5 * (model->contact_stiffness_N_per_m + model->contact_stiffness_N_per_m.transpose());
  Eigen::SelfAdjointEigenSolver<Mat3> eigen;
  eigen.computeDirect(symmetric);
  const Vec3 clamped = eigen.eigenvalues().cwiseMax(0.0).cwiseMin(std::max(0.0, params_.max_stiffness_N_per_m));
  contact_stiffness_N_per_m_ = eigen.eigenvectors() * clamped.asDiagonal() * eigen.eigenvectors().transpose();
  if (!contact_stiffness_N_per_m_.allFinite()) contact_stiffness_N_per_m_.setZero();
}

void ContactRenderer::carry_state_from(const ContactRenderer& other) noexcept {
  initialised_ = other.initialised_;
  touching_ = other.touching_;
  outside_ = other.outside_;
  clear_ = other.clear_;
  proxy_m_ = other.proxy_m_;
  surface_point_m_ = other.surface_point_m_;
  contact_triangle_ = -1;
}

void ContactRenderer::reset() noexcept {
  initialised_ = false;
  touching_ = false;
  outside_ = false;
  clear_ = false;
  contact_triangle_ = -1;
}

void ContactRenderer::extrapolate(std::int64_t now_ns) noexcept {
  const double age_s = 1e-9 * static_cast<double>(now_ns - model_->built_ns);
  const double horizon_s = std::max(0.0, params_.extrapolation_horizon_s);
  const double tau_s = std::clamp(age_s, 0.0, horizon_s);
  surface_moving_ = age_s < horizon_s;
  for (int i = 0; i < model_->vertex_count; ++i)
    vertex_m_[i] = model_->vertex_m[i] + tau_s * model_->vertex_velocity_m_per_s[i];
  for (int t = 0; t < model_->triangle_count; ++t) {
    const auto& tri = model_->triangle[t];
    const Vec3 n = (vertex_m_[tri[1]] - vertex_m_[tri[0]]).cross(vertex_m_[tri[2]] - vertex_m_[tri[0]]);
    const double area2 = n.squaredNorm();
    // An overflowed (inf) or NaN area has no usable normal either.
    degenerate_[t] = !(area2 > kDegenerateArea2_m4 && std::isfinite(area2));
    normal_[t] = degenerate_[t] ? Vec3::Zero() : Vec3(n / std::sqrt(area2));
  }
}

bool ContactRenderer::find_entry(const Vec3& from_m, const Vec3& to_m, Vec3* hit_m) const noexcept {
  double best_t = std::numeric_limits<double>::infinity();
  for (int t = 0; t < model_->triangle_count; ++t) {
    if (degenerate_[t]) continue;
    const auto& tri = model_->triangle[t];
    const Vec3& a = vertex_m_[tri[0]];
    const Vec3& b = vertex_m_[tri[1]];
    const Vec3& c = vertex_m_[tri[2]];
    // Relative motion: carried along with the triangle's own displacement since
    // the last tick, the start point keeps its position relative to the
    // triangle, so the test sees the tool and the surface approach each other.
    Vec3 start = from_m;
    if (have_previous_vertices_)
      start +=
          ((a - previous_vertex_m_[tri[0]]) + (b - previous_vertex_m_[tri[1]]) + (c - previous_vertex_m_[tri[2]])) /
          3.0;
    const Vec3& n = normal_[t];
    const double s_start = n.dot(start - a), s_end = n.dot(to_m - a);
    if (!(s_start >= 0.0 && s_end < 0.0)) continue;  // must go from front (outside) to back
    const double f = s_start / (s_start - s_end);
    if (f >= best_t) continue;
    const Vec3 hit = start + f * (to_m - start);
    // Barycentric coordinates of the hit in the triangle's plane.
    const double area = n.dot((b - a).cross(c - a));
    const double wa = n.dot((b - hit).cross(c - hit)) / area;
    const double wb = n.dot((c - hit).cross(a - hit)) / area;
    const double wc = 1.0 - wa - wb;
    if (wa < -kBarycentricTolerance || wb < -kBarycentricTolerance || wc < -kBarycentricTolerance) continue;
    best_t = f;
    *hit_m = wa * a + wb * b + wc * c;
  }
  return std::isfinite(best_t);
}

ContactRenderer::Closest ContactRenderer::closest_facing(const Vec3& device_m, const Vec3& reference_m,
                                                         bool filter) const noexcept {
  Closest best;
  best.distance2 = std::numeric_limits<double>::infinity();
  for (int t = 0; t < model_->triangle_count; ++t) {
    if (degenerate_[t]) continue;
    const auto& tri = model_->triangle[t];
    const Vec3& a = vertex_m_[tri[0]];
    if (filter && normal_[t].dot(reference_m - a) < -kBehindTolerance_m) continue;  // faces away from the contact
    const TriangleClosest c = closest_point_on_triangle(device_m, a, vertex_m_[tri[1]], vertex_m_[tri[2]]);
    const double d2 = (device_m - c.point_m).squaredNorm();
    if (!(d2 < best.distance2)) continue;  // a NaN distance (overflowed arithmetic) is never the closest
    best.triangle = t;
    best.distance2 = d2;
    best.point = c.point_m;
    best.weight = c.weight;
    best.feature_a = c.feature_a < 0 ? -1 : tri[c.feature_a];
    best.feature_b = c.feature_b < 0 ? -1 : tri[c.feature_b];
  }
  return best;
}

Vec3 ContactRenderer::pseudo_normal(const Closest& c) const noexcept {
  const Vec3& face_normal = normal_[c.triangle];
  if (c.feature_a < 0) return face_normal;
  Vec3 sum = Vec3::Zero();
  for (int t = 0; t < model_->triangle_count; ++t) {
    if (degenerate_[t]) continue;
    const auto& tri = model_->triangle[t];
    int corner_a = -1;
    bool has_b = false;
    for (int k = 0; k < 3; ++k) {
      if (tri[k] == c.feature_a) corner_a = k;
      if (tri[k] == c.feature_b) has_b = true;
    }
    if (corner_a < 0) continue;
    if (c.feature_b >= 0) {
      if (has_b) sum += normal_[t];  // edge: the faces sharing it, equal weights
    } else {
      const Vec3& p = vertex_m_[tri[corner_a]];
      sum += angle_between(vertex_m_[tri[(corner_a + 1) % 3]] - p, vertex_m_[tri[(corner_a + 2) % 3]] - p) * normal_[t];
    }
  }
  const double norm = sum.norm();
  return norm > 1e-12 ? Vec3(sum / norm) : face_normal;
}

bool ContactRenderer::surrounded(const Closest& c) const noexcept {
  if (c.feature_a < 0) return true;  // a face
  // Topology only, so degenerate triangles count: they close a fan though
  // they add nothing to its normal.
  if (c.feature_b >= 0) {
    int faces = 0;  // sharing the edge
    for (int t = 0; t < model_->triangle_count; ++t) {
      const auto& tri = model_->triangle[t];
      const bool has_a = tri[0] == c.feature_a || tri[1] == c.feature_a || tri[2] == c.feature_a;
      const bool has_b = tri[0] == c.feature_b || tri[1] == c.feature_b || tri[2] == c.feature_b;
      faces += has_a && has_b ? 1 : 0;
    }
    return faces >= 2;
  }
  // A vertex: every edge out of it is shared by two of its triangles (a
  // closed fan). Its triangles first, on the stack, so the pairing is over
  // them only.
  std::array<int, LocalModel::kMaxPatchTriangles> fan;
  int fan_size = 0;
  for (int t = 0; t < model_->triangle_count; ++t) {
    const auto& tri = model_->triangle[t];
    if (tri[0] == c.feature_a || tri[1] == c.feature_a || tri[2] == c.feature_a) fan[fan_size++] = t;
  }
  for (int i = 0; i < fan_size; ++i) {
    for (const std::int32_t x : model_->triangle[fan[i]]) {
      if (x == c.feature_a) continue;
      bool shared = false;
      for (int j = 0; j < fan_size && !shared; ++j) {
        const auto& other = model_->triangle[fan[j]];
        shared = j != i && (other[0] == x || other[1] == x || other[2] == x);
      }
      if (!shared) return false;
    }
  }
  return fan_size > 0;
}

double ContactRenderer::border_reach_m(const Closest& c) const noexcept {
  // The patch reaches |c - position_ref| from the point the sim built it
  // around to this border; its own width (the farthest vertex from c) caps
  // that for a model whose reference lies off the patch.
  double width2_m2 = 0.0;
  for (int i = 0; i < model_->vertex_count; ++i)
    width2_m2 = std::max(width2_m2, (vertex_m_[i] - c.point).squaredNorm());
  const double reach_m = std::min((c.point - model_->position_ref_m).norm(), std::sqrt(width2_m2));
  return std::isfinite(reach_m) ? reach_m : 0.0;
}

Vec3 ContactRenderer::surface_velocity(const Closest& c) const noexcept {
  if (!surface_moving_) return Vec3::Zero();  // extrapolation has stopped: the patch is held still
  const auto& tri = model_->triangle[c.triangle];
  return c.weight[0] * model_->vertex_velocity_m_per_s[tri[0]] + c.weight[1] * model_->vertex_velocity_m_per_s[tri[1]] +
         c.weight[2] * model_->vertex_velocity_m_per_s[tri[2]];
}

namespace {

// The object's stiffness along the unit normal n with its sideways motion
// free (the contact is frictionless, so the material under the tool slides
// until it carries no sideways force): the Schur complement
// k_nn - k_tn^T K_tt^+ k_tn of K in the frame (n, t1, t2). For a PSD K it
// lies in [0, k_nn] also when K_tt is (nearly) singular, since each term
// k_tn_i^2 / lambda_i is at most k_nn; rounding is clamped back into it.
double normal_stiffness_N_per_m(const Mat3& K, const Vec3& n) noexcept {
  const Vec3 t1 = n.unitOrthogonal();
  const Vec3 t2 = n.cross(t1);
  const Vec3 Kn = K * n;
  const double k_nn = n.dot(Kn);
  if (!(std::isfinite(k_nn) && k_nn > 0.0)) return 0.0;
  Eigen::Matrix2d K_tt;
  K_tt << t1.dot(K * t1), t1.dot(K * t2), t2.dot(K * t1), t2.dot(K * t2);
  const Eigen::Vector2d k_tn(t1.dot(Kn), t2.dot(Kn));
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eigen;
  eigen.computeDirect(K_tt);
  double coupled = 0.0;
  for (int i = 0; i < 2; ++i) {
    const double lambda = eigen.eigenvalues()[i];
    const double along = eigen.eigenvectors().col(i).dot(k_tn);
    if (lambda > 1e-12 * k_nn) coupled += along * along / lambda;  // a null direction couples nothing
  }
  const double k = k_nn - coupled;
  return std::isfinite(k) ? std::clamp(k, 0.0, k_nn) : 0.0;
}

}  // namespace

bool ContactRenderer::compliant_proxy(const Vec3& device_m, const Vec3& n, Vec3* proxy_m) const noexcept {
  if (!model_->in_contact) return false;
  const double k_v = params_.coupling_stiffness_N_per_m;
  // Along n only (frictionless): heights above the patch point x0, the
  // reference force's normal part f0_n (< 0 when the sim pushes the object
  // in) and the object's normal stiffness k. x0 slides with the contact point
  // along the surface, which leaves its height unchanged.
  const double f0_n = n.dot(model_->force_ref_N);
  double k = normal_stiffness_N_per_m(contact_stiffness_N_per_m_, n);
  // No softer than f0 / kMaxHeldHeight_m, so the force reaches zero within
  // that height (and the contact is let go gradually, not in one step there).
  if (f0_n < 0.0) k = std::max(k, std::min(-f0_n / kMaxHeldHeight_m, params_.max_stiffness_N_per_m));
  const double h_m = n.dot(device_m - model_->position_ref_m);
  // The surface under the tool settles at height s where the coupling and
  // the object balance: k_v (h - s) = f0_n + k s.
  const double s_m = (k_v * h_m - f0_n) / (k_v + k);
  const double push_N = k_v * (h_m - s_m);                  // n . (force on the object)
  if (!(std::isfinite(s_m) && push_N < 0.0)) return false;  // must push into the object (n is outward)
  *proxy_m = device_m + (s_m - h_m) * n;
  return true;
}

RenderOutput ContactRenderer::render(std::int64_t now_ns, const Vec3& device_m,
                                     const Vec3& device_velocity_m_per_s) noexcept {
  RenderOutput out;
  if (!model_ || model_->version == 0 || model_->triangle_count == 0) {
    // Nothing to touch: the proxy follows the device and the force is zero.
    touching_ = false;
    initialised_ = true;
    proxy_m_ = device_m;
    out.proxy_m = device_m;
    return out;
  }
  extrapolate(now_ns);
  if (!initialised_) {
    // Without history we cannot tell which side the device came from: start
    // free, so a device that starts inside the object feels no sudden force.
    initialised_ = true;
    touching_ = false;
    outside_ = false;
    proxy_m_ = device_m;
    clear_ = false;
  }

  // The device's signed height above the patch (along the pseudo-normal at
  // its closest point; NaN without a triangle), found at most once a tick.
  Closest nearest;
  Vec3 nearest_normal = Vec3::Zero();
  double height_m = std::numeric_limits<double>::quiet_NaN();
  bool have_height = false;
  const auto device_height_m = [&]() noexcept {
    if (!have_height) {
      nearest = closest_facing(device_m, device_m, false);
      if (nearest.triangle >= 0) {
        nearest_normal = pseudo_normal(nearest);
        height_m = nearest_normal.dot(device_m - nearest.point);
      }
      have_height = true;
    }
    return height_m;
  };
  // Whether the device is over the patch (top of the header): its closest
  // point has patch triangles all around it, or the device is right above or
  // below that point. Beside the patch the height is only that above the
  // plane of a border face, which says nothing of the surface under the
  // device: the sim did not hand that part over. Found at most once a tick,
  // and only where a contact could start or the side the device is on could
  // change. Without a triangle there is nothing to be beside.
  bool over_patch = true;
  bool have_over_patch = false;
  const auto device_over_patch = [&]() noexcept {
    if (!have_over_patch) {
      device_height_m();
      if (nearest.triangle >= 0 && !surrounded(nearest)) {
        const Vec3 d = device_m - nearest.point;
        over_patch =
            (d - nearest_normal.dot(d) * nearest_normal).squaredNorm() <= kFootprintTolerance_m * kFootprintTolerance_m;
      }
      have_over_patch = true;
    }
    return over_patch;
  };

  Vec3 reference_m = Vec3::Zero();
  bool in_reach = false;  // free, within reach of the deformed object (set below)
  if (!touching_) {
    touching_ = find_entry(proxy_m_, device_m, &reference_m);
    if (!touching_ && outside_) {
      // A tool in front of the surface at the last tick and just behind it
      // now has met it, though the segment test above saw no crossing. That
      // happens (a) on the first tick of a new model: the service publishes
      // one per sim step, so a surface moving into a still tool mostly passes
      // it between two models, where the segment has no previous patch to
      // move with; (b) at a patch vertex or edge, where the segment's face
      // plane and the pseudo-normal below disagree by a fraction of a
      // micrometre (the shipped demo's hand lands on a lattice node). Both
      // lost the whole press: the tool went on inside with no force. Only
      // over the patch: beside it, behind a border face's plane, the device
      // was captured on the border edge and pulled in sideways with up to
      // the device's whole force (30 mm beside a cube's top edge: 12 N asked),
      // touching nothing.
      const double h_m = device_height_m();
      if (h_m < 0.0 && h_m >= -kCaptureDepth_m && device_over_patch()) {
        touching_ = true;
        reference_m = nearest.point;
      }
    }
    if (!touching_ && model_->in_contact) {
      // In front of a deformed patch, below where its linearised force
      // reaches zero (the release rule below, run backwards): the object is
      // met there, where its force is still zero, not on the patch, where it
      // would start at k_v f0 / (k_v + k). Only coming from clear of that
      // region, as the segment test needs a crossing: a device that starts
      // inside it feels no sudden force. Over the patch only, as above.
      const double h_m = device_height_m();
      Vec3 unused_proxy_m;
      in_reach = h_m >= 0.0 && h_m <= kMaxHeldHeight_m && device_over_patch() &&
                 compliant_proxy(device_m, nearest_normal, &unused_proxy_m);
      if (in_reach && clear_) {
        touching_ = true;
        reference_m = nearest.point;
      }
    }
  } else if (contact_triangle_ >= 0) {
    const auto& tri = model_->triangle[contact_triangle_];
    reference_m = contact_weight_[0] * vertex_m_[tri[0]] + contact_weight_[1] * vertex_m_[tri[1]] +
                  contact_weight_[2] * vertex_m_[tri[2]];  // the contact point moves with the surface
  } else {
    // First tick on a new model: project the old contact point onto the new patch.
    reference_m = closest_facing(surface_point_m_, surface_point_m_, false).point;
  }

  Closest c;
  Vec3 n = Vec3::Zero();
  Vec3 rigid_proxy_m = Vec3::Zero();  // on the patch, or on a border face's plane past it
  Vec3 compliant_proxy_m = Vec3::Zero();
  bool compliant = false;
  Vec3 tug_m = Vec3::Zero();  // past the border beyond its reach: the proxy held back at the reach
  if (touching_) {
    c = closest_facing(device_m, reference_m, true);
    if (c.triangle < 0 || !c.point.allFinite()) {
      touching_ = false;  // a non-finite point must not become the proxy
    } else {
      n = pseudo_normal(c);
      const Vec3 offset_m = device_m - c.point;
      const double height_m = n.dot(offset_m);
      rigid_proxy_m = c.point;
      // Past the patch's border (top of the header): the patch is a window
      // the sim cut, the surface goes on, to first order along the plane
      // through the border point c with its normal n. Held on the border
      // edge instead, the proxy dragged the hand back sideways with k_v
      // times its overshoot until the next model came (4 N at 0.3 m/s over
      // the 0.1 s a model may be old). The extended plane meets the patch
      // at c, so the force is continuous across the border (not where c
      // changes feature on a curved patch: top of the header).
      const Vec3 sideways_m = offset_m - height_m * n;
      const double sideways2_m2 = sideways_m.squaredNorm();
      if (sideways2_m2 > kFootprintTolerance_m * kFootprintTolerance_m && !surrounded(c)) {
        // Not without end: beside an object's edge there is no surface at
        // all. No farther than the patch reaches from the point it was
        // built around: the next model, built around the proxy, covers
        // about that much around it, so an edge the hand slid past is in it
        // and decides there (its pseudo-normal lets the hand go), and a
        // first-order guess is not stretched beyond the stretch of surface
        // it comes from. Beyond, the proxy stays at the reach (a tug back,
        // k_v times the overshoot), and the hand is NOT let go: it still
        // presses, and let go it lost its whole force at once and went on
        // into the object, deeper than the next model captures
        // (kCaptureDepth_m), so it was never met again (6 mm deep; on a
        // deformed patch the tissue springs back once the tool's force is
        // gone, deeper still). Remembering the depth and capturing deeper
        // next time would not do: the force would still drop to zero and
        // come back, and the hand, pushed on by the user with nothing
        // against it, goes as deep as it likes before the next model.
        // Only a model can say the surface ends there (the contact rule
        // below: the hand in front of the feature's plane, or off an
        // object's edge by the edge's pseudo-normal in the next model).
        const double reach_m = border_reach_m(c);
        const double sideways_norm_m = std::sqrt(sideways2_m2);
        rigid_proxy_m = c.point + std::min(1.0, reach_m / sideways_norm_m) * sideways_m;
        tug_m = rigid_proxy_m - (c.point + sideways_m);
      }
      compliant = compliant_proxy(device_m, n, &compliant_proxy_m);
      // The deformable proxy moves along n from the hand, so it follows the
      // hand past the border on its own; beyond the reach it is held back
      // as the rigid one is.
      if (compliant) compliant_proxy_m += tug_m;
      // Back outside the patch. A deformed object still pushing holds the
      // contact until its force reaches zero (top of the header), so the
      // force does not drop by k_v f0 / (k_v + k) at the patch.
      if (height_m > 0.0 && !(compliant && height_m <= kMaxHeldHeight_m)) touching_ = false;
    }
  }

  for (int i = 0; i < model_->vertex_count; ++i) previous_vertex_m_[i] = vertex_m_[i];
  have_previous_vertices_ = true;

  if (!touching_) {
    contact_triangle_ = -1;
    proxy_m_ = device_m;
    out.proxy_m = device_m;
    // NaN (no triangle): not known to be outside. In front of any face's
    // plane is outside, but behind a border face's plane beside the patch
    // is not known to be inside: the device stays outside until the next
    // model, built around it, says where the surface is (a device that went
    // below the plane of a surface that goes on is met then).
    outside_ = device_height_m() > 0.0 || (outside_ && !device_over_patch());
    clear_ = outside_ && !in_reach;
    return out;
  }
  outside_ = false;

  contact_triangle_ = c.triangle;
  contact_weight_ = c.weight;
  surface_point_m_ = c.point;
  proxy_m_ = rigid_proxy_m;

  const double k_v = params_.coupling_stiffness_N_per_m;
  const Vec3 proxy = compliant ? compliant_proxy_m : rigid_proxy_m;
  out.compliant = compliant;

  Vec3 force_N = k_v * (proxy - device_m);
  const Vec3 relative_velocity = device_velocity_m_per_s - surface_velocity(c);
  force_N -= params_.coupling_damping_N_s_per_m * n.dot(relative_velocity) * n;
  const double normal_N = n.dot(force_N);
  if (normal_N < 0.0) force_N -= normal_N * n;  // push out, never pull in

  const auto& tri = model_->triangle[c.triangle];
  out.force_on_device_N = force_N;
  out.proxy_m = proxy;
  out.surface_point_m = c.point;
  out.normal = n;
  out.contact = true;
  for (int k = 0; k < 3; ++k) {
    out.contact_node[k] = model_->vertex_node[tri[k]];
    out.contact_weight[k] = c.weight[k];
  }
  return out;
}

}  // namespace tissue::haptics
