#include "export/x3d.hpp"
#include "export/frame_source.hpp"  // frame_time_text
#include "util/xml.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <limits>
#include <string_view>

namespace tissue::x3d {

namespace {

// Okabe-Ito: distinguishable for the common colour-vision deficiencies, and
// the first levels (coarse mesh) get the calmest colours.
constexpr std::array<std::array<float, 3>, kLevelPaletteSize> kLevelPalette = {{
    {0.337f, 0.706f, 0.914f},  // sky blue
    {0.000f, 0.620f, 0.451f},  // bluish green
    {0.941f, 0.894f, 0.259f},  // yellow
    {0.902f, 0.624f, 0.000f},  // orange
    {0.835f, 0.369f, 0.000f},  // vermillion
    {0.800f, 0.475f, 0.655f},  // reddish purple
    {0.000f, 0.447f, 0.698f},  // blue
    {0.600f, 0.600f, 0.600f},  // grey
}};

// Viridis at 9 evenly spaced stops: perceptually uniform and monotonic in
// lightness, so a grey-scale print still orders the values.
constexpr std::array<std::array<float, 3>, 9> kViridis = {{
    {0.267f, 0.005f, 0.329f},
    {0.279f, 0.175f, 0.483f},
    {0.230f, 0.322f, 0.546f},
    {0.173f, 0.449f, 0.558f},
    {0.128f, 0.567f, 0.551f},
    {0.153f, 0.683f, 0.502f},
    {0.361f, 0.786f, 0.388f},
    {0.668f, 0.862f, 0.196f},
    {0.993f, 0.906f, 0.144f},
}};

// The viewer's default field of view (X3D Viewpoint default, pi/4).
constexpr double kFieldOfView_rad = 0.7853982;

// Appends with the shortest representation that reads back to the same
// double (std::to_chars guarantees the round trip); no locale involved.
void put(std::string& out, double v) {
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  out.append(buf, r.ptr);
}

// Colours need no round trip: 4 significant digits are far below what a
// display shows and keep files small.
void put_colour(std::string& out, float v) {
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof buf, v, std::chars_format::general, 4);
  out.append(buf, r.ptr);
}

// For messages: 6 significant digits ("1.5e+308").
std::string short_number(double v) {
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof buf, v, std::chars_format::general, 6);
  return std::string(buf, r.ptr);
}

void put(std::string& out, std::uint64_t v) {
  char buf[24];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  out.append(buf, r.ptr);
}

// An X3D SFString inside an MFString attribute is double-quoted; '"' and
// '\' are backslash-escaped first, then the whole is XML-escaped.
std::string mf_string_item(std::string_view s) {
  std::string q = "\"";
  for (const char c : s) {
    if (c == '"' || c == '\\') q += '\\';
    q += c;
  }
  q += '"';
  return util::escape_xml(q);
}

// For messages, to 9 digits as both clients say frame times: "(t=0.3 s)",
// not the accumulated "(t=0.30000000000000004 s)".
std::string describe_time(const SurfaceFrame& f) { return " (t=" + frame_time_text(f.time_s) + " s)"; }

struct Bounds {
  std::array<double, 3> lo{std::numeric_limits<double>::infinity(), std::numeric_limits<double>::infinity(),
                           std::numeric_limits<double>::infinity()};
  std::array<double, 3> hi{-std::numeric_limits<double>::infinity(), -std::numeric_limits<double>::infinity(),
                           -std::numeric_limits<double>::infinity()};
  void add(const SurfaceFrame& f) {
    for (const auto& v : f.vertices_m)
      for (int a = 0; a < 3; ++a) {
        lo[a] = std::min(lo[a], v[a]);
        hi[a] = std::max(hi[a], v[a]);
      }
  }
};

struct StrainRange {
  double lo_Pa = 0.0, hi_Pa = 0.0;
};

StrainRange strain_range(const std::vector<const SurfaceFrame*>& frames, const X3dOptions& options) {
  if (options.strain_range_Pa) {
    const auto [lo, hi] = *options.strain_range_Pa;
    if (!std::isfinite(lo) || !std::isfinite(hi) || !(lo < hi))
      throw X3dInputError("X3dOptions.strain_range_Pa must be finite with low < high");
    return {lo, hi};
  }
  StrainRange r{std::numeric_limits<double>::infinity(), -std::numeric_limits<double>::infinity()};
  for (const SurfaceFrame* f : frames)
    for (const float e : f->vertex_strain_energy_Pa) {
      r.lo_Pa = std::min(r.lo_Pa, static_cast<double>(e));
      r.hi_Pa = std::max(r.hi_Pa, static_cast<double>(e));
    }
  if (r.hi_Pa - r.lo_Pa < kStrainRangeFloor_Pa) r.hi_Pa = r.lo_Pa;  // rounding: a constant field
  return r;
}

std::array<float, 3> vertex_colour(const SurfaceFrame& f, std::size_t i, const X3dOptions& options,
                                   const StrainRange& range) {
  if (options.colour == ColourMode::kLevel) return level_colour(f.vertex_level.empty() ? 0 : f.vertex_level[i]);
  const double span = range.hi_Pa - range.lo_Pa;
  // A constant field has no range: draw it at the low end of the ramp.
  const double t = span > 0.0 ? (static_cast<double>(f.vertex_strain_energy_Pa[i]) - range.lo_Pa) / span : 0.0;
  return strain_colour(t);
}

void header(std::string& x, const X3dOptions& options, const StrainRange& range, bool event_utilities,
            const std::string& what) {
  x += "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n";
  x += "<!DOCTYPE X3D PUBLIC \"ISO//Web3D//DTD X3D 3.3//EN\" \"http://www.web3d.org/specifications/x3d-3.3.dtd\">\n";
  x += "<X3D profile='Interchange' version='3.3' xmlns:xsd='http://www.w3.org/2001/XMLSchema-instance' "
       "xsd:noNamespaceSchemaLocation='http://www.web3d.org/specifications/x3d-3.3.xsd'>\n";
  x += "  <head>\n";
  // IntegerSequencer is not in the Interchange profile; the component
  // statement adds exactly it, so plain viewers still accept the profile.
  if (event_utilities) x += "    <component name='EventUtilities' level='1'/>\n";
  x += "    <meta name='title' content='" + util::escape_xml(options.title) + "'/>\n";
  x += "    <meta name='generator' content='tissued tissue_export (docs/x3d-export.md)'/>\n";
  x += "    <meta name='description' content='" + util::escape_xml(what) + "'/>\n";
  if (options.colour == ColourMode::kLevel) {
    x += "    <meta name='tissue.colour' content='bisection level per vertex, palette of ";
    put(x, std::uint64_t{kLevelPaletteSize});
    x += " colours (level modulo ";
    put(x, std::uint64_t{kLevelPaletteSize});
    x += ")'/>\n";
  } else {
    x += "    <meta name='tissue.colour' content='strain energy density per vertex, viridis ramp, Pa'/>\n";
    x += "    <meta name='tissue.strain_energy_min_Pa' content='";
    put(x, range.lo_Pa);
    x += "'/>\n    <meta name='tissue.strain_energy_max_Pa' content='";
    put(x, range.hi_Pa);
    x += "'/>\n";
  }
  x += "  </head>\n  <Scene>\n";
}

// Navigation scaled to the object: X3D's defaults assume a human-sized
// world (near plane at 0.125 m would clip a 5 cm specimen away). `what`
// names the frame(s) for an error.
void camera(std::string& x, const Bounds& b, const X3dOptions& options, const std::string& what) {
  // Halves first, so no sum or difference overflows (lo + hi for x = 1e308
  // and 1.5e308 was inf), and the radius from the largest half span times
  // the length of the spans in its units: squared spans overflowed above
  // ~1.3e154 m and underflowed below ~1e-154 m.
  std::array<double, 3> centre{}, half_span{};
  for (int a = 0; a < 3; ++a) {
    centre[a] = b.lo[a] / 2 + b.hi[a] / 2;
    half_span[a] = b.hi[a] / 2 - b.lo[a] / 2;
  }
  const double largest = std::max({half_span[0], half_span[1], half_span[2]});
  double radius_m = 0.01;  // all vertices coincide: any small sphere
  if (largest > 0.0) {
    double unit = 0.0;
    for (int a = 0; a < 3; ++a) unit += (half_span[a] / largest) * (half_span[a] / largest);
    radius_m = largest * std::sqrt(unit);
  }
  const double distance_m = 1.1 * radius_m / std::sin(0.5 * kFieldOfView_rad);
  // A viewpoint must be a finite SFVec3f: coordinates near the double's limit
  // leave no room for one outside the object.
  if (!std::isfinite(radius_m) || !std::isfinite(centre[2] + distance_m))
    throw X3dInputError(what + ": no viewpoint outside the surface is a finite position (its bounds reach " +
                        short_number(std::max({-b.lo[0], -b.lo[1], -b.lo[2], b.hi[0], b.hi[1], b.hi[2]})) +
                        " m from the origin)");
  x += "    <WorldInfo title='" + util::escape_xml(options.title) + "' info='" +
       mf_string_item("units: metres; exported by tissued") + "'/>\n";
  x += "    <NavigationInfo type='\"EXAMINE\" \"ANY\"' avatarSize='";
  put(x, 0.01 * radius_m);
  x += ' ';
  put(x, 0.05 * radius_m);
  x += ' ';
  put(x, 0.02 * radius_m);
  x += "' speed='";
  put(x, radius_m);
  x += "'/>\n    <Viewpoint description='" + util::escape_xml(options.title) + "' position='";
  put(x, centre[0]);
  x += ' ';
  put(x, centre[1]);
  x += ' ';
  put(x, centre[2] + distance_m);
  x += "' centerOfRotation='";
  put(x, centre[0]);
  x += ' ';
  put(x, centre[1]);
  x += ' ';
  put(x, centre[2]);
  x += "' fieldOfView='";
  put(x, kFieldOfView_rad);
  x += "'/>\n";
}

void points(std::string& x, const SurfaceFrame& f) {
  bool first = true;
  for (const auto& v : f.vertices_m) {
    if (!first) x += ' ';
    first = false;
    put(x, v[0]);
    x += ' ';
    put(x, v[1]);
    x += ' ';
    put(x, v[2]);
  }
}

// One Shape drawing `f`; its Coordinate is DEF'd as `coord_def` so an
// interpolator can drive it.
void shape(std::string& x, const SurfaceFrame& f, const X3dOptions& options, const StrainRange& range,
           const std::string& coord_def, const std::string& indent) {
  x += indent + "<Shape>\n";
  x += indent + "  <Appearance><Material/></Appearance>\n";
  // solid: triangles are CCW seen from outside, so back faces can be culled.
  x += indent + "  <IndexedTriangleSet solid='true' ccw='true' colorPerVertex='true' normalPerVertex='true' index='";
  bool first = true;
  for (const auto& t : f.triangles) {
    if (!first) x += ' ';
    first = false;
    put(x, std::uint64_t{t[0]});
    x += ' ';
    put(x, std::uint64_t{t[1]});
    x += ' ';
    put(x, std::uint64_t{t[2]});
  }
  x += "'>\n";
  x += indent + "    <Coordinate DEF='" + coord_def + "' point='";
  points(x, f);
  x += "'/>\n";
  x += indent + "    <Color color='";
  for (std::size_t i = 0; i < f.vertices_m.size(); ++i) {
    if (i > 0) x += ' ';
    const auto c = vertex_colour(f, i, options, range);
    put_colour(x, c[0]);
    x += ' ';
    put_colour(x, c[1]);
    x += ' ';
    put_colour(x, c[2]);
  }
  if (options.colour == ColourMode::kStrain) {
    // The ramp's range travels with the colours, for tools that read metadata.
    x += "'>\n" + indent + "      <MetadataDouble name='strain_energy_range_Pa' value='";
    put(x, range.lo_Pa);
    x += ' ';
    put(x, range.hi_Pa);
    x += "'/>\n" + indent + "    </Color>\n";
  } else {
    x += "'/>\n";
  }
  x += indent + "  </IndexedTriangleSet>\n";
  x += indent + "</Shape>\n";
}

void footer(std::string& x) { x += "  </Scene>\n</X3D>\n"; }

// Bounds-checked: animation_runs is public and may see unvalidated frames.
std::uint8_t level_at(const SurfaceFrame& f, std::size_t i) {
  return i < f.vertex_level.size() ? f.vertex_level[i] : 0;
}

bool same_levels(const SurfaceFrame& a, const SurfaceFrame& b) {
  const std::size_t n = std::max(a.vertices_m.size(), b.vertices_m.size());
  for (std::size_t i = 0; i < n; ++i)
    if (level_at(a, i) != level_at(b, i)) return false;
  return true;
}

std::string frame_label(std::size_t k) { return "frame " + std::to_string(k); }

}  // namespace

std::array<float, 3> level_colour(std::uint8_t level) { return kLevelPalette[level % kLevelPaletteSize]; }

std::array<float, 3> strain_colour(double t) {
  if (!(t > 0.0)) return kViridis.front();  // also NaN
  if (t >= 1.0) return kViridis.back();
  const double pos = t * static_cast<double>(kViridis.size() - 1);
  const std::size_t i = static_cast<std::size_t>(pos);
  const float w = static_cast<float>(pos - static_cast<double>(i));
  std::array<float, 3> c{};
  for (int a = 0; a < 3; ++a) c[a] = kViridis[i][a] + w * (kViridis[i + 1][a] - kViridis[i][a]);
  return c;
}

std::vector<float> vertex_strain_from_triangles(std::size_t vertex_count,
                                                const std::vector<std::array<std::uint32_t, 3>>& triangles,
                                                const std::vector<float>& triangle_strain) {
  if (triangle_strain.empty()) return {};
  if (triangle_strain.size() != triangles.size())
    throw X3dInputError("strain: " + std::to_string(triangle_strain.size()) + " per-triangle values for " +
                        std::to_string(triangles.size()) + " triangles");
  std::vector<double> sum(vertex_count, 0.0);
  std::vector<std::uint32_t> uses(vertex_count, 0);
  for (std::size_t t = 0; t < triangles.size(); ++t)
    for (const std::uint32_t v : triangles[t]) {
      if (v >= vertex_count)
        throw X3dInputError("strain: triangle " + std::to_string(t) + " uses vertex " + std::to_string(v) + " of " +
                            std::to_string(vertex_count));
      sum[v] += triangle_strain[t];
      ++uses[v];
    }
  std::vector<float> out(vertex_count, 0.0f);
  for (std::size_t v = 0; v < vertex_count; ++v)
    if (uses[v] > 0) out[v] = static_cast<float>(sum[v] / uses[v]);
  return out;
}

void validate_frame(const SurfaceFrame& f, bool need_strain, const std::string& label) {
  const std::string where = label + describe_time(f);
  if (!std::isfinite(f.time_s)) throw X3dInputError(label + ": time_s is not finite");
  const std::size_t n = f.vertices_m.size();
  if (n == 0) throw X3dInputError(where + ": vertices_m is empty: nothing to draw");
  if (f.triangles.empty()) throw X3dInputError(where + ": triangles is empty: nothing to draw");
  if (n > std::numeric_limits<std::uint32_t>::max())
    throw X3dInputError(where + ": " + std::to_string(n) + " vertices exceed 32-bit indices");
  for (std::size_t i = 0; i < n; ++i)
    for (int a = 0; a < 3; ++a)
      if (!std::isfinite(f.vertices_m[i][a]))
        throw X3dInputError(where + ": vertices_m[" + std::to_string(i) + "][" + std::to_string(a) + "] is not finite");
  for (std::size_t t = 0; t < f.triangles.size(); ++t) {
    const auto& tri = f.triangles[t];
    for (int c = 0; c < 3; ++c)
      if (tri[c] >= n)
        throw X3dInputError(where + ": triangles[" + std::to_string(t) + "][" + std::to_string(c) +
                            "] = " + std::to_string(tri[c]) + " is out of range (the frame has " + std::to_string(n) +
                            " vertices)");
    if (tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2])
      throw X3dInputError(where + ": triangles[" + std::to_string(t) + "] repeats a vertex (" + std::to_string(tri[0]) +
                          " " + std::to_string(tri[1]) + " " + std::to_string(tri[2]) + "): degenerate");
  }
  if (!f.vertex_level.empty() && f.vertex_level.size() != n)
    throw X3dInputError(where + ": vertex_level has " + std::to_string(f.vertex_level.size()) + " values for " +
                        std::to_string(n) + " vertices (must be empty or one per vertex)");
  const std::vector<float>& ts = f.triangle_strain_energy_J_per_m3;
  if (!ts.empty() && ts.size() != f.triangles.size())
    throw X3dInputError(where + ": triangle_strain_energy_J_per_m3 has " + std::to_string(ts.size()) + " values for " +
                        std::to_string(f.triangles.size()) + " triangles (must be empty or one per triangle)");
  for (std::size_t t = 0; t < ts.size(); ++t)
    if (!std::isfinite(ts[t]) || ts[t] < 0.0f)
      throw X3dInputError(where + ": triangle_strain_energy_J_per_m3[" + std::to_string(t) +
                          "] = " + std::to_string(ts[t]) + " is not a strain energy density (must be finite and >= 0)");
  if (need_strain) {
    if (f.vertex_strain_energy_Pa.size() != n)
      throw X3dInputError(where + ": strain colouring needs one vertex_strain_energy_Pa value per vertex, got " +
                          std::to_string(f.vertex_strain_energy_Pa.size()) + " for " + std::to_string(n) + " vertices");
    for (std::size_t i = 0; i < n; ++i)
      if (!std::isfinite(f.vertex_strain_energy_Pa[i]))
        throw X3dInputError(where + ": vertex_strain_energy_Pa[" + std::to_string(i) + "] is not finite");
  }
}

std::string x3d_snapshot(const SurfaceFrame& frame, const X3dOptions& options) {
  const bool strain = options.colour == ColourMode::kStrain;
  validate_frame(frame, strain, "frame");
  const StrainRange range = strain ? strain_range({&frame}, options) : StrainRange{};
  Bounds b;
  b.add(frame);
  std::string x;
  // ~60 bytes per vertex (point + colour) and ~25 per triangle.
  x.reserve(2048 + 64 * frame.vertices_m.size() + 32 * frame.triangles.size());
  std::string what = "tissue surface at session time ";
  put(what, frame.time_s);
  what += " s: " + std::to_string(frame.vertices_m.size()) + " vertices, " + std::to_string(frame.triangles.size()) +
          " triangles";
  header(x, options, range, false, what);
  camera(x, b, options, "frame" + describe_time(frame));
  shape(x, frame, options, range, "SurfaceCoordinates", "    ");
  footer(x);
  return x;
}

std::vector<FrameRun> animation_runs(const std::vector<SurfaceFrame>& frames, const X3dOptions& options) {
  std::vector<FrameRun> runs;
  for (std::size_t k = 0; k < frames.size(); ++k) {
    if (!runs.empty() && options.colour == ColourMode::kLevel) {
      const SurfaceFrame& a = frames[runs.back().first];
      const SurfaceFrame& b = frames[k];
      // Same vertex count and triangles is what an interpolator needs; same
      // levels because colours cannot be interpolated per vertex in X3D.
      if (a.vertices_m.size() == b.vertices_m.size() && a.triangles == b.triangles && same_levels(a, b)) {
        runs.back().end = k + 1;
        continue;
      }
    }
    runs.push_back({k, k + 1});
  }
  return runs;
}

std::string x3d_animation(const std::vector<SurfaceFrame>& frames, const X3dOptions& options) {
  const bool strain = options.colour == ColourMode::kStrain;
  if (frames.size() < 2)
    throw X3dInputError("an animation needs at least 2 frames, got " + std::to_string(frames.size()));
  std::vector<const SurfaceFrame*> all;
  Bounds b;
  for (std::size_t k = 0; k < frames.size(); ++k) {
    validate_frame(frames[k], strain, frame_label(k));
    if (k > 0 && frames[k].time_s < frames[k - 1].time_s) {
      std::string now = describe_time(frames[k]), before = describe_time(frames[k - 1]);
      // Times that differ only past 9 digits would read the same: in full.
      if (now == before) {
        now = " (t=", before = " (t=";
        put(now, frames[k].time_s), put(before, frames[k - 1].time_s);
        now += " s)", before += " s)";
      }
      throw X3dInputError(frame_label(k) + now + ": time_s goes backwards (" + frame_label(k - 1) + before +
                          "); frames must be in time order");
    }
    all.push_back(&frames[k]);
    b.add(frames[k]);
  }
  const double t0_s = frames.front().time_s;
  const double window_s = frames.back().time_s - t0_s;
  const std::string all_frames = "frames 0 to " + std::to_string(frames.size() - 1);
  // Each time is finite, the difference need not be (-1e308 to 1e308).
  if (!std::isfinite(window_s))
    throw X3dInputError(all_frames + " span more time than a number holds (t=" + frame_time_text(t0_s) + " s to " +
                        frame_time_text(frames.back().time_s) + " s)");
  if (!(window_s > 0.0))
    throw X3dInputError("frames span no time (first and last at t=" + frame_time_text(t0_s) +
                        " s): an animation needs a window longer than 0 s");
  const auto fraction = [&](const SurfaceFrame& f) { return std::clamp((f.time_s - t0_s) / window_s, 0.0, 1.0); };

  const StrainRange range = strain ? strain_range(all, options) : StrainRange{};
  const std::vector<FrameRun> runs = animation_runs(frames, options);
  std::size_t values = 0;
  for (const SurfaceFrame& f : frames) values += f.vertices_m.size();

  std::string x;
  x.reserve(4096 + 64 * values + 32 * frames.front().triangles.size() * runs.size());
  std::string what = "tissue surface animation, session time ";
  put(what, t0_s);
  what += " to ";
  put(what, frames.back().time_s);
  what += " s: " + std::to_string(frames.size()) + " frames in " + std::to_string(runs.size()) +
          " topology runs, looping every ";
  put(what, window_s);
  what += " s";
  header(x, options, range, runs.size() > 1, what);
  camera(x, b, options, all_frames);
  x += "    <TimeSensor DEF='Clock' cycleInterval='";
  put(x, window_s);
  x += "' loop='true'/>\n";
  x += "    <Switch DEF='Runs' whichChoice='0'>\n";
  for (std::size_t r = 0; r < runs.size(); ++r)
    shape(x, frames[runs[r].first], options, range, "Coords" + std::to_string(r), "      ");
  x += "    </Switch>\n";

  std::string routes;
  for (std::size_t r = 0; r < runs.size(); ++r) {
    if (runs[r].end - runs[r].first < 2) continue;  // a single frame stays put
    const std::string interp = "Move" + std::to_string(r);
    x += "    <CoordinateInterpolator DEF='" + interp + "' key='";
    for (std::size_t k = runs[r].first; k < runs[r].end; ++k) {
      if (k > runs[r].first) x += ' ';
      put(x, fraction(frames[k]));
    }
    x += "' keyValue='";
    for (std::size_t k = runs[r].first; k < runs[r].end; ++k) {
      if (k > runs[r].first) x += ' ';
      points(x, frames[k]);
    }
    x += "'/>\n";
    routes +=
        "    <ROUTE fromNode='Clock' fromField='fraction_changed' toNode='" + interp + "' toField='set_fraction'/>\n";
    routes += "    <ROUTE fromNode='" + interp + "' fromField='value_changed' toNode='Coords" + std::to_string(r) +
              "' toField='point'/>\n";
  }
  if (runs.size() > 1) {
    // A step function of the cycle fraction: run r is shown from its first
    // frame's time until the next run starts.
    x += "    <IntegerSequencer DEF='Show' key='";
    for (std::size_t r = 0; r < runs.size(); ++r) {
      if (r > 0) x += ' ';
      put(x, fraction(frames[runs[r].first]));
    }
    x += "' keyValue='";
    for (std::size_t r = 0; r < runs.size(); ++r) {
      if (r > 0) x += ' ';
      put(x, std::uint64_t{r});
    }
    x += "'/>\n";
    routes += "    <ROUTE fromNode='Clock' fromField='fraction_changed' toNode='Show' toField='set_fraction'/>\n";
    routes += "    <ROUTE fromNode='Show' fromField='value_changed' toNode='Runs' toField='whichChoice'/>\n";
  }
  x += routes;
  footer(x);
  return x;
}

}  // namespace tissue::x3d
