#include "export/export_test_support.hpp"

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>

namespace tissue::x3d::testing {

SurfaceFrame box_frame(double time_s, std::array<double, 3> lo, std::array<double, 3> hi) {
  SurfaceFrame f;
  f.time_s = time_s;
  // Vertex i has x from bit 0, y from bit 1, z from bit 2.
  for (std::uint32_t i = 0; i < 8; ++i)
    f.vertices_m.push_back({(i & 1) ? hi[0] : lo[0], (i & 2) ? hi[1] : lo[1], (i & 4) ? hi[2] : lo[2]});
  // Two CCW triangles per face, seen from outside.
  f.triangles = {{0, 2, 3}, {0, 3, 1},   // z = lo (normal -z)
                 {4, 5, 7}, {4, 7, 6},   // z = hi (+z)
                 {0, 1, 5}, {0, 5, 4},   // y = lo (-y)
                 {2, 6, 7}, {2, 7, 3},   // y = hi (+y)
                 {0, 4, 6}, {0, 6, 2},   // x = lo (-x)
                 {1, 3, 7}, {1, 7, 5}};  // x = hi (+x)
  f.vertex_level = {0, 1, 2, 3, 4, 5, 6, 7};
  f.vertex_strain_energy_Pa = {0.f, 10.f, 20.f, 30.f, 40.f, 50.f, 60.f, 70.f};
  return f;
}

SurfaceFrame tetra_frame(double time_s, double s) {
  SurfaceFrame f;
  f.time_s = time_s;
  f.vertices_m = {{0, 0, 0}, {s, 0, 0}, {0, s, 0}, {0, 0, s}};
  f.triangles = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  f.vertex_level = {1, 1, 2, 2};
  f.vertex_strain_energy_Pa = {1.f, 2.f, 3.f, 4.f};
  return f;
}

namespace {

// Start of the n-th "<element" followed by whitespace, '/' or '>'.
std::size_t find_element(const std::string& xml, const std::string& element, std::size_t n) {
  const std::string open = "<" + element;
  std::size_t pos = 0, seen = 0;
  while ((pos = xml.find(open, pos)) != std::string::npos) {
    const std::size_t after = pos + open.size();
    if (after < xml.size() &&
        (std::isspace(static_cast<unsigned char>(xml[after])) || xml[after] == '/' || xml[after] == '>')) {
      if (seen++ == n) return pos;
    }
    pos = after;
  }
  return std::string::npos;
}

}  // namespace

std::string attribute(const std::string& xml, const std::string& element, const std::string& attr, std::size_t n,
                      bool* found) {
  if (found) *found = false;
  const std::size_t start = find_element(xml, element, n);
  if (start == std::string::npos) return {};
  const std::size_t end = xml.find('>', start);
  const std::string tag = xml.substr(start, end - start);
  for (const char q : {'\'', '"'}) {
    const std::string key = " " + attr + "=" + q;
    const std::size_t at = tag.find(key);
    if (at == std::string::npos) continue;
    const std::size_t v = at + key.size();
    const std::size_t close = tag.find(q, v);
    if (close == std::string::npos) return {};
    if (found) *found = true;
    return tag.substr(v, close - v);
  }
  return {};
}

std::size_t count_elements(const std::string& xml, const std::string& element) {
  std::size_t n = 0;
  while (find_element(xml, element, n) != std::string::npos) ++n;
  return n;
}

std::vector<double> numbers(const std::string& text) {
  std::vector<double> out;
  const char* p = text.data();
  const char* end = p + text.size();
  while (p < end) {
    if (std::isspace(static_cast<unsigned char>(*p)) || *p == ',') {
      ++p;
      continue;
    }
    double v = 0.0;
    const auto r = std::from_chars(p, end, v);
    if (r.ec != std::errc()) {
      ADD_FAILURE() << "not a number at '" << std::string(p, std::min<std::size_t>(20, end - p)) << "'";
      return out;
    }
    out.push_back(v);
    p = r.ptr;
  }
  return out;
}

std::string tovrmlx3d_path() {
  const char* path = std::getenv("PATH");
  std::stringstream dirs(path ? path : "");
  std::string dir;
  while (std::getline(dirs, dir, ':')) {
    const std::string candidate = (dir.empty() ? std::string(".") : dir) + "/tovrmlx3d";
    if (::access(candidate.c_str(), X_OK) == 0) return candidate;
  }
  return {};
}

}  // namespace tissue::x3d::testing
