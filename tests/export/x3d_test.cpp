// X3D output of tissue_export: structure, index ranges, round-tripped
// coordinates and bounds (scanned back from our own text), input
// validation, and acceptance by a third-party X3D reader (tovrmlx3d).
#include "export/x3d.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "export/export_test_support.hpp"

namespace tissue::x3d {
namespace {

using testing::attribute;
using testing::box_frame;
using testing::count_elements;
using testing::numbers;
using testing::tetra_frame;

// Checks one IndexedTriangleSet of `xml` (the n-th) against `frame`:
// every index in range, the index list and the coordinates read back
// exactly, one colour per vertex, and the coordinate bounds match.
void expect_shape_matches(const std::string& xml, std::size_t n, const SurfaceFrame& frame) {
  const std::vector<double> index = numbers(attribute(xml, "IndexedTriangleSet", "index", n));
  const std::vector<double> point = numbers(attribute(xml, "Coordinate", "point", n));
  const std::vector<double> colour = numbers(attribute(xml, "Color", "color", n));
  ASSERT_EQ(point.size(), 3 * frame.vertices_m.size());
  ASSERT_EQ(index.size(), 3 * frame.triangles.size());
  EXPECT_EQ(colour.size(), point.size());
  for (std::size_t i = 0; i < index.size(); ++i) {
    EXPECT_GE(index[i], 0.0);
    EXPECT_LT(index[i], static_cast<double>(frame.vertices_m.size())) << "index " << i;
    EXPECT_EQ(index[i], frame.triangles[i / 3][i % 3]);
  }
  std::array<double, 3> lo{INFINITY, INFINITY, INFINITY}, hi{-INFINITY, -INFINITY, -INFINITY};
  std::array<double, 3> flo = lo, fhi = hi;
  for (std::size_t v = 0; v < frame.vertices_m.size(); ++v)
    for (int a = 0; a < 3; ++a) {
      EXPECT_EQ(point[3 * v + a], frame.vertices_m[v][a]) << "vertex " << v << " axis " << a;  // exact round trip
      lo[a] = std::min(lo[a], point[3 * v + a]);
      hi[a] = std::max(hi[a], point[3 * v + a]);
      flo[a] = std::min(flo[a], frame.vertices_m[v][a]);
      fhi[a] = std::max(fhi[a], frame.vertices_m[v][a]);
    }
  EXPECT_EQ(lo, flo);
  EXPECT_EQ(hi, fhi);
  for (const double c : colour) {
    EXPECT_GE(c, 0.0);
    EXPECT_LE(c, 1.0);
  }
}

TEST(X3dSnapshot, HeaderSceneAndGeometryRoundTrip) {
  // Values that need all 17 digits to survive a text round trip.
  SurfaceFrame f = box_frame(1.5, {-0.1, 0.2 / 3.0, 1e-7}, {0.05 + 1e-12, 0.3, 0.123456789012345678});
  const std::string xml = x3d_snapshot(f, X3dOptions{});
  EXPECT_EQ(xml.rfind("<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n", 0), 0u);
  EXPECT_NE(xml.find("<X3D profile='Interchange' version='3.3'"), std::string::npos);
  EXPECT_NE(xml.find("</X3D>"), std::string::npos);
  EXPECT_EQ(count_elements(xml, "Scene"), 1u);
  EXPECT_EQ(count_elements(xml, "Shape"), 1u);
  EXPECT_EQ(count_elements(xml, "Viewpoint"), 1u);
  EXPECT_EQ(attribute(xml, "IndexedTriangleSet", "solid"), "true");
  EXPECT_EQ(attribute(xml, "IndexedTriangleSet", "ccw"), "true");
  EXPECT_EQ(count_elements(xml, "TimeSensor"), 0u);
  expect_shape_matches(xml, 0, f);
}

TEST(X3dSnapshot, ViewpointFramesTheBounds) {
  const SurfaceFrame f = box_frame(0.0, {0.0, 0.0, 0.0}, {0.04, 0.02, 0.01});
  const std::string xml = x3d_snapshot(f, X3dOptions{});
  const std::vector<double> pos = numbers(attribute(xml, "Viewpoint", "position"));
  const std::vector<double> centre = numbers(attribute(xml, "Viewpoint", "centerOfRotation"));
  const std::vector<double> fov = numbers(attribute(xml, "Viewpoint", "fieldOfView"));
  ASSERT_EQ(pos.size(), 3u);
  ASSERT_EQ(centre.size(), 3u);
  ASSERT_EQ(fov.size(), 1u);
  EXPECT_DOUBLE_EQ(centre[0], 0.02);
  EXPECT_DOUBLE_EQ(centre[1], 0.01);
  EXPECT_DOUBLE_EQ(centre[2], 0.005);
  // Looking down -z from in front: the bounding sphere fits the field of view.
  const double radius = 0.5 * std::sqrt(0.04 * 0.04 + 0.02 * 0.02 + 0.01 * 0.01);
  const double distance = pos[2] - centre[2];
  EXPECT_GT(distance, radius);
  EXPECT_GE(std::asin(radius / distance), 0.0);
  EXPECT_LE(std::asin(radius / distance), 0.5 * fov[0]);
  // Near plane (avatarSize[0] / 2) must not clip a small specimen away.
  const std::vector<double> avatar = numbers(attribute(xml, "NavigationInfo", "avatarSize"));
  ASSERT_EQ(avatar.size(), 3u);
  EXPECT_LT(avatar[0] / 2, distance - radius);
}

// The same box at any scale is framed the same: squared spans overflowed
// above ~1.3e154 m (the viewpoint was put 0.029 m from a 1e200 m box, inside
// it) and underflowed below ~1e-154 m (0.029 m from a 1e-200 m box).
TEST(X3dSnapshot, ViewpointFramesTheBoundsAtAnyScale) {
  for (const double scale : {1e200, 1e-200, 1e150}) {
    SCOPED_TRACE(::testing::Message() << "scale " << scale);
    const SurfaceFrame f = box_frame(0.0, {0.0, 0.0, 0.0}, {0.04 * scale, 0.02 * scale, 0.01 * scale});
    const std::string xml = x3d_snapshot(f, X3dOptions{});
    const std::vector<double> pos = numbers(attribute(xml, "Viewpoint", "position"));
    const std::vector<double> centre = numbers(attribute(xml, "Viewpoint", "centerOfRotation"));
    const std::vector<double> fov = numbers(attribute(xml, "Viewpoint", "fieldOfView"));
    ASSERT_EQ(pos.size(), 3u);
    ASSERT_EQ(centre.size(), 3u);
    ASSERT_EQ(fov.size(), 1u);
    EXPECT_DOUBLE_EQ(centre[2], 0.005 * scale);
    const double radius = 0.5 * std::sqrt(0.04 * 0.04 + 0.02 * 0.02 + 0.01 * 0.01) * scale;
    const double distance = pos[2] - centre[2];
    EXPECT_GT(distance, radius);
    EXPECT_LE(std::asin(radius / distance), 0.5 * fov[0]);
    EXPECT_GE(std::asin(radius / distance), 0.25 * fov[0]) << "the box fills a good part of the view";
  }
}

// Coordinates near the double's limit: the centre of 1e308 and 1.5e308 was
// computed as (lo + hi) / 2, inf, and written as position='inf ...' (no
// SFVec3f). Where a finite viewpoint exists it is used; where none does the
// export is refused naming the frame.
TEST(X3dSnapshot, ViewpointNearTheLimitOfDoublesIsFiniteOrRefused) {
  const SurfaceFrame far = box_frame(0.0, {1e308, 0.0, 0.0}, {1.5e308, 1.0, 1.0});
  const std::string xml = x3d_snapshot(far, X3dOptions{});
  const std::vector<double> pos = numbers(attribute(xml, "Viewpoint", "position"));
  const std::vector<double> centre = numbers(attribute(xml, "Viewpoint", "centerOfRotation"));
  ASSERT_EQ(pos.size(), 3u);
  ASSERT_EQ(centre.size(), 3u);
  for (int a = 0; a < 3; ++a) {
    EXPECT_TRUE(std::isfinite(pos[a])) << attribute(xml, "Viewpoint", "position");
    EXPECT_TRUE(std::isfinite(centre[a])) << attribute(xml, "Viewpoint", "centerOfRotation");
  }
  EXPECT_DOUBLE_EQ(centre[0], 1.25e308);
  const SurfaceFrame huge = box_frame(2.5, {1e308, 1e308, 1e308}, {1.5e308, 1.5e308, 1.5e308});
  try {
    x3d_snapshot(huge, X3dOptions{});
    ADD_FAILURE() << "no error";
  } catch (const X3dInputError& e) {
    EXPECT_EQ(std::string(e.what()),
              "frame (t=2.5 s): no viewpoint outside the surface is a finite position (its bounds reach 1.5e+308 m "
              "from the origin)");
  }
  try {
    x3d_animation({huge, box_frame(3.0, {0, 0, 0}, {1, 1, 1})}, X3dOptions{});
    ADD_FAILURE() << "no error";
  } catch (const X3dInputError& e) {
    EXPECT_EQ(std::string(e.what()).rfind("frames 0 to 1: no viewpoint outside the surface is a finite position", 0),
              0u)
        << e.what();
  }
}

TEST(X3dSnapshot, LevelColoursFollowThePalette) {
  const SurfaceFrame f = box_frame(0.0, {0, 0, 0}, {1, 1, 1});
  const std::vector<double> colour = numbers(attribute(x3d_snapshot(f, X3dOptions{}), "Color", "color"));
  ASSERT_EQ(colour.size(), 24u);
  for (std::size_t v = 0; v < 8; ++v) {
    const auto expected = level_colour(f.vertex_level[v]);
    for (int a = 0; a < 3; ++a) EXPECT_NEAR(colour[3 * v + a], expected[a], 1e-3) << "vertex " << v;
  }
  // Distinct colours for neighbouring levels, and the palette wraps.
  EXPECT_NE(level_colour(0), level_colour(1));
  EXPECT_EQ(level_colour(0), level_colour(kLevelPaletteSize));
}

TEST(X3dSnapshot, StrainColoursUseTheRampAndRecordTheRange) {
  const SurfaceFrame f = box_frame(0.0, {0, 0, 0}, {1, 1, 1});  // strain 0, 10, ..., 70 Pa
  X3dOptions o;
  o.colour = ColourMode::kStrain;
  const std::string xml = x3d_snapshot(f, o);
  const std::vector<double> colour = numbers(attribute(xml, "Color", "color"));
  ASSERT_EQ(colour.size(), 24u);
  for (int a = 0; a < 3; ++a) {
    EXPECT_NEAR(colour[a], strain_colour(0.0)[a], 1e-3);
    EXPECT_NEAR(colour[21 + a], strain_colour(1.0)[a], 1e-3);
    EXPECT_NEAR(colour[9 + a], strain_colour(3.0 / 7.0)[a], 1e-3);
  }
  EXPECT_EQ(numbers(attribute(xml, "MetadataDouble", "value")), (std::vector<double>{0.0, 70.0}));
  EXPECT_EQ(attribute(xml, "MetadataDouble", "name"), "strain_energy_range_Pa");
  // A fixed range clamps values outside it.
  o.strain_range_Pa = std::array<double, 2>{20.0, 30.0};
  const std::vector<double> clamped = numbers(attribute(x3d_snapshot(f, o), "Color", "color"));
  for (int a = 0; a < 3; ++a) {
    EXPECT_NEAR(clamped[a], strain_colour(0.0)[a], 1e-3);
    EXPECT_NEAR(clamped[21 + a], strain_colour(1.0)[a], 1e-3);
  }
  // A range from the data narrower than kStrainRangeFloor_Pa is rounding (a
  // body at rest): every vertex takes the ramp's low end.
  o.strain_range_Pa.reset();
  SurfaceFrame at_rest = f;
  for (std::size_t i = 0; i < at_rest.vertex_strain_energy_Pa.size(); ++i)
    at_rest.vertex_strain_energy_Pa[i] = static_cast<float>(1e-26 * static_cast<double>(i));
  const std::vector<double> flat = numbers(attribute(x3d_snapshot(at_rest, o), "Color", "color"));
  ASSERT_EQ(flat.size(), 24u);
  for (std::size_t i = 0; i < flat.size(); ++i) EXPECT_NEAR(flat[i], strain_colour(0.0)[i % 3], 1e-3) << i;
  // ... and its recorded range is that one value, not the data's min..max
  // (docs/x3d-export.md says so): here a spread of 1e-20 Pa above 2e-20.
  for (std::size_t i = 0; i < at_rest.vertex_strain_energy_Pa.size(); ++i)
    at_rest.vertex_strain_energy_Pa[i] = static_cast<float>(2e-20 + 1e-20 * static_cast<double>(i) / 7.0);
  const float lowest = at_rest.vertex_strain_energy_Pa[0];
  const std::string rest_xml = x3d_snapshot(at_rest, o);
  EXPECT_EQ(numbers(attribute(rest_xml, "MetadataDouble", "value")),
            (std::vector<double>{static_cast<double>(lowest), static_cast<double>(lowest)}));
  for (const char* end : {"min", "max"}) {
    const std::string tag = std::string("<meta name='tissue.strain_energy_") + end + "_Pa' content='";
    const std::size_t at = rest_xml.find(tag);
    ASSERT_NE(at, std::string::npos) << end;
    EXPECT_EQ(numbers(rest_xml.substr(at + tag.size(), rest_xml.find('\'', at + tag.size()) - at - tag.size())),
              (std::vector<double>{static_cast<double>(lowest)}))
        << end;
  }
  // The ramp is monotonic in brightness (viridis).
  double last = -1.0;
  for (int i = 0; i <= 20; ++i) {
    const auto c = strain_colour(i / 20.0);
    const double luma = 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
    EXPECT_GT(luma, last);
    last = luma;
  }
}

TEST(X3dSnapshot, TitleIsEscaped) {
  X3dOptions o;
  o.title = "a<b & 'c' \"d\"";
  const std::string xml = x3d_snapshot(box_frame(0, {0, 0, 0}, {1, 1, 1}), o);
  EXPECT_EQ(xml.find("a<b"), std::string::npos);
  EXPECT_NE(xml.find("a&lt;b &amp; &apos;c&apos; &quot;d&quot;"), std::string::npos);
}

// Each bad frame must be rejected with a message naming the field.
void expect_rejected(const SurfaceFrame& f, const std::string& fragment, ColourMode mode = ColourMode::kLevel) {
  X3dOptions o;
  o.colour = mode;
  try {
    x3d_snapshot(f, o);
    ADD_FAILURE() << "accepted; expected an error containing '" << fragment << "'";
  } catch (const X3dInputError& e) {
    EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
  }
}

TEST(X3dSnapshot, DegenerateInputsAreRejected) {
  const SurfaceFrame good = box_frame(0, {0, 0, 0}, {1, 1, 1});
  SurfaceFrame f = good;
  f.triangles[5][1] = 8;
  expect_rejected(f, "triangles[5][1] = 8 is out of range (the frame has 8 vertices)");
  f = good;
  f.triangles[0] = {std::numeric_limits<std::uint32_t>::max(), 1, 2};
  expect_rejected(f, "triangles[0][0] = 4294967295 is out of range");
  f = good;
  f.vertices_m[3][2] = std::numeric_limits<double>::quiet_NaN();
  expect_rejected(f, "vertices_m[3][2] is not finite");
  f = good;
  f.vertices_m[0][0] = std::numeric_limits<double>::infinity();
  expect_rejected(f, "vertices_m[0][0] is not finite");
  f = good;
  f.triangles.clear();
  expect_rejected(f, "triangles is empty");
  f = good;
  f.vertices_m.clear();
  expect_rejected(f, "vertices_m is empty");
  f = good;
  f.triangles[2] = {4, 4, 1};
  expect_rejected(f, "triangles[2] repeats a vertex");
  f = good;
  f.vertex_level.pop_back();
  expect_rejected(f, "vertex_level has 7 values for 8 vertices");
  f = good;
  f.time_s = std::numeric_limits<double>::infinity();
  expect_rejected(f, "time_s is not finite");
  f = good;
  f.vertex_strain_energy_Pa.clear();
  expect_rejected(f, "strain colouring needs one vertex_strain_energy_Pa value per vertex, got 0", ColourMode::kStrain);
  f = good;
  f.vertex_strain_energy_Pa[4] = std::numeric_limits<float>::quiet_NaN();
  expect_rejected(f, "vertex_strain_energy_Pa[4] is not finite", ColourMode::kStrain);
  // Per-triangle strain is optional, but when present one finite value >= 0
  // per triangle (12 triangles in the box).
  f = good;
  f.triangle_strain_energy_J_per_m3.assign(good.triangles.size(), 2.5f);
  EXPECT_NO_THROW(x3d_snapshot(f, X3dOptions{}));
  f.triangle_strain_energy_J_per_m3.pop_back();
  expect_rejected(f, "triangle_strain_energy_J_per_m3 has 11 values for 12 triangles");
  f.triangle_strain_energy_J_per_m3.assign(good.triangles.size() + 1, 2.5f);
  expect_rejected(f, "triangle_strain_energy_J_per_m3 has 13 values for 12 triangles");
  f.triangle_strain_energy_J_per_m3.assign(good.triangles.size(), 2.5f);
  f.triangle_strain_energy_J_per_m3[7] = -1.0f;
  expect_rejected(f, "triangle_strain_energy_J_per_m3[7] = -1.000000 is not a strain energy density");
  f.triangle_strain_energy_J_per_m3[7] = std::numeric_limits<float>::quiet_NaN();
  expect_rejected(f, "triangle_strain_energy_J_per_m3[7] = nan is not a strain energy density");
  // Level colouring does not need strain values at all.
  f = good;
  f.vertex_strain_energy_Pa.clear();
  f.vertex_level.clear();
  EXPECT_NO_THROW(x3d_snapshot(f, X3dOptions{}));
  X3dOptions bad_range;
  bad_range.colour = ColourMode::kStrain;
  bad_range.strain_range_Pa = std::array<double, 2>{5.0, 5.0};
  EXPECT_THROW(x3d_snapshot(good, bad_range), X3dInputError);
}

// Frames 0-2: a box moving in x; frames 3-4: a tetrahedron; frame 5: the box again.
std::vector<SurfaceFrame> mixed_frames() {
  std::vector<SurfaceFrame> frames;
  for (int k = 0; k < 3; ++k)
    frames.push_back(box_frame(1.0 + 0.5 * k, {0.01 * k, 0, 0}, {0.01 * k + 0.02, 0.02, 0.02}));
  frames.push_back(tetra_frame(2.5, 0.02));
  frames.push_back(tetra_frame(3.0, 0.03));
  frames.push_back(box_frame(5.0, {0, 0, 0}, {0.02, 0.02, 0.02}));
  return frames;
}

TEST(X3dAnimation, RunsSplitWhereTopologyChanges) {
  const std::vector<SurfaceFrame> frames = mixed_frames();
  const std::vector<FrameRun> runs = animation_runs(frames, X3dOptions{});
  ASSERT_EQ(runs.size(), 3u);
  EXPECT_EQ(runs[0].first, 0u);
  EXPECT_EQ(runs[0].end, 3u);
  EXPECT_EQ(runs[1].first, 3u);
  EXPECT_EQ(runs[1].end, 5u);
  EXPECT_EQ(runs[2].first, 5u);
  EXPECT_EQ(runs[2].end, 6u);
  // A level change alone also splits (colours cannot be interpolated).
  std::vector<SurfaceFrame> relevelled = {frames[0], frames[1]};
  relevelled[1].vertex_level[0] = 3;
  EXPECT_EQ(animation_runs(relevelled, X3dOptions{}).size(), 2u);
  // Strain colours change every frame: a flip-book.
  X3dOptions strain;
  strain.colour = ColourMode::kStrain;
  EXPECT_EQ(animation_runs(frames, strain).size(), frames.size());
}

TEST(X3dAnimation, TimeSensorInterpolatorsSequencerAndRoutes) {
  const std::vector<SurfaceFrame> frames = mixed_frames();
  const std::string xml = x3d_animation(frames, X3dOptions{});
  EXPECT_NE(xml.find("<X3D profile='Interchange' version='3.3'"), std::string::npos);
  EXPECT_NE(xml.find("<component name='EventUtilities' level='1'/>"), std::string::npos);
  EXPECT_EQ(numbers(attribute(xml, "TimeSensor", "cycleInterval")), (std::vector<double>{4.0}));
  EXPECT_EQ(attribute(xml, "TimeSensor", "loop"), "true");
  ASSERT_EQ(count_elements(xml, "Shape"), 3u);
  expect_shape_matches(xml, 0, frames[0]);
  expect_shape_matches(xml, 1, frames[3]);
  expect_shape_matches(xml, 2, frames[5]);

  // Two runs move (3 and 2 frames); the last is a single frame.
  ASSERT_EQ(count_elements(xml, "CoordinateInterpolator"), 2u);
  EXPECT_EQ(attribute(xml, "CoordinateInterpolator", "DEF", 0), "Move0");
  EXPECT_EQ(numbers(attribute(xml, "CoordinateInterpolator", "key", 0)), (std::vector<double>{0.0, 0.125, 0.25}));
  const std::vector<double> kv0 = numbers(attribute(xml, "CoordinateInterpolator", "keyValue", 0));
  ASSERT_EQ(kv0.size(), 3u * 8u * 3u);  // keys x vertices x xyz
  for (std::size_t k = 0; k < 3; ++k)
    for (std::size_t v = 0; v < 8; ++v)
      for (int a = 0; a < 3; ++a) EXPECT_EQ(kv0[(k * 8 + v) * 3 + a], frames[k].vertices_m[v][a]);
  EXPECT_EQ(attribute(xml, "CoordinateInterpolator", "DEF", 1), "Move1");
  EXPECT_EQ(numbers(attribute(xml, "CoordinateInterpolator", "key", 1)), (std::vector<double>{0.375, 0.5}));
  EXPECT_EQ(numbers(attribute(xml, "CoordinateInterpolator", "keyValue", 1)).size(), 2u * 4u * 3u);

  EXPECT_EQ(numbers(attribute(xml, "IntegerSequencer", "key")), (std::vector<double>{0.0, 0.375, 1.0}));
  EXPECT_EQ(numbers(attribute(xml, "IntegerSequencer", "keyValue")), (std::vector<double>{0, 1, 2}));
  EXPECT_EQ(attribute(xml, "Switch", "DEF"), "Runs");

  // Every ROUTE names nodes that exist.
  const std::size_t routes = count_elements(xml, "ROUTE");
  EXPECT_EQ(routes, 2u * 2u + 2u);
  for (std::size_t r = 0; r < routes; ++r)
    for (const char* end : {"fromNode", "toNode"}) {
      const std::string def = attribute(xml, "ROUTE", end, r);
      EXPECT_NE(xml.find("DEF='" + def + "'"), std::string::npos) << "ROUTE " << r << " " << end << "=" << def;
    }
  EXPECT_NE(xml.find("toNode='Coords0' toField='point'"), std::string::npos);
  EXPECT_NE(xml.find("toNode='Runs' toField='whichChoice'"), std::string::npos);
}

TEST(X3dAnimation, OneTopologyNeedsNoSequencer) {
  std::vector<SurfaceFrame> frames = {box_frame(0, {0, 0, 0}, {1, 1, 1}), box_frame(2, {0, 0, 0}, {2, 1, 1})};
  const std::string xml = x3d_animation(frames, X3dOptions{});
  EXPECT_EQ(count_elements(xml, "IntegerSequencer"), 0u);
  EXPECT_EQ(xml.find("EventUtilities"), std::string::npos);  // plain Interchange profile
  EXPECT_EQ(count_elements(xml, "CoordinateInterpolator"), 1u);
  EXPECT_EQ(numbers(attribute(xml, "TimeSensor", "cycleInterval")), (std::vector<double>{2.0}));
}

TEST(X3dAnimation, BadFrameSequencesAreRejected) {
  const SurfaceFrame a = box_frame(1.0, {0, 0, 0}, {1, 1, 1});
  SurfaceFrame b = a;
  b.time_s = 0.5;
  try {
    x3d_animation({a, b}, X3dOptions{});
    ADD_FAILURE() << "backwards time accepted";
  } catch (const X3dInputError& e) {
    EXPECT_NE(std::string(e.what()).find("frame 1 (t=0.5 s): time_s goes backwards"), std::string::npos) << e.what();
  }
  // Times are said to 9 digits; two that differ only past them, with every
  // digit (both "t=0.3 s" would not say what went backwards).
  SurfaceFrame summed = a, rounded = a;
  summed.time_s = 0.1 + 0.2;  // 0.30000000000000004
  rounded.time_s = 0.3;
  try {
    x3d_animation({summed, rounded}, X3dOptions{});
    ADD_FAILURE() << "backwards time accepted";
  } catch (const X3dInputError& e) {
    EXPECT_NE(std::string(e.what()).find(
                  "frame 1 (t=0.3 s): time_s goes backwards (frame 0 (t=0.30000000000000004 s)); frames must be in "
                  "time order"),
              std::string::npos)
        << e.what();
  }
  b.time_s = 1.0;
  try {
    x3d_animation({a, b}, X3dOptions{});
    ADD_FAILURE() << "zero-length window accepted";
  } catch (const X3dInputError& e) {
    EXPECT_EQ(std::string(e.what()),
              "frames span no time (first and last at t=1 s): an animation needs a window longer than 0 s");
  }
  // Finite times, an infinite span: it was called no time, with 300 digits.
  SurfaceFrame early = a, late = a;
  early.time_s = -1e308;
  late.time_s = 1e308;
  try {
    x3d_animation({early, late}, X3dOptions{});
    ADD_FAILURE() << "infinite window accepted";
  } catch (const X3dInputError& e) {
    EXPECT_EQ(std::string(e.what()), "frames 0 to 1 span more time than a number holds (t=-1e+308 s to 1e+308 s)");
  }
  EXPECT_THROW(x3d_animation({a}, X3dOptions{}), X3dInputError);  // one frame
  b.time_s = 2.0;
  b.triangles[11][2] = 99;
  try {
    x3d_animation({a, b}, X3dOptions{});
    ADD_FAILURE() << "bad index accepted";
  } catch (const X3dInputError& e) {
    EXPECT_NE(std::string(e.what()).find("frame 1 (t=2 s): triangles[11][2] = 99 is out of range"), std::string::npos)
        << e.what();
  }
}

// tovrmlx3d parses X3D but exits 0 on errors: the pass criterion is exit 0
// AND nothing on stderr (docs: /work/shared/design/STACK.md).
void expect_tovrmlx3d_accepts(const std::string& xml, const char* name) {
  const std::string tool = testing::tovrmlx3d_path();
  if (tool.empty()) GTEST_SKIP() << "tovrmlx3d not installed (apt-get install view3dscene)";
  testing::TempDir dir;
  const std::string path = dir / name;
  testing::write_text(path, xml);
  const testing::RunResult r = testing::run(testing::quote(tool) + " " + testing::quote(path) + " --encoding xml", dir);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.err, "");
  EXPECT_NE(r.out.find("IndexedTriangleSet"), std::string::npos);  // it did read the geometry
}

TEST(X3dThirdParty, TovrmlAcceptsSnapshotLevel) {
  expect_tovrmlx3d_accepts(x3d_snapshot(box_frame(0, {0, 0, 0}, {0.05, 0.02, 0.01}), X3dOptions{}), "snap.x3d");
}

TEST(X3dThirdParty, TovrmlAcceptsSnapshotStrain) {
  X3dOptions o;
  o.colour = ColourMode::kStrain;
  expect_tovrmlx3d_accepts(x3d_snapshot(box_frame(0, {0, 0, 0}, {0.05, 0.02, 0.01}), o), "strain.x3d");
}

TEST(X3dThirdParty, TovrmlAcceptsAnimation) {
  expect_tovrmlx3d_accepts(x3d_animation(mixed_frames(), X3dOptions{}), "anim.x3d");
}

TEST(X3dThirdParty, TovrmlAcceptsStrainFlipBook) {
  X3dOptions o;
  o.colour = ColourMode::kStrain;
  expect_tovrmlx3d_accepts(x3d_animation(mixed_frames(), o), "flip.x3d");
}

TEST(VertexStrainFromTriangles, MeanOverAdjacentTrianglesAndZeroForUnused) {
  // Two triangles sharing the edge 1-2; vertex 4 is used by none.
  const std::vector<std::array<std::uint32_t, 3>> tris = {{0, 1, 2}, {1, 3, 2}};
  const std::vector<float> v = vertex_strain_from_triangles(5, tris, {2.0f, 6.0f});
  ASSERT_EQ(v.size(), 5u);
  EXPECT_FLOAT_EQ(v[0], 2.0f);
  EXPECT_FLOAT_EQ(v[1], 4.0f);
  EXPECT_FLOAT_EQ(v[2], 4.0f);
  EXPECT_FLOAT_EQ(v[3], 6.0f);
  EXPECT_FLOAT_EQ(v[4], 0.0f);
  EXPECT_TRUE(vertex_strain_from_triangles(5, tris, {}).empty());
}

TEST(VertexStrainFromTriangles, RejectsSizeMismatchAndBadIndices) {
  const std::vector<std::array<std::uint32_t, 3>> tris = {{0, 1, 2}};
  EXPECT_THROW(vertex_strain_from_triangles(3, tris, {1.0f, 2.0f}), X3dInputError);
  EXPECT_THROW(vertex_strain_from_triangles(2, tris, {1.0f}), X3dInputError);
}

}  // namespace
}  // namespace tissue::x3d
