// The replay device as the service builds it (HapticSide): the session's
// /haptic/device_fresh flags and the config's device.limits.device_timeout_s
// must reach the ReplayDevice. Each case is told by start(): HapticSide::start
// throws, naming device.replay.speed, when the replay would play the track
// faster than device.limits.max_speed_m_per_s, and warns (device.replay.loop)
// when a looping replay jumps too far at the wrap, in one tick or over the
// time it plays no samples across it.
#include <gtest/gtest.h>

#include <cstdint>
#include <cstdio>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "config/daemon_config.hpp"
#include "record/record_test_support.hpp"
#include "record/session_writer.hpp"
#include "service/haptic_side.hpp"

namespace tissue::service {
namespace {

// A 250 Hz device recorded at 1 kHz (a sample every 4th row, flagged), along
// x: pose(k) for sample k; the samples in `lost` never came (their rows hold
// the last one, unflagged).
template <typename Pose>
std::string write_250hz_session(const std::string& path, int rows, Pose pose, int lost_from, int lost_to) {
  record::SessionMetadata meta;
  meta.scene_name = "replay";
  meta.software_version = "test";
  auto writer = record::SessionWriter::create(path, meta);
  std::vector<record::HapticRow> haptic;
  double held_x_m = pose(0);
  for (int row = 0; row < rows; ++row) {
    const int sample = row / 4;
    const bool came = row % 4 == 0 && (sample < lost_from || sample > lost_to);
    if (came) held_x_m = pose(sample);
    record::HapticRow r;
    r.time_s = 1e-3 * row;
    r.device_position_m = {held_x_m, 0.0, 0.0};
    r.device_fresh = came ? 1 : 0;
    haptic.push_back(r);
  }
  writer->append_haptic(haptic);
  writer->close();
  return path;
}

config::DaemonConfig replay_config(const std::string& session, double speed) {
  config::DaemonConfig config;
  config.device.kind = config::DeviceSpec::Kind::kReplay;
  config.device.replay.session = session;
  config.device.replay.speed = speed;
  config.realtime.sched_fifo = false;
  config.realtime.lock_memory = false;
  return config;
}

// Starts the haptic side; "" when it started, else why it did not. With
// `printed`, what it printed when it started (its warnings).
std::string start_error(const config::DaemonConfig& config, std::string* printed = nullptr) {
  auto samples = std::make_unique<ToolSampleRing>();
  auto models = std::make_unique<LocalModelChannel>();
  std::FILE* out = printed ? std::tmpfile() : nullptr;
  std::string error;
  try {
    auto side = HapticSide::start(config, *samples, *models, out);
    side->stop();
  } catch (const std::runtime_error& e) {
    error = e.what();
  }
  if (out) {
    printed->clear();
    std::rewind(out);
    char buffer[512];
    while (std::fgets(buffer, sizeof buffer, out)) *printed += buffer;
    std::fclose(out);
  }
  return error;
}

// Four packets lost in a row at 3 m/s: with the flags the 60 mm step spreads
// over the 20 ms gap (3 m/s), so 1.5 times real time plays at 4.5 m/s; the
// rule for files without flags squeezes it into 3 periods (5 m/s) and refuses
// 1.5 (7.5 m/s). The device timeout is set above the gap so it glides.
TEST(ReplayHapticSide, TheSessionsFreshFlagsReachTheReplayDevice) {
  record::testing::TempDir dir;
  const std::string path = write_250hz_session(
      dir / "v3.h5", 261, [](int k) { return -0.4 + 3.0 * 4e-3 * k; }, 30, 33);
  config::DaemonConfig config = replay_config(path, 1.5);
  config.device.limits.device_timeout_s = 0.05;
  EXPECT_EQ(start_error(config), "");

  record::testing::make_version_2(path);  // the same rows without the flags
  const std::string error = start_error(config);
  EXPECT_NE(error.find("device.replay.speed 1.5"), std::string::npos) << error;
}

// 80 mm in the 20 ms of four lost packets (4 m/s, as the live loop took it),
// and the track ends on the sample after them, looping. With the default
// 10 ms device timeout the gap plays as no samples (the loop loses the
// device, as live), so the wrap makes no one-tick jump and the daemon does
// not warn; with a 50 ms timeout the gap glides, the track ends at 80 mm
// and the one-tick jump back to the origin is warned about.
TEST(ReplayHapticSide, TheDeviceTimeoutReachesTheReplayDevice) {
  record::testing::TempDir dir;
  const std::string path = write_250hz_session(
      dir / "gap.h5", 137, [](int k) { return k < 30 ? 0.0 : 0.08; }, 30, 33);
  config::DaemonConfig config = replay_config(path, 1.0);
  config.device.replay.loop = true;
  ASSERT_EQ(config.device.limits.device_timeout_s, 0.01);
  std::string printed;
  EXPECT_EQ(start_error(config, &printed), "");
  EXPECT_EQ(printed.find("device.replay.loop"), std::string::npos) << printed;

  config.device.limits.device_timeout_s = 0.05;
  EXPECT_EQ(start_error(config, &printed), "");
  EXPECT_NE(printed.find("tissued: warning: device.replay.loop"), std::string::npos) << printed;
}

// A looping session whose device came at row 52 (samples 0..12 never came,
// the rows before at the origin), then along x at 1.25 m/s to 0.245 m: at
// each wrap the replay plays those 52 ms as no samples, and the loop judges
// the first sample (0.065 m) against the last over them: 0.18 m in 52 ms,
// 3.5 m/s, taken, no warning (warned before as a one-tick jump). At twice
// the speed, 26 ms of wall time: 6.9 m/s, rejected, and the daemon says so.
TEST(ReplayHapticSide, TheWrapThroughTheRowsBeforeTheFirstSampleIsJudgedOverThem) {
  record::testing::TempDir dir;
  const std::string path = write_250hz_session(
      dir / "late.h5", 200, [](int k) { return k < 13 ? 0.0 : 5e-3 * k; }, 0, 12);
  config::DaemonConfig config = replay_config(path, 1.0);
  config.device.replay.loop = true;
  ASSERT_EQ(config.device.limits.max_speed_m_per_s, 5.0);
  std::string printed;
  EXPECT_EQ(start_error(config, &printed), "");
  EXPECT_EQ(printed.find("device.replay.loop"), std::string::npos) << printed;

  config.device.replay.speed = 2.0;
  EXPECT_EQ(start_error(config, &printed), "");
  EXPECT_NE(printed.find("tissued: warning: device.replay.loop: the looping track goes from its last sample back to "
                         "its first through 0.026 s (wall time) without samples, a 0.18 m jump"),
            std::string::npos)
      << printed;
}

// A session whose device never delivered a sample (every flag 0, the rows at
// the device origin) has no hand to replay: refused, naming the file.
TEST(ReplayHapticSide, ASessionWithNoDeviceSampleIsRefusedNamingIt) {
  record::testing::TempDir dir;
  const std::string path = write_250hz_session(
      dir / "nodevice.h5", 40, [](int) { return 0.0; }, 0, 1000);
  const std::string error = start_error(replay_config(path, 1.0));
  EXPECT_NE(error.find("haptic device replay (device.replay.session " + path +
                       "): replay device: the track has no "
                       "device sample"),
            std::string::npos)
      << error;
}

}  // namespace
}  // namespace tissue::service
