#include "physics/field_error.hpp"

#include <algorithm>

#include "physics/probes.hpp"

namespace tissue::physics {

namespace {

// The distances |u − u_ref| at the compared points, as RMS and maximum
// relative to a scale (NaN when nothing was compared or the scale is 0).
struct DistanceSum {
  double sum2 = 0.0, worst = 0.0;
  std::size_t count = 0;
  void add(double distance) {
    sum2 += distance * distance;
    worst = std::max(worst, distance);
    ++count;
  }
  template <class Error>
  void finish(double scale, Error& e) const {
    e.compared = count;
    if (count == 0 || !(scale > 0.0)) return;
    e.rms_rel = std::sqrt(sum2 / static_cast<double>(count)) / scale;
    e.max_rel = worst / scale;
  }
};

}  // namespace

DisplacementField capture_displacement_field(const Body& body) {
  DisplacementField f;
  std::vector<int> compact(body.x_m.size(), -1);
  body.mesh().for_each_node([&](NodeId n, const mesh::Node&) {
    compact[n] = static_cast<int>(f.rest_m.size());
    f.rest_m.push_back(body.rest_m[n]);
    f.u_m.push_back(body.x_m[n] - body.rest_m[n]);
    f.free.push_back(body.kind[n] == NodeKind::kFree ? 1 : 0);
  });
  body.mesh().for_each_tet([&](TetId, const mesh::Tet& t) {
    f.tets.push_back({compact[t.v[0]], compact[t.v[1]], compact[t.v[2]], compact[t.v[3]]});
  });
  return f;
}

FieldError compare_displacement_fields(const DisplacementField& ref, const DisplacementField& test) {
  FieldError e;
  const std::size_t n = ref.rest_m.size();
  if (n == 0) return e;
  Vec3 lo = ref.rest_m[0], hi = ref.rest_m[0];
  for (const auto& p : ref.rest_m) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  // Bins of about one reference node each.
  const Vec3 extent = hi - lo;
  const double cell = std::max(std::cbrt(std::max(extent.prod(), 1e-30) / static_cast<double>(n)), 1e-12);
  std::array<int, 3> dims{};
  for (int a = 0; a < 3; ++a) dims[a] = static_cast<int>(extent[a] / cell) + 1;
  // Clamped as a double, then converted: a tet of `test` may reach more bins
  // past the reference than an int holds (converting those is undefined).
  const auto bin_of = [&](int a, double x) {
    return static_cast<int>(std::clamp((x - lo[a]) / cell, 0.0, static_cast<double>(dims[a] - 1)));
  };
  const auto bin_index = [&](int i, int j, int k) { return (static_cast<std::size_t>(k) * dims[1] + j) * dims[0] + i; };
  std::vector<std::vector<int>> bins(static_cast<std::size_t>(dims[0]) * dims[1] * dims[2]);
  for (std::size_t i = 0; i < n; ++i)
    bins[bin_index(bin_of(0, ref.rest_m[i][0]), bin_of(1, ref.rest_m[i][1]), bin_of(2, ref.rest_m[i][2]))].push_back(
        static_cast<int>(i));

  std::vector<Vec3> interpolated(n, Vec3::Zero());
  std::vector<std::uint8_t> located(n, 0);
  // Nodes on a tet's face or edge belong to it too (rounding of the rest
  // positions must not leave them out).
  const double tol = 1e-9 * std::max(extent.maxCoeff(), 1e-12);
  for (const auto& t : test.tets) {
    const Vec3 &a = test.rest_m[t[0]], &b = test.rest_m[t[1]], &c = test.rest_m[t[2]], &d = test.rest_m[t[3]];
    const Vec3 tlo = a.cwiseMin(b).cwiseMin(c).cwiseMin(d).array() - tol;
    const Vec3 thi = a.cwiseMax(b).cwiseMax(c).cwiseMax(d).array() + tol;
    for (int k = bin_of(2, tlo[2]); k <= bin_of(2, thi[2]); ++k)
      for (int j = bin_of(1, tlo[1]); j <= bin_of(1, thi[1]); ++j)
        for (int i = bin_of(0, tlo[0]); i <= bin_of(0, thi[0]); ++i)
          for (const int r : bins[bin_index(i, j, k)]) {
            if (located[r]) continue;
            const Vec3& p = ref.rest_m[r];
            if ((p.array() < tlo.array()).any() || (p.array() > thi.array()).any()) continue;
            const auto l = barycentric(p, a, b, c, d);
            if (std::min({l[0], l[1], l[2], l[3]}) < -1e-9) continue;
            located[r] = 1;
            interpolated[r] =
                l[0] * test.u_m[t[0]] + l[1] * test.u_m[t[1]] + l[2] * test.u_m[t[2]] + l[3] * test.u_m[t[3]];
          }
  }
  for (std::size_t i = 0; i < n; ++i) e.reference_max_m = std::max(e.reference_max_m, ref.u_m[i].norm());
  DistanceSum distances;
  for (std::size_t i = 0; i < n; ++i) {
    if (!ref.free[i]) continue;
    if (located[i])
      distances.add((interpolated[i] - ref.u_m[i]).norm());
    else
      ++e.unlocated;
  }
  distances.finish(e.reference_max_m, e);
  return e;
}

TrajectoryError compare_trajectories(const std::vector<double>& ref_t, const std::vector<Vec3>& ref_u,
                                     const std::vector<double>& t, const std::vector<Vec3>& u) {
  TrajectoryError e;
  const std::size_t n_ref = std::min(ref_t.size(), ref_u.size());
  for (std::size_t k = 0; k < n_ref; ++k) e.reference_max_m = std::max(e.reference_max_m, ref_u[k].norm());
  if (n_ref == 0) return e;
  // Rounding of accumulated step times (k dt summed) must not drop the ends.
  const double slack = 1e-9 * std::max({std::abs(ref_t.front()), std::abs(ref_t[n_ref - 1]), 1e-9});
  DistanceSum distances;
  std::size_t j = 0;  // reference interval [j, j + 1] holding the sample (times increase)
  for (std::size_t k = 0; k < std::min(t.size(), u.size()); ++k) {
    if (t[k] < ref_t.front() - slack || t[k] > ref_t[n_ref - 1] + slack) continue;
    while (j + 1 < n_ref && ref_t[j + 1] < t[k]) ++j;
    Vec3 reference = ref_u[j];
    if (j + 1 < n_ref && ref_t[j + 1] > ref_t[j]) {
      const double w = std::clamp((t[k] - ref_t[j]) / (ref_t[j + 1] - ref_t[j]), 0.0, 1.0);
      reference = (1.0 - w) * ref_u[j] + w * ref_u[j + 1];
    }
    distances.add((u[k] - reference).norm());
  }
  distances.finish(e.reference_max_m, e);
  return e;
}

}  // namespace tissue::physics
