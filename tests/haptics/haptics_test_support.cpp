#include "haptics/haptics_test_support.hpp"

namespace tissue::haptics::test {
namespace {

// LocalModel's std::array<Vec3, N> members are NOT zeroed by their `{}`
// initialisers (Eigen's default constructor leaves coefficients
// uninitialised), so every builder clears the arrays explicitly.
LocalModel blank_model() {
  LocalModel m;
  m.vertex_m.fill(Vec3::Zero());
  m.vertex_velocity_m_per_s.fill(Vec3::Zero());
  return m;
}

}  // namespace

LocalModel make_grid_patch(double half_size_m, int cells, const Vec3& centre_m, const Vec3& u, const Vec3& v) {
  LocalModel m = blank_model();
  m.version = 1;
  const int n = cells + 1;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const double a = -half_size_m + 2.0 * half_size_m * i / cells;
      const double b = -half_size_m + 2.0 * half_size_m * j / cells;
      const int k = j * n + i;
      m.vertex_m[k] = centre_m + a * u + b * v;
      m.vertex_node[k] = 1000 + static_cast<std::uint32_t>(k);
    }
  m.vertex_count = n * n;
  int t = 0;
  for (int j = 0; j < cells; ++j)
    for (int i = 0; i < cells; ++i) {
      const int v00 = j * n + i, v10 = v00 + 1, v01 = v00 + n, v11 = v01 + 1;
      m.triangle[t++] = {v00, v10, v11};  // counter-clockwise seen from u x v
      m.triangle[t++] = {v00, v11, v01};
    }
  m.triangle_count = t;
  return m;
}

LocalModel make_flat_patch(double half_size_m, int cells) { return make_grid_patch(half_size_m, cells); }

LocalModel make_slab(double half_size_m, double thickness_m, int cells) {
  LocalModel top = make_grid_patch(half_size_m, cells, Vec3(0, 0, thickness_m / 2));
  // Bottom: swap u and v so it faces -z.
  const LocalModel bottom =
      make_grid_patch(half_size_m, cells, Vec3(0, 0, -thickness_m / 2), Vec3::UnitY(), Vec3::UnitX());
  const int offset = top.vertex_count;
  for (int i = 0; i < bottom.vertex_count; ++i) {
    top.vertex_m[offset + i] = bottom.vertex_m[i];
    top.vertex_node[offset + i] = 5000 + i;
  }
  for (int t = 0; t < bottom.triangle_count; ++t)
    top.triangle[top.triangle_count + t] = {bottom.triangle[t][0] + offset, bottom.triangle[t][1] + offset,
                                            bottom.triangle[t][2] + offset};
  top.vertex_count += bottom.vertex_count;
  top.triangle_count += bottom.triangle_count;
  return top;
}

LocalModel make_ridge(double half_size_m, double slope) {
  // Vertices: ridge line (x=0) at y = -h, +h; left and right feet.
  LocalModel m = blank_model();
  m.version = 1;
  const double h = half_size_m;
  m.vertex_m[0] = Vec3(0, -h, 0);
  m.vertex_m[1] = Vec3(0, h, 0);
  m.vertex_m[2] = Vec3(-h, -h, -slope * h);
  m.vertex_m[3] = Vec3(-h, h, -slope * h);
  m.vertex_m[4] = Vec3(h, -h, -slope * h);
  m.vertex_m[5] = Vec3(h, h, -slope * h);
  m.vertex_count = 6;
  for (int i = 0; i < 6; ++i) m.vertex_node[i] = 100 + i;
  // Left face (x < 0): ridge edge 0-1, foot 2-3; right face: 0-1 and 4-5; both facing up.
  m.triangle[0] = {2, 0, 1};
  m.triangle[1] = {2, 1, 3};
  m.triangle[2] = {0, 4, 5};
  m.triangle[3] = {0, 5, 1};
  m.triangle_count = 4;
  return m;
}

void set_linear_contact(LocalModel& m, double stiffness_N_per_m, const Vec3& force_ref_N, const Vec3& position_ref_m) {
  m.in_contact = true;
  m.contact_stiffness_N_per_m = stiffness_N_per_m * Mat3::Identity();
  m.force_ref_N = force_ref_N;
  m.position_ref_m = position_ref_m;
}

}  // namespace tissue::haptics::test
