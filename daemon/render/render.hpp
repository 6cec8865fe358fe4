// Off-screen pictures of the surface with OSMesa (no display, no GPU): what
// `tissue render` draws. Fixed-function OpenGL in a compatibility context is
// enough for flat-shaded triangles; a picture is a plain RGBA buffer, written
// to PNG by png_writer.
#pragma once

#include <array>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include "export/x3d.hpp"

namespace tissue::render {

class RenderError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct Image {
  int width = 0, height = 0;
  std::vector<std::uint8_t> rgba;  // row 0 at the top, 4 bytes per pixel
  std::array<std::uint8_t, 4> pixel(int x, int y) const {
    const std::size_t i = 4 * (static_cast<std::size_t>(y) * width + x);
    return {rgba[i], rgba[i + 1], rgba[i + 2], rgba[i + 3]};
  }
};

struct RenderOptions {
  int width_px = 800, height_px = 600;
  // Camera direction: azimuth about +z from +x, elevation above the xy plane.
  // The view is orthographic and fits the frame's bounding sphere.
  double azimuth_deg = -60.0, elevation_deg = 30.0;
  bool legend = true;  // level swatches with their numbers, bottom left
  std::array<std::uint8_t, 3> background{255, 255, 255};
};

// Triangles take the palette colour (x3d::level_colour, the same as the X3D
// export) of their finest vertex, shaded by the angle to a head light.
// Renders one frame (validated like the X3D export: throws
// x3d::X3dInputError for bad input, RenderError when OSMesa fails).
Image render_frame(const x3d::SurfaceFrame& frame, const RenderOptions& options);

}  // namespace tissue::render
