#include "render/render.hpp"

#include <GL/gl.h>
#include <GL/osmesa.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>

namespace tissue::render {

namespace {

using V3 = std::array<double, 3>;

V3 sub(const V3& a, const V3& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
V3 cross(const V3& a, const V3& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
double dot(const V3& a, const V3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
V3 normalized(const V3& a) {
  const double n = std::sqrt(dot(a, a));
  return n > 0.0 ? V3{a[0] / n, a[1] / n, a[2] / n} : V3{0, 0, 1};
}

struct ContextDeleter {
  void operator()(osmesa_context* c) const { OSMesaDestroyContext(c); }
};

// 3x5 digits for the legend: one row of 3 bits per line, top first.
constexpr std::array<std::array<std::uint8_t, 5>, 10> kDigits = {{{7, 5, 5, 5, 7},
                                                                  {2, 6, 2, 2, 7},
                                                                  {7, 1, 7, 4, 7},
                                                                  {7, 1, 7, 1, 7},
                                                                  {5, 5, 7, 1, 1},
                                                                  {7, 4, 7, 1, 7},
                                                                  {7, 4, 7, 5, 7},
                                                                  {7, 1, 1, 1, 1},
                                                                  {7, 5, 7, 5, 7},
                                                                  {7, 5, 7, 1, 7}}};

void fill_rect(Image& img, int x0, int y0, int w, int h, const std::array<std::uint8_t, 3>& c) {
  for (int y = std::max(0, y0); y < std::min(img.height, y0 + h); ++y)
    for (int x = std::max(0, x0); x < std::min(img.width, x0 + w); ++x) {
      std::uint8_t* p = &img.rgba[4 * (static_cast<std::size_t>(y) * img.width + x)];
      p[0] = c[0], p[1] = c[1], p[2] = c[2], p[3] = 255;
    }
}

void draw_number(Image& img, int x, int y, int value, int scale) {
  const std::string text = std::to_string(value);
  for (char ch : text) {
    const auto& glyph = kDigits[static_cast<std::size_t>(ch - '0')];
    for (int row = 0; row < 5; ++row)
      for (int col = 0; col < 3; ++col)
        if (glyph[row] & (4 >> col)) fill_rect(img, x + col * scale, y + row * scale, scale, scale, {0, 0, 0});
    x += 4 * scale;
  }
}

std::array<std::uint8_t, 3> to_bytes(const std::array<float, 3>& c, double shade) {
  std::array<std::uint8_t, 3> out{};
  for (int i = 0; i < 3; ++i) {
    // NaN through std::clamp stays NaN, and NaN to an integer is undefined:
    // full brightness is the one safe value (the callers never give NaN).
    const double v = c[i] * shade;
    out[i] = static_cast<std::uint8_t>((std::isnan(v) ? 1.0 : std::clamp(v, 0.0, 1.0)) * 255.0 + 0.5);
  }
  return out;
}

}  // namespace

std::array<double, 2> strain_range_Pa(const x3d::SurfaceFrame& frame, const RenderOptions& o) {
  if (o.strain_range_Pa) {
    const auto [lo, hi] = *o.strain_range_Pa;
    if (!std::isfinite(lo) || !std::isfinite(hi) || !(lo < hi))
      throw x3d::X3dInputError("render: the strain range must be finite with low < high");
    return {lo, hi};
  }
  if (frame.vertex_strain_energy_Pa.empty()) return {0.0, 0.0};
  const auto [lo, hi] = std::minmax_element(frame.vertex_strain_energy_Pa.begin(), frame.vertex_strain_energy_Pa.end());
  if (static_cast<double>(*hi) - static_cast<double>(*lo) < x3d::kStrainRangeFloor_Pa)  // rounding: constant
    return {static_cast<double>(*lo), static_cast<double>(*lo)};
  return {static_cast<double>(*lo), static_cast<double>(*hi)};
}

struct Renderer::Context {
  std::unique_ptr<osmesa_context, ContextDeleter> gl;
  // Flat-shaded triangles as client vertex arrays: three vertices and three
  // copies of the triangle's colour each (one glDrawArrays instead of a GL
  // call per vertex). Kept between frames.
  std::vector<float> positions;
  std::vector<std::uint8_t> colours;
};

Renderer::Renderer() : context_(std::make_unique<Context>()) {}
Renderer::~Renderer() = default;
Renderer::Renderer(Renderer&&) noexcept = default;
Renderer& Renderer::operator=(Renderer&&) noexcept = default;

Box_m empty_box_m() {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  return Box_m{{{kInf, kInf, kInf}, {-kInf, -kInf, -kInf}}};
}

void extend_box_m(Box_m& box, const x3d::SurfaceFrame& frame) {
  for (const auto& v : frame.vertices_m)
    for (int a = 0; a < 3; ++a) box[0][a] = std::min(box[0][a], v[a]), box[1][a] = std::max(box[1][a], v[a]);
}

Image render_frame(const x3d::SurfaceFrame& frame, const RenderOptions& options) {
  Renderer renderer;
  return renderer.render(frame, options);
}

Image Renderer::render(const x3d::SurfaceFrame& frame, const RenderOptions& o) {
  const bool strain = o.colour == x3d::ColourMode::kStrain;
  x3d::validate_frame(frame, strain, "frame");
  const std::array<double, 2> range = strain ? strain_range_Pa(frame, o) : std::array<double, 2>{0.0, 0.0};
  const double span = range[1] - range[0];
  if (o.width_px < 16 || o.height_px < 16 || o.width_px > 8192 || o.height_px > 8192)
    throw RenderError("render: image size must be 16..8192 pixels a side (got " + std::to_string(o.width_px) + "x" +
                      std::to_string(o.height_px) + ")");
  if (!std::isfinite(o.azimuth_deg) || !std::isfinite(o.elevation_deg))
    throw RenderError("render: camera angles must be finite");

  Image img;
  img.width = o.width_px;
  img.height = o.height_px;
  img.rgba.assign(4 * static_cast<std::size_t>(img.width) * img.height, 0);
  // One context for all frames: creating it (and llvmpipe's threads) costs
  // more than drawing a small surface.
  if (!context_->gl) context_->gl.reset(OSMesaCreateContextExt(OSMESA_RGBA, 24, 0, 0, nullptr));
  if (!context_->gl) throw RenderError("render: OSMesa could not create a context");
  if (!OSMesaMakeCurrent(context_->gl.get(), img.rgba.data(), GL_UNSIGNED_BYTE, img.width, img.height))
    throw RenderError("render: OSMesa could not bind the image buffer");
  OSMesaPixelStore(OSMESA_Y_UP, 0);  // row 0 at the top, as PNG wants

  // Orthographic camera fitting the bounding sphere.
  Box_m box = empty_box_m();
  if (o.frame_box_m) {
    box = *o.frame_box_m;
    for (int a = 0; a < 3; ++a)
      if (!std::isfinite(box[0][a]) || !std::isfinite(box[1][a]) || box[0][a] > box[1][a])
        throw RenderError("render: the camera's box must be finite with lo <= hi on every axis");
  } else {
    extend_box_m(box, frame);
  }
  const V3& lo = box[0];
  const V3& hi = box[1];
  // The picture is drawn in units of the bounding radius about the centre:
  // GL's float pipeline then sees coordinates of order 1 whatever the
  // object's size and place (a surface at ±3e38 m overflowed the projection
  // to a blank picture; one a nanometre across was a dot). Halves first, so
  // no sum or difference overflows.
  const V3 centre{lo[0] / 2 + hi[0] / 2, lo[1] / 2 + hi[1] / 2, lo[2] / 2 + hi[2] / 2};
  const V3 half_span{hi[0] / 2 - lo[0] / 2, hi[1] / 2 - lo[1] / 2, hi[2] / 2 - lo[2] / 2};
  const double largest = std::max({half_span[0], half_span[1], half_span[2]});
  // The bounding radius is largest_m · unit_radius (unit_radius in [1, √3]);
  // not multiplied out, which overflows when every axis spans more than
  // ~1.04e308. All vertices at one point: any scale draws it.
  const double largest_m = largest > 0.0 ? largest : 1.0;
  const V3 unit_span{half_span[0] / largest_m, half_span[1] / largest_m, half_span[2] / largest_m};
  const double unit_radius = largest > 0.0 ? std::sqrt(dot(unit_span, unit_span)) : 1.0;
  // A vertex relative to the centre, in bounding radii: within ±1, and floats
  // keep the detail of an object of any size wherever it sits. (p - centre
  // cannot overflow: it is at most the half span, and the halves are exact.)
  const auto in_radii = [&](const V3& p) {
    V3 r;
    for (int k = 0; k < 3; ++k) r[k] = (p[k] - centre[k]) / largest_m / unit_radius;
    return r;
  };
  const double radius = 1.0;  // of the drawing
  // Whole turns taken off first (exactly: fmod is exact): an angle past
  // ~1.03e306 degrees overflowed to inf in radians, and its NaN cosine made
  // a blank picture with no error.
  const auto radians = [](double degrees) { return std::fmod(degrees, 360.0) * M_PI / 180.0; };
  const double az = radians(o.azimuth_deg), el = radians(o.elevation_deg);
  const V3 eye_dir{std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), std::sin(el)};  // towards the camera
  // Right is horizontal and follows the azimuth at every elevation, up to
  // straight down or up: an up hint switched near the poles turned the
  // picture by ~60° between 81° and 82° and froze the azimuth above.
  const V3 right{-std::sin(az), std::cos(az), 0.0};
  const V3 up = cross(eye_dir, right);

  glViewport(0, 0, img.width, img.height);
  glClearColor(o.background[0] / 255.0f, o.background[1] / 255.0f, o.background[2] / 255.0f, 1.0f);
  glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
  glEnable(GL_DEPTH_TEST);
  glMatrixMode(GL_PROJECTION);
  glLoadIdentity();
  const double aspect = static_cast<double>(img.width) / img.height;
  const double half_h = 1.05 * radius * std::max(1.0, 1.0 / aspect), half_w = half_h * aspect;
  glOrtho(-half_w, half_w, -half_h, half_h, 0.0, 4.0 * radius);
  glMatrixMode(GL_MODELVIEW);
  // View matrix: rows right/up/eye_dir, eye at 2 r eye_dir from the centre.
  const V3 eye{2 * radius * eye_dir[0], 2 * radius * eye_dir[1], 2 * radius * eye_dir[2]};
  const GLdouble view[16] = {right[0], up[0], eye_dir[0], 0, right[1],         up[1],         eye_dir[1],         0,
                             right[2], up[2], eye_dir[2], 0, -dot(right, eye), -dot(up, eye), -dot(eye_dir, eye), 1};
  glLoadMatrixd(view);

  std::vector<bool> level_seen(256, false);
  std::vector<float>& positions = context_->positions;
  std::vector<std::uint8_t>& colours = context_->colours;
  positions.clear();
  colours.clear();
  positions.reserve(9 * frame.triangles.size());
  colours.reserve(9 * frame.triangles.size());
  for (const auto& t : frame.triangles) {
    const V3& a = frame.vertices_m[t[0]];
    const V3& b = frame.vertices_m[t[1]];
    const V3& c = frame.vertices_m[t[2]];
    int level = 0;
    if (!frame.vertex_level.empty())
      for (std::uint32_t v : t) level = std::max<int>(level, frame.vertex_level[v]);
    level_seen[static_cast<std::size_t>(level)] = true;
    std::array<float, 3> base = x3d::level_colour(static_cast<std::uint8_t>(level));
    if (strain) {
      double mean = 0.0;
      for (std::uint32_t v : t) mean += frame.vertex_strain_energy_Pa[v] / 3.0;
      // A constant field has no range: the low end of the ramp, as in X3D.
      base = x3d::strain_colour(span > 0.0 ? (mean - range[0]) / span : 0.0);
    }
    const std::array<V3, 3> drawn{in_radii(a), in_radii(b), in_radii(c)};
    // A head light: faces turned to the camera are bright, grazing ones dim.
    // The normal from the drawn positions (within ±1): from metres, an edge
    // of 2e308 m overflowed to inf and the facing was NaN.
    const double facing = std::abs(dot(normalized(cross(sub(drawn[1], drawn[0]), sub(drawn[2], drawn[0]))), eye_dir));
    const auto colour = to_bytes(base, 0.35 + 0.65 * facing);
    for (const V3& p : drawn) {
      for (int k = 0; k < 3; ++k) positions.push_back(static_cast<float>(p[k]));
      colours.insert(colours.end(), colour.begin(), colour.end());
    }
  }
  glEnableClientState(GL_VERTEX_ARRAY);
  glEnableClientState(GL_COLOR_ARRAY);
  glVertexPointer(3, GL_FLOAT, 0, positions.data());
  glColorPointer(3, GL_UNSIGNED_BYTE, 0, colours.data());
  glDrawArrays(GL_TRIANGLES, 0, static_cast<GLsizei>(positions.size() / 3));
  glDisableClientState(GL_COLOR_ARRAY);
  glDisableClientState(GL_VERTEX_ARRAY);
  glFinish();

  if (o.legend && strain) {  // the ramp, low at the bottom (its ends are in the caller's caption)
    const int scale = std::max(2, img.height / 200), w = 6 * scale, h = std::min(img.height / 3, 60 * scale);
    const int x0 = 2 * scale, y0 = img.height - h - 2 * scale;
    for (int i = 0; i < h; ++i)
      fill_rect(img, x0, y0 + i, w, 1, to_bytes(x3d::strain_colour(1.0 - static_cast<double>(i) / (h - 1)), 1.0));
  } else if (o.legend) {  // a swatch and the level number for each level drawn
    const int scale = std::max(2, img.height / 200), box = 6 * scale;
    int y = img.height - box - 2 * scale;
    for (int level = 255; level >= 0; --level) {
      if (!level_seen[static_cast<std::size_t>(level)]) continue;
      fill_rect(img, 2 * scale, y, box, box, to_bytes(x3d::level_colour(static_cast<std::uint8_t>(level)), 1.0));
      draw_number(img, 3 * scale + box, y + scale / 2, level, scale);
      y -= box + scale;
      if (y < 0) break;
    }
  }
  return img;
}

}  // namespace tissue::render
