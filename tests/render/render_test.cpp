#include "render/render.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>

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

bool is_background(const Image& img, int x, int y) {
  const auto p = img.pixel(x, y);
  return p[0] == 255 && p[1] == 255 && p[2] == 255;
}

// Seen from straight above, the orthographic picture of the box is a
// rectangle of the box's x-y extent at the camera's scale.
TEST(Render, ObjectCoversItsProjectedBounds) {
  RenderOptions o;
  o.width_px = 400;
  o.height_px = 300;
  o.azimuth_deg = -90.0;
  o.elevation_deg = 90.0;
  o.legend = false;
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

// Refinement shows: the refined corner is drawn in another palette colour
// than the coarse rest, and the legend lists both levels.
TEST(Render, RefinedRegionChangesColour) {
  RenderOptions o;
  o.width_px = 400;
  o.height_px = 300;
  o.azimuth_deg = -90.0;
  o.elevation_deg = 90.0;
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
  write_png(render_frame(box_surface(true), o), path);
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
