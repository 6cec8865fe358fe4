// Device frame <-> scene frame, applied in exactly one place (HapticLoop).
//
//   p_scene = offset_m + scale * p_device,   v_scene = scale * v_device.
//
// Forces map so that power is the same in both frames (F_dev . v_dev ==
// F_scene . v_scene), which keeps the mapping passive: F_device = scale *
// F_scene. With scale != 1 the user feels the scene's stiffness times scale^2,
// the usual price of a scaled workspace.
#pragma once

#include <array>

#include "haptics/local_model.hpp"

namespace tissue::haptics {

struct FrameTransform {
  Vec3 offset_m = Vec3::Zero();
  double scale = 1.0;

  static FrameTransform from(const std::array<double, 3>& offset_m, double scale) {
    return {Vec3(offset_m[0], offset_m[1], offset_m[2]), scale};
  }
  Vec3 position_to_scene(const Vec3& p_device_m) const { return offset_m + scale * p_device_m; }
  Vec3 position_to_device(const Vec3& p_scene_m) const { return (p_scene_m - offset_m) / scale; }
  Vec3 velocity_to_scene(const Vec3& v_device_m_per_s) const { return scale * v_device_m_per_s; }
  Vec3 force_to_device(const Vec3& f_scene_N) const { return scale * f_scene_N; }
  Vec3 force_to_scene(const Vec3& f_device_N) const { return f_device_N / scale; }
};

}  // namespace tissue::haptics
