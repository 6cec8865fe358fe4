#include "physics/field_error.hpp"

#include <gtest/gtest.h>

#include <functional>

#include "physics/body.hpp"
#include "physics_test_support.hpp"

namespace tissue::physics {
namespace {

using testing::beam_scene;
using testing::randomly_refined_beam;

// The beam at uniform `depth` with every node displaced by u(rest).
Body displaced_beam(int depth, const std::function<Vec3(const Vec3&)>& u) {
  scene::Scene s = beam_scene();
  s.adaptivity.min_depth = depth;
  Body body(s);
  body.mesh().for_each_node([&](NodeId n, const mesh::Node&) { body.x_m[n] = body.rest_m[n] + u(body.rest_m[n]); });
  return body;
}

Vec3 linear_field(const Vec3& p) {
  return Vec3(0.01 * p.y() - 0.002, 0.03 * p.x() + 0.02 * p.z(), -0.05 * p.x() + 0.001);
}

// Bending-like: curved along the beam, so linear interpolation misses it.
Vec3 quadratic_field(const Vec3& p) { return Vec3(0.0, 0.0, -0.2 * p.x() * p.x()); }

std::size_t free_nodes(const DisplacementField& f) {
  std::size_t n = 0;
  for (const auto is_free : f.free) n += is_free;
  return n;
}

TEST(FieldError, CaptureKeepsLiveNodesWithTheirDisplacementAndTets) {
  const Body body = displaced_beam(1, linear_field);
  const DisplacementField f = capture_displacement_field(body);
  ASSERT_EQ(f.rest_m.size(), body.mesh().node_count());
  ASSERT_EQ(f.u_m.size(), f.rest_m.size());
  ASSERT_EQ(f.tets.size(), body.mesh().tet_count());
  for (std::size_t i = 0; i < f.rest_m.size(); ++i) EXPECT_LT((f.u_m[i] - linear_field(f.rest_m[i])).norm(), 1e-15);
  // The fixed face (x = 0) is not free; everything else is.
  for (std::size_t i = 0; i < f.rest_m.size(); ++i) EXPECT_EQ(f.free[i] == 1, f.rest_m[i].x() > 0.0) << i;
  for (const auto& t : f.tets)
    for (const int v : t) {
      EXPECT_GE(v, 0);
      EXPECT_LT(static_cast<std::size_t>(v), f.rest_m.size());
    }
}

TEST(FieldError, ARunAgainstItselfHasNoError) {
  const DisplacementField f = capture_displacement_field(displaced_beam(1, quadratic_field));
  const FieldError e = compare_displacement_fields(f, f);
  EXPECT_EQ(e.compared, free_nodes(f));
  EXPECT_EQ(e.unlocated, 0u);
  EXPECT_EQ(e.rms_rel, 0.0);
  EXPECT_EQ(e.max_rel, 0.0);
  EXPECT_GT(e.reference_max_m, 0.0);
}

// Barycentric interpolation reproduces a linear field exactly: a coarse run
// carrying the same linear displacement as a fine reference has no error.
TEST(FieldError, ALinearFieldOnACoarserMeshHasNoError) {
  const DisplacementField reference = capture_displacement_field(displaced_beam(3, linear_field));
  const DisplacementField coarse = capture_displacement_field(displaced_beam(0, linear_field));
  const FieldError e = compare_displacement_fields(reference, coarse);
  EXPECT_EQ(e.compared, free_nodes(reference));
  EXPECT_EQ(e.unlocated, 0u);
  EXPECT_LT(e.rms_rel, 1e-12);
  EXPECT_LT(e.max_rel, 1e-12);
}

// And an adaptively refined mesh (mixed depths) is located and interpolated
// as well as a uniform one.
TEST(FieldError, ALinearFieldOnAMixedDepthMeshHasNoError) {
  const DisplacementField reference = capture_displacement_field(displaced_beam(3, linear_field));
  Body refined = randomly_refined_beam(7, 3);
  refined.mesh().for_each_node(
      [&](NodeId n, const mesh::Node&) { refined.x_m[n] = refined.rest_m[n] + linear_field(refined.rest_m[n]); });
  const FieldError e = compare_displacement_fields(reference, capture_displacement_field(refined));
  EXPECT_EQ(e.compared, free_nodes(reference));
  EXPECT_EQ(e.unlocated, 0u);
  EXPECT_LT(e.rms_rel, 1e-12);
}

// A curved field is interpolated with an error that shrinks as the mesh is
// refined towards the reference (h² for linear elements: ~4x per halving).
TEST(FieldError, ACurvedFieldsErrorShrinksWithRefinement) {
  const DisplacementField reference = capture_displacement_field(displaced_beam(6, quadratic_field));
  const FieldError depth0 =
      compare_displacement_fields(reference, capture_displacement_field(displaced_beam(0, quadratic_field)));
  const FieldError depth3 =
      compare_displacement_fields(reference, capture_displacement_field(displaced_beam(3, quadratic_field)));
  EXPECT_GT(depth0.rms_rel, 1e-4);
  EXPECT_GT(depth3.rms_rel, 0.0);
  EXPECT_LT(depth3.rms_rel, depth0.rms_rel / 3.0);
  EXPECT_LE(depth0.rms_rel, depth0.max_rel);
}

// A uniform offset δ on the same mesh: every compared node is off by |δ|,
// so both measures are |δ| / max |u_ref|.
TEST(FieldError, AnOffsetIsMeasuredRelativeToTheLargestReferenceDisplacement) {
  const Vec3 delta(0.0, 3e-4, -4e-4);  // |δ| = 5e-4 m
  const DisplacementField reference = capture_displacement_field(displaced_beam(1, quadratic_field));
  const DisplacementField shifted =
      capture_displacement_field(displaced_beam(1, [&](const Vec3& p) { return Vec3(quadratic_field(p) + delta); }));
  const FieldError e = compare_displacement_fields(reference, shifted);
  double largest = 0.0;
  for (const auto& u : reference.u_m) largest = std::max(largest, u.norm());
  EXPECT_DOUBLE_EQ(e.reference_max_m, largest);
  EXPECT_NEAR(e.rms_rel, 5e-4 / largest, 1e-12);
  EXPECT_NEAR(e.max_rel, 5e-4 / largest, 1e-12);
}

// Reference nodes outside the other mesh are counted, not compared, and
// kinematic reference nodes are neither.
TEST(FieldError, NodesOutsideTheOtherMeshAreCountedAsUnlocated) {
  const DisplacementField reference = capture_displacement_field(displaced_beam(1, linear_field));
  scene::Scene half = beam_scene();
  half.object.cubes = {4, 2, 2};  // x in [0, 0.2]: the reference's far half is outside
  half.loads.clear();
  half.adaptivity.min_depth = 1;
  Body short_beam(half);
  short_beam.mesh().for_each_node([&](NodeId n, const mesh::Node&) {
    short_beam.x_m[n] = short_beam.rest_m[n] + linear_field(short_beam.rest_m[n]);
  });
  const FieldError e = compare_displacement_fields(reference, capture_displacement_field(short_beam));
  std::size_t inside = 0, outside = 0;
  for (std::size_t i = 0; i < reference.rest_m.size(); ++i) {
    if (!reference.free[i]) continue;
    (reference.rest_m[i].x() <= 0.2 + 1e-12 ? inside : outside)++;
  }
  ASSERT_GT(outside, 0u);
  EXPECT_EQ(e.compared, inside);
  EXPECT_EQ(e.unlocated, outside);
  EXPECT_LT(e.rms_rel, 1e-12);
}

TEST(FieldError, NothingToCompareGivesNaNNotZero) {
  const DisplacementField still =
      capture_displacement_field(displaced_beam(0, [](const Vec3&) { return Vec3::Zero(); }));
  const FieldError e = compare_displacement_fields(still, still);
  EXPECT_EQ(e.reference_max_m, 0.0);
  EXPECT_TRUE(std::isnan(e.rms_rel));  // no scale to be relative to
  EXPECT_TRUE(std::isnan(e.max_rel));
  const FieldError empty = compare_displacement_fields(DisplacementField{}, still);
  EXPECT_EQ(empty.compared, 0u);
  EXPECT_TRUE(std::isnan(empty.rms_rel));
}

}  // namespace
}  // namespace tissue::physics
