#include "physics/field_error.hpp"

#include <gtest/gtest.h>

#include <cmath>
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

// A tet of the other mesh reaching far past the reference (more bins away
// than an int holds) still finds the reference nodes inside it: its bin
// range is clamped before it becomes an int (the conversion of 1.6e12 bins
// was undefined, and on x86 gave INT_MIN, bin 0, so only the first bin's
// nodes were found).
TEST(FieldError, AHugeTetOfTheOtherMeshFindsTheNodesInside) {
  DisplacementField reference;
  const Vec3 u(0.0, 0.0, 0.01);  // the same everywhere: interpolation is exact
  for (int k = 0; k < 3; ++k)
    for (int j = 0; j < 3; ++j)
      for (int i = 0; i < 3; ++i) {
        reference.rest_m.push_back(0.5 * Vec3(i, j, k));
        reference.u_m.push_back(u);
        reference.free.push_back(1);
      }
  DisplacementField huge;
  huge.rest_m = {Vec3(-1e12, -1e12, -1e12), Vec3(1e13, -1e12, -1e12), Vec3(-1e12, 1e13, -1e12),
                 Vec3(-1e12, -1e12, 1e13)};
  huge.u_m.assign(4, u);
  huge.free.assign(4, 1);
  huge.tets = {{0, 1, 2, 3}};
  const FieldError e = compare_displacement_fields(reference, huge);
  EXPECT_EQ(e.unlocated, 0u);
  EXPECT_EQ(e.compared, reference.rest_m.size());
  EXPECT_LT(e.max_rel, 1e-9);
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

// Trajectories: u(t) sampled at two rates.
struct Samples {
  std::vector<double> t_s;
  std::vector<Vec3> u_m;
};

Samples sample(double dt_s, double end_s, const std::function<Vec3(double)>& u) {
  Samples s;
  for (int k = 1; k * dt_s <= end_s + 1e-12; ++k) {
    s.t_s.push_back(k * dt_s);  // as a run records: after each step
    s.u_m.push_back(u(k * dt_s));
  }
  return s;
}

Vec3 oscillation(double t) { return Vec3(0.0, 0.0, -0.01 * (1.0 - std::exp(-20.0 * t) * std::cos(60.0 * t))); }

TEST(TrajectoryError, ARunAgainstItselfHasNoError) {
  const Samples a = sample(1e-3, 0.5, oscillation);
  const TrajectoryError e = compare_trajectories(a.t_s, a.u_m, a.t_s, a.u_m);
  EXPECT_EQ(e.compared, a.t_s.size());
  EXPECT_EQ(e.rms_rel, 0.0);
  EXPECT_EQ(e.max_rel, 0.0);
}

// A linear motion is interpolated exactly between reference samples, so a
// coarser run of the same motion (samples between the reference's) is exact.
TEST(TrajectoryError, ALinearMotionSampledCoarserHasNoError) {
  const auto line = [](double t) { return Vec3(0.002 * t, -0.03 * t, 0.001); };
  const Samples reference = sample(1e-3, 0.5, line);
  const Samples coarse = sample(2.5e-3, 0.5, line);  // 2.5 ms: most samples fall between the reference's
  const TrajectoryError e = compare_trajectories(reference.t_s, reference.u_m, coarse.t_s, coarse.u_m);
  EXPECT_EQ(e.compared, coarse.t_s.size());
  EXPECT_LT(e.rms_rel, 1e-12);
  EXPECT_LT(e.max_rel, 1e-12);
}

// A run that damps the motion (an implicit integrator at a large step) ends
// where the reference does but departs from it on the way.
TEST(TrajectoryError, ADampedRunIsFarOffOnTheWayThoughItEndsTheSame) {
  const Samples reference = sample(1e-3, 0.5, oscillation);
  const Samples damped =
      sample(5e-3, 0.5, [](double t) { return Vec3(0.0, 0.0, -0.01 * (1.0 - std::exp(-40.0 * t))); });
  const TrajectoryError e = compare_trajectories(reference.t_s, reference.u_m, damped.t_s, damped.u_m);
  EXPECT_LT((damped.u_m.back() - reference.u_m.back()).norm(), 1e-6);  // the same end state
  EXPECT_GT(e.rms_rel, 0.1);
  EXPECT_GE(e.max_rel, e.rms_rel);
  // While the same motion at 5 ms is within the interpolation error of 1 ms samples.
  const Samples same = sample(5e-3, 0.5, oscillation);
  EXPECT_LT(compare_trajectories(reference.t_s, reference.u_m, same.t_s, same.u_m).rms_rel, 0.01);
}

TEST(TrajectoryError, AnOffsetIsMeasuredRelativeToTheLargestReferenceDisplacement) {
  const Samples reference = sample(1e-3, 0.2, oscillation);
  Samples shifted = reference;
  for (auto& u : shifted.u_m) u += Vec3(3e-4, 0.0, 4e-4);  // |δ| = 5e-4 m
  double largest = 0.0;
  for (const auto& u : reference.u_m) largest = std::max(largest, u.norm());
  const TrajectoryError e = compare_trajectories(reference.t_s, reference.u_m, shifted.t_s, shifted.u_m);
  EXPECT_DOUBLE_EQ(e.reference_max_m, largest);
  EXPECT_NEAR(e.rms_rel, 5e-4 / largest, 1e-12);
  EXPECT_NEAR(e.max_rel, 5e-4 / largest, 1e-12);
}

// A run longer than the reference (or starting before it) is compared where
// both exist; the ends of the span count despite rounded step times.
TEST(TrajectoryError, SamplesOutsideTheReferenceSpanAreNotCompared) {
  const Samples reference = sample(1e-3, 0.1, oscillation);
  Samples longer = sample(1e-3, 0.3, oscillation);
  longer.t_s.insert(longer.t_s.begin(), 0.0);
  longer.u_m.insert(longer.u_m.begin(), Vec3(1.0, 1.0, 1.0));  // before the reference: never compared
  const TrajectoryError e = compare_trajectories(reference.t_s, reference.u_m, longer.t_s, longer.u_m);
  EXPECT_EQ(e.compared, reference.t_s.size());
  EXPECT_LT(e.rms_rel, 1e-12);
  // Step times accumulated by summing dt are within rounding of k dt.
  Samples summed;
  double t = 0.0;
  for (int k = 0; k < 100; ++k) {
    t += 1e-3;
    summed.t_s.push_back(t);
    summed.u_m.push_back(oscillation(t));
  }
  EXPECT_EQ(compare_trajectories(reference.t_s, reference.u_m, summed.t_s, summed.u_m).compared, 100u);
}

TEST(TrajectoryError, NothingToCompareGivesNaNNotZero) {
  const Samples still = sample(1e-3, 0.1, [](double) { return Vec3::Zero(); });
  EXPECT_TRUE(std::isnan(compare_trajectories(still.t_s, still.u_m, still.t_s, still.u_m).rms_rel));
  const Samples moving = sample(1e-3, 0.1, oscillation);
  const TrajectoryError none = compare_trajectories({}, {}, moving.t_s, moving.u_m);
  EXPECT_EQ(none.compared, 0u);
  EXPECT_TRUE(std::isnan(none.rms_rel));
}

}  // namespace
}  // namespace tissue::physics
