#include "render/render.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <utility>

#include "mesh/kuhn_mesh.hpp"
#include "mesh/refine_ops.hpp"
#include "mesh/surface.hpp"
#include "render/png_writer.hpp"

namespace tissue::render {
namespace {

// The surface of a 0.4 x 0.1 x 0.1 m box of Kuhn cubes, optionally refined
// around one corner, as the frames a session holds.
x3d::SurfaceFrame box_surface(bool refine_corner) {
  mesh::KuhnMesh m(mesh::BoxSpec{8, 2, 2, 0.05, 6});
  if (refine_corner) mesh::refine_sphere(m, {{0.4, 0.1, 0.1}, 0.06}, 6, nullptr);
  mesh::SurfaceMesh s;
  mesh::extract_surface(m, &s);
  x3d::SurfaceFrame f;
  for (mesh::NodeId n : s.vertex_nodes) {
    f.vertices_m.push_back(m.node_position_m(n));
    f.vertex_level.push_back(m.node(n).depth);
  }
  f.triangles = s.triangles;
  return f;
}

// 400 x 300, looking straight down: the box's top face fills a known
// rectangle, lit head-on.
RenderOptions top_view(bool legend) {
  RenderOptions o;
  o.width_px = 400;
  o.height_px = 300;
  o.azimuth_deg = -90.0;
  o.elevation_deg = 90.0;
  o.legend = legend;
  return o;
}

bool is_background(const Image& img, int x, int y) {
  const auto p = img.pixel(x, y);
  return p[0] == 255 && p[1] == 255 && p[2] == 255;
}

// Seen from straight above, the orthographic picture of the box is a
// rectangle of the box's x-y extent at the camera's scale.
TEST(Render, ObjectCoversItsProjectedBounds) {
  RenderOptions o = top_view(false);
  const Image img = render_frame(box_surface(false), o);
  int covered = 0;
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x) covered += is_background(img, x, y) ? 0 : 1;
  // Camera: half height = 1.05 x bounding radius (aspect 4:3 > 1).
  const double radius = 0.5 * std::sqrt(0.4 * 0.4 + 0.1 * 0.1 + 0.1 * 0.1);
  const double px_per_m = img.height / (2 * 1.05 * radius);
  const double expected = (0.4 * px_per_m) * (0.1 * px_per_m);
  EXPECT_NEAR(covered, expected, 0.05 * expected);
  // And it is centred.
  EXPECT_FALSE(is_background(img, img.width / 2, img.height / 2));
  EXPECT_TRUE(is_background(img, 2, 2));
}

// The picture does not depend on the object's size or place: the box scaled
// to ±3e38 m (finite; a blank picture before) or to a nanometre (a dot
// before), or moved a kilometre, draws as the box itself. Within a few
// pixels: the float rasteriser rounds differently at each scale.
TEST(Render, APictureDoesNotDependOnTheObjectsScaleOrPlace) {
  const RenderOptions o = top_view(true);
  const x3d::SurfaceFrame box = box_surface(true);
  const Image reference = render_frame(box, o);
  const auto transformed = [&](double scale, double shift_m) {
    x3d::SurfaceFrame f = box;
    for (auto& v : f.vertices_m)
      for (int a = 0; a < 3; ++a) v[a] = (v[a] - 0.2) * scale + shift_m;
    return f;
  };
  for (const auto& [scale, shift_m] :
       {std::pair{1.5e39, 0.0}, std::pair{5e-9, 0.0}, std::pair{1.0, 1000.0}, std::pair{1e300, 0.0}}) {
    SCOPED_TRACE(::testing::Message() << "scale " << scale << " shift " << shift_m);
    const Image img = render_frame(transformed(scale, shift_m), o);
    int differing = 0, covered = 0;
    for (int y = 0; y < img.height; ++y)
      for (int x = 0; x < img.width; ++x) {
        differing += img.pixel(x, y) != reference.pixel(x, y) ? 1 : 0;
        covered += is_background(img, x, y) ? 0 : 1;
      }
    EXPECT_GT(covered, img.width * img.height / 20);  // not blank
    EXPECT_LT(differing, img.width * img.height / 200) << differing << " pixels differ";
  }
}

// Coordinates near the double's limit draw as the same shape at unit size.
// A triangle with an edge of 2e308 m had an infinite normal, a NaN shade and
// a NaN converted to a colour byte (undefined; black on x86); a tetrahedron
// spanning 3e308 m on every axis had an infinite bounding radius and drew
// nothing.
TEST(Render, SurfacesSpanningTheWholeDoubleRangeDrawAsAtUnitSize) {
  const RenderOptions o = top_view(false);
  x3d::SurfaceFrame triangle;
  triangle.vertices_m = {{-1, 0, 0}, {1, 0, 0}, {0, 1, 1}};
  triangle.triangles = {{0, 1, 2}};
  x3d::SurfaceFrame tetra;
  tetra.vertices_m = {{-1.5, -1.5, -1.5}, {1.5, -1.5, -1.5}, {-1.5, 1.5, -1.5}, {-1.5, -1.5, 1.5}};
  tetra.triangles = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  for (const x3d::SurfaceFrame* unit : {&triangle, &tetra}) {
    SCOPED_TRACE(::testing::Message() << unit->vertices_m.size() << " vertices");
    x3d::SurfaceFrame huge = *unit;
    for (auto& v : huge.vertices_m)
      for (double& x : v) x *= 1e308;
    const Image reference = render_frame(*unit, o);
    const Image img = render_frame(huge, o);
    int differing = 0, covered = 0, black = 0;
    for (int y = 0; y < img.height; ++y)
      for (int x = 0; x < img.width; ++x) {
        differing += img.pixel(x, y) != reference.pixel(x, y) ? 1 : 0;
        covered += is_background(img, x, y) ? 0 : 1;
        const auto p = img.pixel(x, y);
        black += p[0] == 0 && p[1] == 0 && p[2] == 0 ? 1 : 0;
      }
    EXPECT_GT(covered, img.width * img.height / 20);  // not blank
    EXPECT_EQ(black, 0);
    EXPECT_LT(differing, img.width * img.height / 200) << differing << " pixels differ";
  }
}

// The camera turns smoothly over the poles: one degree of elevation moves
// few pixels (81° to 82° turned the picture by ~60°), and the azimuth still
// turns the view from straight above (it froze from 82° on).
TEST(Render, TheViewChangesSmoothlyWithElevationAndAzimuthTurnsItFromAbove) {
  RenderOptions o = top_view(false);
  const x3d::SurfaceFrame box = box_surface(false);
  // Pixels covered in one picture and background in the other (the shade
  // of every face changes a little with any turn; the silhouette moves only
  // as far as the turn).
  const auto differing = [](const Image& a, const Image& b) {
    int n = 0;
    for (int y = 0; y < a.height; ++y)
      for (int x = 0; x < a.width; ++x) n += is_background(a, x, y) != is_background(b, x, y) ? 1 : 0;
    return n;
  };
  o.azimuth_deg = -60.0;
  for (double elevation = 75.0; elevation < 90.0; elevation += 1.0) {
    SCOPED_TRACE(::testing::Message() << "elevation " << elevation);
    o.elevation_deg = elevation;
    const Image lower = render_frame(box, o);
    o.elevation_deg = elevation + 1.0;
    const Image higher = render_frame(box, o);
    EXPECT_LT(differing(lower, higher), lower.width * lower.height / 10);
  }
  o.elevation_deg = 90.0;
  o.azimuth_deg = -90.0;
  const Image along_x = render_frame(box, o);
  o.azimuth_deg = 0.0;
  const Image along_y = render_frame(box, o);
  EXPECT_GT(differing(along_x, along_y), along_x.width * along_x.height / 10);
}

// Angles are taken modulo a full turn before they become radians:
// --azimuth 1e308 overflowed to inf radians, the view matrix was NaN and
// the picture blank (exit 0, nothing said).
TEST(Render, HugeCameraAnglesDrawAsTheirRemainderOfAFullTurn) {
  const x3d::SurfaceFrame box = box_surface(false);
  const auto covered = [](const Image& img) {
    int n = 0;
    for (int y = 0; y < img.height; ++y)
      for (int x = 0; x < img.width; ++x) n += is_background(img, x, y) ? 0 : 1;
    return n;
  };
  for (const double angle_deg : {1e308, -1e308, 1e20, 3630.0, -7170.0}) {
    SCOPED_TRACE(::testing::Message() << "angle " << angle_deg);
    RenderOptions huge = top_view(false), reduced = top_view(false);
    huge.azimuth_deg = angle_deg;
    reduced.azimuth_deg = std::fmod(angle_deg, 360.0);
    huge.elevation_deg = reduced.elevation_deg = 30.0;
    const Image by_azimuth = render_frame(box, huge);
    EXPECT_GT(covered(by_azimuth), by_azimuth.width * by_azimuth.height / 100);
    EXPECT_EQ(by_azimuth.rgba, render_frame(box, reduced).rgba);
    // The library takes any finite elevation (the CLI: -90 to 90).
    huge.azimuth_deg = reduced.azimuth_deg = -60.0;
    huge.elevation_deg = angle_deg;
    reduced.elevation_deg = std::fmod(angle_deg, 360.0);
    const Image by_elevation = render_frame(box, huge);
    EXPECT_GT(covered(by_elevation), by_elevation.width * by_elevation.height / 100);
    EXPECT_EQ(by_elevation.rgba, render_frame(box, reduced).rgba);
  }
}

// Refinement shows: the refined corner is drawn in another palette colour
// than the coarse rest, and the legend lists both levels.
TEST(Render, RefinedRegionChangesColour) {
  RenderOptions o = top_view(true);
  const Image coarse = render_frame(box_surface(false), o);
  const Image refined = render_frame(box_surface(true), o);
  // x = 0.38 m (near the refined end) and x = 0.02 m (far from it), y = 0.05 m.
  const double radius = 0.5 * std::sqrt(0.18);
  const double px_per_m = o.height_px / (2 * 1.05 * radius);
  auto at = [&](double x_m, double y_m) {
    return std::pair{static_cast<int>(o.width_px / 2 + (x_m - 0.2) * px_per_m),
                     static_cast<int>(o.height_px / 2 - (y_m - 0.05) * px_per_m)};
  };
  const auto [fx, fy] = at(0.38, 0.08);
  const auto [cx, cy] = at(0.05, 0.05);
  EXPECT_NE(refined.pixel(fx, fy), coarse.pixel(fx, fy));  // the refined corner changed colour
  EXPECT_EQ(refined.pixel(cx, cy), coarse.pixel(cx, cy));  // the far end did not
}

// Strain colouring: a field rising along x is drawn from the low end of the
// ramp (x = 0) to the high end (x = 0.4 m); seen from above the top face is
// lit head-on, so the pixels are the ramp colours themselves.
TEST(Render, StrainColoursFollowTheField) {
  x3d::SurfaceFrame f = box_surface(false);
  for (const auto& v : f.vertices_m) f.vertex_strain_energy_Pa.push_back(static_cast<float>(250.0 * v[0]));
  RenderOptions o = top_view(false);
  o.colour = x3d::ColourMode::kStrain;
  const auto range = strain_range_Pa(f, o);
  EXPECT_FLOAT_EQ(range[0], 0.0);
  EXPECT_FLOAT_EQ(range[1], 100.0);
  const Image img = render_frame(f, o);
  const double radius = 0.5 * std::sqrt(0.18);
  const double px_per_m = o.height_px / (2 * 1.05 * radius);
  const auto pixel_at_in = [&](const Image& picture, double x_m) {
    return picture.pixel(static_cast<int>(o.width_px / 2 + (x_m - 0.2) * px_per_m), o.height_px / 2);
  };
  const auto pixel_at = [&](double x_m) { return pixel_at_in(img, x_m); };
  // A triangle takes the mean of its vertices: in the first 0.05 m cube that
  // is 1/3 or 2/3 of the way across, t = 0.04 or 0.08 (and 0.92 / 0.96 at
  // the other end).
  const auto expect_near_ramp = [&](double x_m, double t_lo, double t_hi) {
    const auto p = pixel_at(x_m);
    double best = 1e9;
    for (double t = t_lo; t <= t_hi; t += 0.005) {
      const auto c = x3d::strain_colour(t);
      double d = 0.0;
      for (int k = 0; k < 3; ++k) d = std::max(d, std::abs(p[k] - c[k] * 255.0));
      best = std::min(best, d);
    }
    EXPECT_LT(best, 4.0) << "x=" << x_m << " is not on the ramp between " << t_lo << " and " << t_hi;
  };
  expect_near_ramp(0.02, 0.03, 0.09);
  expect_near_ramp(0.38, 0.91, 0.97);
  EXPECT_NE(pixel_at(0.02), pixel_at(0.38));
  // A fixed range moves the colours: everything above 10 Pa saturates.
  o.strain_range_Pa = std::array<double, 2>{0.0, 10.0};
  const Image fixed = render_frame(f, o);
  const auto p = fixed.pixel(static_cast<int>(o.width_px / 2 + 0.0 * px_per_m), o.height_px / 2);
  const auto top = x3d::strain_colour(1.0);
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(p[k], top[k] * 255.0, 12.0) << k;
  // Rounding is no strain: a field spanning 6e-26 Pa (a body at rest) is
  // drawn as constant, the ramp's low end, not across the whole ramp.
  o.strain_range_Pa.reset();
  for (std::size_t i = 0; i < f.vertices_m.size(); ++i)
    f.vertex_strain_energy_Pa[i] = static_cast<float>(6e-26 * f.vertices_m[i][0] / 0.4);
  const auto noise = strain_range_Pa(f, o);
  EXPECT_EQ(noise[0], noise[1]);
  const Image at_rest = render_frame(f, o);
  const auto low = x3d::strain_colour(0.0);
  for (const double x_m : {0.02, 0.38})
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(pixel_at_in(at_rest, x_m)[k], low[k] * 255.0, 12.0) << x_m;
  // Strain colouring needs the values.
  f.vertex_strain_energy_Pa.clear();
  EXPECT_THROW(render_frame(f, o), x3d::X3dInputError);
  o.strain_range_Pa = std::array<double, 2>{5.0, 5.0};
  EXPECT_THROW(strain_range_Pa(f, o), x3d::X3dInputError);
}

// A Renderer keeps its context between frames, but every frame is drawn as
// if alone: the same pixels as render_frame, whatever came before (another
// size, colouring, camera).
TEST(Render, ARendererGivesTheSamePicturesAsSingleFrames) {
  RenderOptions small;
  small.width_px = 200;
  small.height_px = 120;
  RenderOptions strain;
  strain.colour = x3d::ColourMode::kStrain;
  strain.azimuth_deg = 10.0;
  strain.elevation_deg = 70.0;
  x3d::SurfaceFrame strained = box_surface(true);
  for (const auto& v : strained.vertices_m) strained.vertex_strain_energy_Pa.push_back(static_cast<float>(v[0]));
  Renderer renderer;
  for (int round = 0; round < 2; ++round) {
    EXPECT_EQ(renderer.render(box_surface(true), RenderOptions{}).rgba,
              render_frame(box_surface(true), RenderOptions{}).rgba);
    EXPECT_EQ(renderer.render(box_surface(false), small).rgba, render_frame(box_surface(false), small).rgba);
    EXPECT_EQ(renderer.render(strained, strain).rgba, render_frame(strained, strain).rgba);
  }
}

// A sequence's camera box is grown frame by frame: the union of the frames'
// bounds, whatever their order, and a frame's own box gives the same picture
// as no box at all.
TEST(Render, ExtendingABoxFrameByFrameGivesTheUnionOfTheirBounds) {
  x3d::SurfaceFrame a = box_surface(false);
  x3d::SurfaceFrame b = box_surface(false);
  for (auto& v : b.vertices_m) v = {v[0] - 1.0, v[1] + 0.5, v[2] * 3.0};
  Box_m ab = empty_box_m(), ba = empty_box_m();
  extend_box_m(ab, a);
  extend_box_m(ab, b);
  extend_box_m(ba, b);
  extend_box_m(ba, a);
  EXPECT_EQ(ab, ba);
  const Box_m expected{{{-1.0, 0.0, 0.0}, {0.4, 0.1 + 0.5, 0.3}}};
  for (int c = 0; c < 2; ++c)
    for (int axis = 0; axis < 3; ++axis) EXPECT_NEAR(ab[c][axis], expected[c][axis], 1e-12) << c << " " << axis;
  Box_m own = empty_box_m();
  extend_box_m(own, a);
  RenderOptions boxed;
  boxed.frame_box_m = own;
  EXPECT_EQ(render_frame(a, boxed).rgba, render_frame(a, RenderOptions{}).rgba);
  // An empty box is not a camera box.
  boxed.frame_box_m = empty_box_m();
  EXPECT_THROW(render_frame(a, boxed), RenderError);
}

TEST(Render, BadInputIsAClearError) {
  x3d::SurfaceFrame f = box_surface(false);
  f.triangles[3][1] = 100000;
  EXPECT_THROW(render_frame(f, RenderOptions{}), x3d::X3dInputError);
  RenderOptions tiny;
  tiny.width_px = 4;
  EXPECT_THROW(render_frame(box_surface(false), tiny), RenderError);
}

TEST(Render, WritesAPngFile) {
  const std::string path = (std::filesystem::temp_directory_path() / "tissue_render_test.png").string();
  RenderOptions o;
  o.width_px = 64;
  o.height_px = 48;
  const Image image = render_frame(box_surface(true), o);
  write_png(image, path);
  std::FILE* f = std::fopen(path.c_str(), "rb");
  ASSERT_NE(f, nullptr);
  unsigned char sig[8] = {};
  ASSERT_EQ(std::fread(sig, 1, 8, f), 8u);
  std::fclose(f);
  EXPECT_EQ(sig[1], 'P');
  EXPECT_EQ(sig[2], 'N');
  EXPECT_EQ(sig[3], 'G');
  // What read_png returns is what was written, pixel for pixel.
  const Image back = read_png(path);
  EXPECT_EQ(back.width, image.width);
  EXPECT_EQ(back.height, image.height);
  EXPECT_EQ(back.rgba, image.rgba);
  std::filesystem::remove(path);
  EXPECT_THROW(write_png(render_frame(box_surface(false), o), "/nonexistent-dir/x.png"), RenderError);
  EXPECT_THROW(read_png("/nonexistent-dir/x.png"), RenderError);
  const std::string junk = (std::filesystem::temp_directory_path() / "tissue_render_junk.png").string();
  std::FILE* j = std::fopen(junk.c_str(), "wb");
  ASSERT_NE(j, nullptr);
  std::fputs("\x89PNG not really", j);
  std::fclose(j);
  EXPECT_THROW(read_png(junk), RenderError);
  std::filesystem::remove(junk);
}

}  // namespace
}  // namespace tissue::render
