// The real tissued binary, killed with SIGKILL while recording: after repair
// the session file holds everything the daemon had flushed (issue 6: a crash
// loses at most about a second).
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <thread>

#include "control/control_client.hpp"
#include "control/temp_dir.hpp"
#include "record/session_tools.hpp"

extern char** environ;

namespace tissue::service {
namespace {

using namespace std::chrono_literals;
using control::testing::TempDir;

TEST(DaemonProcess, KillNineWhileRecordingThenRepairKeepsWhatWasFlushed) {
  TempDir dir;
  const std::string config = dir / "tissued.yaml";
  std::ofstream(config) << "scene: " << TISSUE_SOURCE_DIR << "/config/scenes/cantilever.yaml\n"
                        << "state_dir: " << dir.path() << "\n"
                        << "device:\n  kind: sim\n  sim:\n    mode: hand\n    loop: true\n    waypoints:\n"
                        << "      - {time_s: 0.0, position_m: [0.05, 0.05, 0.105]}\n"
                        << "      - {time_s: 0.3, position_m: [0.05, 0.05, 0.095]}\n"
                        << "realtime: {sched_fifo: false, lock_memory: false}\n"
                        << "control: {unix_socket_path: " << (dir / "ctl.sock") << "}\n";
  std::vector<std::string> args = {TISSUED_BINARY, "--config", config, "--record", "crash.h5"};
  std::vector<char*> argv;
  for (std::string& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  pid_t pid = 0;
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, "/dev/null", O_WRONLY, 0);
  ASSERT_EQ(::posix_spawn(&pid, TISSUED_BINARY, &actions, nullptr, argv.data(), environ), 0);
  posix_spawn_file_actions_destroy(&actions);

  // Let it record for a while, and ask how much it has written.
  std::uint64_t rows_before_kill = 0;
  for (int i = 0; i < 200 && rows_before_kill < 1500; ++i) {
    std::this_thread::sleep_for(20ms);
    try {
      control::ControlClient client = control::ControlClient::connect_unix(dir / "ctl.sock", 2000ms);
      const nlohmann::json r = client.call("status");
      if (r["ok"].get<bool>() && r["result"]["recording"].is_object())
        rows_before_kill = r["result"]["recording"]["haptic_rows"].get<std::uint64_t>();
    } catch (const control::ControlClientError&) {
      // not up yet
    }
  }
  ASSERT_GE(rows_before_kill, 1000u) << "the daemon did not record";
  ASSERT_EQ(::kill(pid, SIGKILL), 0);
  int status = 0;
  ASSERT_EQ(::waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFSIGNALED(status));

  const std::string file = dir / "crash.h5";
  const record::SessionInfo crashed = record::read_session_info(file);
  EXPECT_FALSE(crashed.closed_cleanly);
  record::repair_session(file);
  const record::SessionInfo info = record::read_session_info(file);
  // Rows written before the status call were flushed within the flush
  // interval (0.25 s) after it: a crash loses at most that much, here 1 s
  // of margin for a loaded machine.
  EXPECT_GE(info.rows.haptic_rows + 1000, rows_before_kill);
  EXPECT_GT(info.rows.mesh_frames, 0u);
  EXPECT_EQ(info.scene_name, "cantilever");
}

}  // namespace
}  // namespace tissue::service
