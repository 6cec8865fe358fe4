// Our X3D in a real third-party browser: view3dscene (Castle Game Engine)
// renders the exported snapshot headless under Xvfb, and the picture shows
// the object, framed by our Viewpoint, in the palette colour of its level.
// tovrmlx3d only parses; this is the check that a lab user opening the file
// actually sees the surface. Skipped when view3dscene or xvfb-run is missing
// (scripts/install-deps.sh installs both).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <string>

#include "export/export_test_support.hpp"
#include "export/x3d.hpp"
#include "render/png_writer.hpp"

namespace tissue::render {
namespace {

using x3d::testing::quote;
using x3d::testing::run;
using x3d::testing::TempDir;

bool on_path(const std::string& program) {
  return std::system(("command -v " + program + " >/dev/null 2>&1").c_str()) == 0;
}

// A 0.1 m cube, every vertex at `level`: one palette colour everywhere.
x3d::SurfaceFrame cube(std::uint8_t level) {
  x3d::SurfaceFrame f = x3d::testing::box_frame(0.0, {0.0, 0.0, 0.0}, {0.1, 0.1, 0.1});
  f.vertex_level.assign(f.vertices_m.size(), level);
  return f;
}

// view3dscene's screenshot of the X3D snapshot of `frame`.
Image screenshot(const x3d::SurfaceFrame& frame, const TempDir& dir, const std::string& name) {
  const std::string x3d_path = dir / (name + ".x3d"), png_path = dir / (name + ".png");
  x3d::testing::write_text(x3d_path, x3d::x3d_snapshot(frame, x3d::X3dOptions{}));
  const x3d::testing::RunResult r = run("timeout 120 xvfb-run -a -s '-screen 0 640x480x24' view3dscene " +
                                            quote(x3d_path) + " --screenshot 0 " + quote(png_path),
                                        dir);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  return read_png(png_path);
}

int distance(const std::array<std::uint8_t, 4>& p, const std::array<float, 3>& rgb) {
  int d = 0;
  for (int c = 0; c < 3; ++c) d = std::max(d, std::abs(int(p[c]) - int(std::lround(rgb[c] * 255.0f))));
  return d;
}

TEST(X3dView3dscene, ShowsTheSurfaceFramedAndInItsLevelColour) {
  if (!on_path("view3dscene") || !on_path("xvfb-run")) GTEST_SKIP() << "view3dscene or xvfb-run not installed";
  TempDir dir;
  for (const std::uint8_t level : {std::uint8_t{0}, std::uint8_t{2}}) {
    SCOPED_TRACE("level " + std::to_string(level));
    const Image img = screenshot(cube(level), dir, "level" + std::to_string(level));
    ASSERT_GT(img.width, 100);
    ASSERT_GT(img.height, 100);
    // Background: the corner colour; the object: every pixel that differs.
    const auto bg = img.pixel(0, 0);
    int covered = 0;
    double cx = 0.0, cy = 0.0;
    for (int y = 0; y < img.height; ++y)
      for (int x = 0; x < img.width; ++x) {
        const auto p = img.pixel(x, y);
        if (p[0] == bg[0] && p[1] == bg[1] && p[2] == bg[2]) continue;
        ++covered;
        cx += x;
        cy += y;
      }
    const double fraction = double(covered) / (double(img.width) * img.height);
    // Framed: visible, not filling the window, centred by our Viewpoint.
    EXPECT_GT(fraction, 0.05);
    EXPECT_LT(fraction, 0.95);
    ASSERT_GT(covered, 0);
    EXPECT_NEAR(cx / covered, img.width / 2.0, 0.1 * img.width);
    EXPECT_NEAR(cy / covered, img.height / 2.0, 0.1 * img.height);
    // The face towards the camera is lit head-on: its centre shows the
    // palette colour itself (a little shading allowed), not another level's.
    const auto centre = img.pixel(img.width / 2, img.height / 2);
    EXPECT_LE(distance(centre, x3d::level_colour(level)), 40)
        << "centre pixel " << int(centre[0]) << "," << int(centre[1]) << "," << int(centre[2]);
    const std::uint8_t other = level == 0 ? 2 : 0;
    EXPECT_GT(distance(centre, x3d::level_colour(other)), 60);
  }
}

}  // namespace
}  // namespace tissue::render
