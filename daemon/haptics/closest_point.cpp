#include "haptics/closest_point.hpp"

#include <algorithm>
#include <utility>

namespace tissue::haptics {
namespace {

using Vec3 = Eigen::Vector3d;

// Closest point to p on the segment from corner i to corner j.
TriangleClosest closest_on_edge(const Vec3& p, const Vec3* corner[3], int i, int j) {
  const Vec3 e = *corner[j] - *corner[i];
  const double length2 = e.squaredNorm();
  // A zero-length edge (two corners at one point) is that point.
  const double t = length2 > 0.0 ? std::clamp((p - *corner[i]).dot(e) / length2, 0.0, 1.0) : 0.0;
  TriangleClosest out{*corner[i] + t * e, {0.0, 0.0, 0.0}, i, j};
  out.weight[i] = 1.0 - t;
  out.weight[j] = t;
  if (t == 0.0) out.feature_b = -1;  // corner i
  if (t == 1.0) out = {*corner[j], out.weight, j, -1};
  return out;
}

// A triangle with no area (two corners at one point, or all three on a
// line) is its three edges: the closest of their closest points. The
// Voronoi formulas below divide by squared edge lengths and the squared
// area, which are zero there (0/0 gave NaN points and weights).
TriangleClosest closest_on_degenerate(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3* corner[3] = {&a, &b, &c};
  TriangleClosest best = closest_on_edge(p, corner, 0, 1);
  for (const auto& [i, j] : {std::pair{0, 2}, std::pair{1, 2}}) {
    const TriangleClosest e = closest_on_edge(p, corner, i, j);
    if ((e.point_m - p).squaredNorm() < (best.point_m - p).squaredNorm()) best = e;
  }
  return best;
}

}  // namespace

TriangleClosest closest_point_on_triangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0.0 && d2 <= 0.0) return {a, {1, 0, 0}, 0, -1};
  const Vec3 bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0.0 && d4 <= d3) return {b, {0, 1, 0}, 1, -1};
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) {
    const double length2 = d1 - d3;  // |ab|^2
    if (!(length2 > 0.0)) return closest_on_degenerate(p, a, b, c);
    const double v = d1 / length2;
    return {a + v * ab, {1 - v, v, 0}, 0, 1};
  }
  const Vec3 cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0.0 && d5 <= d6) return {c, {0, 0, 1}, 2, -1};
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) {
    const double length2 = d2 - d6;  // |ac|^2
    if (!(length2 > 0.0)) return closest_on_degenerate(p, a, b, c);
    const double w = d2 / length2;
    return {a + w * ac, {1 - w, 0, w}, 0, 2};
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0) {
    const double length2 = (d4 - d3) + (d5 - d6);  // |bc|^2
    if (!(length2 > 0.0)) return closest_on_degenerate(p, a, b, c);
    const double w = (d4 - d3) / length2;
    return {b + w * (c - b), {0, 1 - w, w}, 1, 2};
  }
  // Inside the face: va, vb, vc > 0 and their sum is |ab x ac|^2. On a
  // triangle with (next to) no area rounding can leave one negative or the
  // sum zero, which would put the weights outside [0, 1] or make them NaN.
  const double area2 = va + vb + vc;
  if (!(area2 > 0.0) || va < 0.0 || vb < 0.0 || vc < 0.0) return closest_on_degenerate(p, a, b, c);
  const double v = vb / area2, w = vc / area2;
  return {a + v * ab + w * ac, {1 - v - w, v, w}, -1, -1};
}

}  // namespace tissue::haptics
