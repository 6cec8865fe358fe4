// Shared fixtures for the haptics tests: hand-built LocalModels (flat patch,
// thin slab, ridge) and a scripted device whose pose the test sets directly.
#pragma once

#include <cstdint>

#include "config/daemon_config.hpp"
#include "haptics/device.hpp"
#include "haptics/local_model.hpp"

namespace tissue::haptics::test {

inline constexpr std::int64_t kMs = 1000000;  // ns per millisecond

// A square grid patch of (cells x cells) squares, 2 triangles each, centred
// at `centre_m`, spanning [-half, half]^2 in the plane spanned by (u, v) and
// facing n = u x v (outward). vertex_node[i] = 1000 + i.
LocalModel make_grid_patch(double half_size_m, int cells, const Vec3& centre_m = Vec3::Zero(),
                           const Vec3& u = Vec3::UnitX(), const Vec3& v = Vec3::UnitY());
// Flat patch z = 0, normal +z.
LocalModel make_flat_patch(double half_size_m = 0.05, int cells = 4);
// A thin slab: top face z = +t/2 (normal +z) and bottom face z = -t/2 (normal -z).
LocalModel make_slab(double half_size_m, double thickness_m, int cells = 4);
// Two faces meeting along the line x = 0, z = 0 (along y), falling by
// `slope` (dz/dx) to either side: slope > 0 a convex ridge, slope < 0 a
// concave valley; outward normals up.
LocalModel make_ridge(double half_size_m, double slope);
// Contact linearisation on top of a patch: in contact, K_c = k I, F0, x0.
void set_linear_contact(LocalModel& m, double stiffness_N_per_m, const Vec3& force_ref_N = Vec3::Zero(),
                        const Vec3& position_ref_m = Vec3::Zero());

// A device whose pose the test sets; read() fails while `available` is false.
class ScriptedDevice final : public Device {
 public:
  Vec3 position_m = Vec3::Zero();
  Vec3 velocity_m_per_s = Vec3::Zero();
  bool available = true;
  Vec3 last_force_N = Vec3::Zero();
  std::uint64_t writes = 0;

  bool start(std::string*) override { return true; }
  void stop() noexcept override {}
  bool read(std::int64_t, DeviceSample* out) noexcept override {
    if (!available) return false;
    out->position_m = position_m;
    out->velocity_m_per_s = velocity_m_per_s;
    return true;
  }
  void write(std::int64_t, const Vec3& force_N) noexcept override {
    last_force_N = force_N;
    ++writes;
  }
  const char* name() const noexcept override { return "scripted"; }
};

}  // namespace tissue::haptics::test
