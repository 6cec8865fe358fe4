#include "replay_test_support.hpp"

#include <hdf5.h>

#include <fstream>
#include <random>

#include "record/session_writer.hpp"

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
  record::SessionMetadata m;
  m.scene_name = "replay test";
  m.software_version = "test";
  auto w = record::SessionWriter::create(path, m);
  const std::uint64_t haptic = frames * 1000 / 30, sim = frames * 50 / 30;
  std::vector<record::HapticRow> h;
  for (std::uint64_t i = 0; i < haptic; ++i) h.push_back(record::testing::haptic_row(i));
  w->append_haptic(h);
  std::vector<record::SimRow> s;
  for (std::uint64_t i = 0; i < sim; ++i) s.push_back(record::testing::sim_row(i));
  w->append_sim(s);
  for (std::uint64_t f = 0; f < frames; ++f) w->append_mesh_frame(record::testing::test_frame(f).view());
  w->close();
  return path;
}

namespace {
void write_bytes(const std::string& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}
}  // namespace

std::vector<std::string> bad_session_files(const record::testing::TempDir& dir) {
  std::vector<std::string> files;
  const std::string good = write_session(dir / "good.h5", 5);
  const std::string bytes = record::testing::slurp(good);
  write_bytes(dir / "empty.h5", "");
  files.push_back(dir / "empty.h5");
  write_bytes(dir / "text.h5", "this is a scene file, not a session\nname: cantilever\n");
  files.push_back(dir / "text.h5");
  std::mt19937 rng(7);
  std::string noise(65536, '\0');
  for (char& c : noise) c = static_cast<char>(rng() & 0xff);
  write_bytes(dir / "random.h5", noise);
  files.push_back(dir / "random.h5");
  write_bytes(dir / "signature_then_noise.h5", bytes.substr(0, 8) + noise);
  files.push_back(dir / "signature_then_noise.h5");
  for (const std::size_t cut :
       {std::size_t{11}, std::size_t{500}, bytes.size() / 4, bytes.size() / 2, bytes.size() - 100, bytes.size() - 1}) {
    const std::string name = dir / ("truncated_" + std::to_string(cut) + ".h5");
    write_bytes(name, bytes.substr(0, cut));
    files.push_back(name);
  }
  const hid_t f = H5Fcreate((dir / "foreign.h5").c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
  H5Fclose(f);
  files.push_back(dir / "foreign.h5");
  files.push_back(dir / "does_not_exist.h5");
  files.push_back(dir.path());
  return files;
}

}  // namespace tissue::replay::testing
