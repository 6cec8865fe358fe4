// Shared by the export suites: test frames, a tiny scan of our own X3D output
// (enough to count and compare what was written, not a general XML parser),
// scratch directories and running external programs.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "export/x3d.hpp"
#include "support/process_support.hpp"

namespace tissue::x3d::testing {

using tissue::testing::quote;
using tissue::testing::run;
using tissue::testing::RunResult;
using tissue::testing::slurp;
using tissue::testing::TempDir;
using tissue::testing::write_text;

// Axis-aligned box [lo, hi]: 8 vertices, 12 triangles CCW seen from outside;
// levels 0..7 per vertex.
SurfaceFrame box_frame(double time_s, std::array<double, 3> lo_m, std::array<double, 3> hi_m);
// A tetrahedron (4 vertices, 4 triangles, outward CCW), a different topology.
SurfaceFrame tetra_frame(double time_s, double size_m);

// Value of attribute `attr` of the n-th element named `element` (0-based);
// XML entities are not decoded. Empty and `found` false when missing.
std::string attribute(const std::string& xml, const std::string& element, const std::string& attr, std::size_t n = 0,
                      bool* found = nullptr);
// How many elements named `element` the document has.
std::size_t count_elements(const std::string& xml, const std::string& element);
// Whitespace/comma separated numbers (X3D MF fields); fails the test on junk.
std::vector<double> numbers(const std::string& text);

// Runs a shell command line, capturing stdout and stderr into `scratch`.
// Path of tovrmlx3d (package view3dscene), empty when not installed.
std::string tovrmlx3d_path();

}  // namespace tissue::x3d::testing
