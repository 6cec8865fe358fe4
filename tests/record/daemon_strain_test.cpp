// End to end: the real tissued records the loaded cantilever (config/scenes/
// cantilever.yaml bends under 5 N from t = 0), and the session carries the
// strain the sim thread computed: finite everywhere, non-zero where it
// bends, and `tissue x3d` / `tissue render --colour strain` draw it.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <thread>

#include "export/frame_source.hpp"
#include "record/session_tools.hpp"
#include "record_test_support.hpp"

extern char** environ;

namespace tissue::record {
namespace {

using testing::quote;
using testing::TempDir;

// Runs tissued for `seconds` of wall time recording `name`; returns its exit
// status (-1 when it had to be killed).
int run_daemon(const TempDir& dir, const std::string& name, double seconds) {
  const std::string config = dir / "tissued.yaml";
  std::ofstream(config) << "scene: " << TISSUE_SOURCE_DIR << "/config/scenes/cantilever.yaml\n"
                        << "state_dir: " << dir.path() << "\n"
                        << "device: {kind: none}\n"
                        << "realtime: {sched_fifo: false, lock_memory: false}\n"
                        << "control: {unix_socket_path: " << (dir / "ctl.sock") << "}\n";
  std::vector<std::string> args = {TISSUED_BINARY,         "--config", config, "--record", name, "--duration",
                                   std::to_string(seconds)};
  std::vector<char*> argv;
  for (std::string& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, "/dev/null", O_WRONLY, 0);
  pid_t pid = 0;
  const int spawned = ::posix_spawn(&pid, TISSUED_BINARY, &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  if (spawned != 0) return -2;
  // Generous: start-up and shutdown on a loaded 2-core machine.
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds + 30.0);
  int status = 0;
  while (::waitpid(pid, &status, WNOHANG) == 0) {
    if (std::chrono::steady_clock::now() > deadline) {
      ::kill(pid, SIGKILL);
      ::waitpid(pid, &status, 0);
      return -1;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

TEST(DaemonStrain, RecordedCantileverCarriesStrainAndTheClientsColourByIt) {
  TempDir dir;
  ASSERT_EQ(run_daemon(dir, "bend.h5", 2.0), 0);
  const std::string session = dir / "bend.h5";
  const SessionInfo info = read_session_info(session);
  EXPECT_TRUE(info.closed_cleanly);
  EXPECT_TRUE(info.has_strain);
  ASSERT_GE(info.rows.mesh_frames, 2u);

  // Raw column: one finite, non-negative value per triangle row, and the
  // bending object is strained somewhere.
  const hid_t file = H5Fopen(session.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  ASSERT_GE(file, 0);
  const auto strain = testing::read_f32(file, "/mesh/triangle_strain_energy_J_per_m3");
  const auto tris = testing::read_i32(file, "/mesh/triangles");
  H5Fclose(file);
  ASSERT_EQ(3 * strain.size(), tris.size());
  for (std::size_t i = 0; i < strain.size(); ++i) ASSERT_TRUE(std::isfinite(strain[i]) && strain[i] >= 0) << i;
  EXPECT_GT(*std::max_element(strain.begin(), strain.end()), 1.0f) << "a 5 N load on a 5e4 Pa cube strains it";

  // Through the clients' source: per-vertex values, finite; a frame while
  // the load is on (released at 1 s of simulated time) is strained, and not
  // uniformly (most near the clamped face).
  auto source = x3d::open_session_source(session);
  ASSERT_TRUE(source->has_strain());
  const auto loaded = x3d::frame_at_time(*source, 0.5);
  ASSERT_TRUE(loaded.has_value());
  const x3d::SurfaceFrame bent = source->read_frame(*loaded);
  ASSERT_EQ(bent.vertex_strain_energy_Pa.size(), bent.vertices_m.size());
  for (const float e : bent.vertex_strain_energy_Pa) ASSERT_TRUE(std::isfinite(e));
  const auto [lo, hi] = std::minmax_element(bent.vertex_strain_energy_Pa.begin(), bent.vertex_strain_energy_Pa.end());
  EXPECT_GT(*hi, 1.0f);
  EXPECT_LT(*lo, 0.5f * *hi);
  for (std::size_t k = 0; k < source->frame_count(); ++k)
    for (const float e : source->read_frame(k).vertex_strain_energy_Pa) ASSERT_TRUE(std::isfinite(e)) << "frame " << k;

  TempDir scratch;
  const std::string tissue = quote(TISSUE_CLI_BINARY);
  const auto x3d = testing::run(
      tissue + " x3d --session " + quote(session) + " --time 0.5 --colour strain -o " + quote(dir / "bend.x3d"),
      scratch);
  EXPECT_EQ(x3d.exit_code, 0) << x3d.err;
  const std::string xml = testing::slurp(dir / "bend.x3d");
  const std::string key = "tissue.strain_energy_max_Pa' content='";
  const std::size_t at = xml.find(key);
  ASSERT_NE(at, std::string::npos);
  EXPECT_GT(std::stod(xml.substr(at + key.size(), 32)), 1.0) << "the X3D ramp spans the recorded strain";
  const auto anim = testing::run(
      tissue + " x3d --session " + quote(session) + " --animate --colour strain -o " + quote(dir / "anim.x3d"),
      scratch);
  EXPECT_EQ(anim.exit_code, 0) << anim.err;
  const auto png = testing::run(
      tissue + " render --session " + quote(session) + " --time 0.5 --colour strain -o " + quote(dir / "bend.png"),
      scratch);
  EXPECT_EQ(png.exit_code, 0) << png.err;
  EXPECT_NE(png.out.find(" Pa"), std::string::npos) << png.out;  // the ramp's ends are printed
  EXPECT_GT(std::filesystem::file_size(dir / "bend.png"), 100u);

  // And a version-1 copy is refused for strain with the clear message (exit 2).
  std::filesystem::copy_file(session, dir / "v1.h5");
  testing::make_version_1(dir / "v1.h5");
  for (const char* cmd : {" x3d", " render"}) {
    const auto r = testing::run(
        tissue + cmd + " --session " + quote(dir / "v1.h5") + " --colour strain -o " + quote(dir / "v1.out"), scratch);
    EXPECT_EQ(r.exit_code, 2) << cmd << ": " << r.err;
    EXPECT_NE(r.err.find("stores no strain"), std::string::npos) << cmd << ": " << r.err;
  }
}

}  // namespace
}  // namespace tissue::record
