// Off-screen pictures of the surface with OSMesa (no display, no GPU): what
// `tissue render` draws. Fixed-function OpenGL in a compatibility context is
// enough for flat-shaded triangles; a picture is a plain RGBA buffer, written
// to PNG by png_writer.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <optional>
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
  // Camera direction: azimuth about +z from +x, elevation above the xy plane;
  // any finite angle, taken modulo 360 degrees. The view is orthographic and
  // fits the frame's bounding sphere.
  double azimuth_deg = -60.0, elevation_deg = 30.0;
  bool legend = true;  // level swatches with their numbers (strain: the ramp), bottom left
  std::array<std::uint8_t, 3> background{255, 255, 255};
  // kLevel: bisection level; kStrain: strain-energy density (the frame must
  // carry vertex_strain_energy_Pa), on the X3D export's ramp.
  x3d::ColourMode colour = x3d::ColourMode::kLevel;
  // Strain ramp ends (Pa); unset: the frame's own min..max.
  std::optional<std::array<double, 2>> strain_range_Pa;
  // Box the camera frames (lo, hi corners, m); unset: the frame's own
  // bounds. A sequence passes the union over its frames, so one camera
  // shows the motion instead of re-centring on every frame.
  std::optional<std::array<std::array<double, 3>, 2>> frame_box_m;  // a Box_m
};

// Axis-aligned bounds (lo, hi corners, m) for RenderOptions::frame_box_m.
using Box_m = std::array<std::array<double, 3>, 2>;

// The box that covers nothing (lo = +inf, hi = -inf): extend_box_m grows it.
Box_m empty_box_m();

// Grows `box` to cover `frame`'s vertices, so a sequence read frame by frame
// gets the union of its frames' bounds without holding them all.
void extend_box_m(Box_m& box, const x3d::SurfaceFrame& frame);

// The strain range render_frame uses for `frame` with `options` (for
// captions): options.strain_range_Pa or the frame's min..max. Throws
// x3d::X3dInputError for a non-finite or empty given range.
std::array<double, 2> strain_range_Pa(const x3d::SurfaceFrame& frame, const RenderOptions& options);

// Level colouring: triangles take the palette colour (x3d::level_colour, the
// same as the X3D export) of their finest vertex. Strain colouring: the ramp
// colour (x3d::strain_colour) of the mean of their vertices' values. Both
// shaded by the angle to a head light.
// Renders one frame (validated like the X3D export: throws
// x3d::X3dInputError for bad input, RenderError when OSMesa fails).
Image render_frame(const x3d::SurfaceFrame& frame, const RenderOptions& options);

// The same, keeping the OpenGL context and buffers between frames (a frame
// sequence pays the context set-up once). Frames are independent: each
// render() gives exactly what render_frame() gives. One thread at a time.
class Renderer {
 public:
  Renderer();
  ~Renderer();
  Renderer(Renderer&&) noexcept;
  Renderer& operator=(Renderer&&) noexcept;
  Image render(const x3d::SurfaceFrame& frame, const RenderOptions& options);

 private:
  struct Context;
  std::unique_ptr<Context> context_;
};

}  // namespace tissue::render
