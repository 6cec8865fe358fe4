// X3D 3.3 (XML encoding) export of the tissue surface: a snapshot of one
// frame, or an animation over a window of frames (docs/x3d-export.md).
// Pure functions over plain frames: no threads, no I/O, no dependency on the
// simulation, so recorded sessions, live sources and tests all feed the same
// code. Invalid input throws X3dInputError naming the frame, the field and
// the reason; nothing is written for it.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

namespace tissue::x3d {

// One surface frame as drawn: what daemon/mesh/surface.hpp extracts and what
// a session stores per mesh frame (docs/session-format.md).
struct SurfaceFrame {
  double time_s = 0.0;  // session time of the frame
  std::vector<std::array<double, 3>> vertices_m;
  // Indices into vertices_m, counter-clockwise seen from outside.
  std::vector<std::array<std::uint32_t, 3>> triangles;
  // Bisection depth per vertex; empty means all 0.
  std::vector<std::uint8_t> vertex_level;
  // Strain energy density per vertex; may be empty (sessions of format
  // version 1 do not store it). Required only for ColourMode::kStrain.
  std::vector<float> vertex_strain_energy_Pa;
  // Strain energy density per triangle (J/m^3 = Pa), as recorded: the values
  // vertex_strain_energy_Pa is averaged from, kept so that a consumer that
  // wants per-triangle values (replay sends them on the wire) gets them
  // exactly instead of re-averaging the vertices. Empty when the source has
  // none or does not keep them (format version 1, a frame recorded without
  // strain, the live subscribers, which give per-vertex values only);
  // otherwise one value per triangle.
  std::vector<float> triangle_strain_energy_J_per_m3;
};

class X3dInputError : public std::invalid_argument {
 public:
  using std::invalid_argument::invalid_argument;
};

enum class ColourMode {
  kLevel,   // discrete palette by bisection depth (kLevelPalette, wrapping)
  kStrain,  // continuous ramp over strain energy density
};

struct X3dOptions {
  ColourMode colour = ColourMode::kLevel;
  // WorldInfo title and Viewpoint description (XML-escaped on output).
  std::string title = "tissue surface";
  // Ramp range for kStrain, [low, high] in Pa. Unset: min..max of the data
  // (over all frames of an animation, so colours compare across frames).
  std::optional<std::array<double, 2>> strain_range_Pa;
};

// The level palette: sRGB in [0,1], Okabe-Ito (colour-blind safe). Level L
// uses entry L % size.
inline constexpr std::size_t kLevelPaletteSize = 8;
std::array<float, 3> level_colour(std::uint8_t level);
// The strain ramp (viridis, piecewise linear): t in [0,1], clamped.
std::array<float, 3> strain_colour(double t);
// A strain range taken from the data (not given) that is narrower than this
// is rounding, not deformation: a body at rest spanned 0 to 6e-26 Pa and was
// drawn across the whole ramp. Such a field is drawn as constant (the low
// end of the ramp). Rounding strains are ~1e-15; 1e-12 Pa is a strain of
// 3e-8 even at E = 1e3 Pa.
inline constexpr double kStrainRangeFloor_Pa = 1e-12;

// Per-vertex strain-energy density from per-triangle values (what messages
// and sessions carry): the mean over the triangles that use the vertex, 0 for
// a vertex no triangle uses. Empty when `triangle_strain` is empty. Throws
// X3dInputError when sizes disagree or an index is out of range.
std::vector<float> vertex_strain_from_triangles(std::size_t vertex_count,
                                                const std::vector<std::array<std::uint32_t, 3>>& triangles,
                                                const std::vector<float>& triangle_strain);

// Throws X3dInputError unless the frame is drawable: finite time and
// coordinates, at least one vertex and one triangle, every index in range,
// no triangle repeating a vertex, vertex_level empty or one per vertex,
// triangle_strain_energy_J_per_m3 empty or one finite value >= 0 per triangle,
// and (when `need_strain`) one finite strain value per vertex. `label` prefixes
// messages, e.g. "frame 3".
void validate_frame(const SurfaceFrame& frame, bool need_strain, const std::string& label);

// One frame as a complete X3D document.
std::string x3d_snapshot(const SurfaceFrame& frame, const X3dOptions& options);

// Frames (time_s non-decreasing, first < last) as a looping animation whose
// cycle is last.time_s - first.time_s. Sessions store no node ids, so frames
// cannot be matched across topology changes: consecutive frames with the
// same triangles and the same colours form a run, each run is one Shape with
// its own Coordinate (driven by a CoordinateInterpolator when the run has
// more than one frame), and an IntegerSequencer switches runs on and off
// through a Switch. Strain colours change every frame, so with kStrain every
// frame is its own run (a flip-book, positions not interpolated).
std::string x3d_animation(const std::vector<SurfaceFrame>& frames, const X3dOptions& options);

// How x3d_animation groups frames: [first, end) index ranges, in order.
struct FrameRun {
  std::size_t first = 0, end = 0;
};
std::vector<FrameRun> animation_runs(const std::vector<SurfaceFrame>& frames, const X3dOptions& options);

}  // namespace tissue::x3d
