#include "replay_test_support.hpp"

namespace tissue::replay::testing {

void RecordingSink::mesh(const service::MeshSnapshot& s) {
  sent.push_back({StreamKind::kMesh, s.sim_time_s, clock_->now_s(), s.sequence, s.vertices_m.size()});
  if (const auto cost = mesh_cost_s.find(s.sequence); cost != mesh_cost_s.end()) clock_->advance(cost->second);
  if (++meshes_ == stop_after && stop) stop->store(true);
}

void RecordingSink::haptic(const service::SimStatus& s) {
  sent.push_back({StreamKind::kHaptic, s.sim_time_s, clock_->now_s()});
}

void RecordingSink::stats(const service::SimStatus& s) {
  sent.push_back({StreamKind::kStats, s.sim_time_s, clock_->now_s()});
}

void RecordingSink::haptic_hole(const record::HapticHole& hole) { holes.push_back({hole, sent.size()}); }

std::vector<x3d::SurfaceFrame> moving_frames(std::size_t n, double dt_s) {
  std::vector<x3d::SurfaceFrame> out;
  for (std::size_t k = 0; k < n; ++k) {
    const record::testing::TestFrame t = record::testing::test_frame(k);
    x3d::SurfaceFrame f;
    f.time_s = static_cast<double>(k) * dt_s;
    f.vertices_m = t.vertices_m;
    f.triangles = t.triangles;
    f.vertex_level = t.vertex_level;
    out.push_back(std::move(f));
  }
  return out;
}

SessionRows rows(std::size_t haptic, double haptic_dt_s, std::size_t sim, double sim_dt_s) {
  SessionRows r;
  for (std::size_t i = 0; i < haptic; ++i) {
    r.haptic.push_back(record::testing::haptic_row(i));
    r.haptic.back().time_s = static_cast<double>(i) * haptic_dt_s;
  }
  for (std::size_t i = 0; i < sim; ++i) {
    r.sim.push_back(record::testing::sim_row(i));
    r.sim.back().time_s = static_cast<double>(i) * sim_dt_s;
  }
  return r;
}

std::string write_session(const std::string& path, std::uint64_t frames) {
  record::testing::TestSession content;
  content.haptic = frames * 1000 / 30;
  content.sim = frames * 50 / 30;
  content.frames = frames;
  content.events = 0;
  content.scene_name = "replay test";
  return record::testing::write_test_session(path, content);
}

}  // namespace tissue::replay::testing
