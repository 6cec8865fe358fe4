// BatchRecorder (app/batch_record.cpp) in-process: what a batch run's session
// holds, frame by frame; the process contract of `tissued --batch --record`
// (exit codes, the report unchanged, a file-size limit) is in
// batch_run_test.cpp.
#include "app/batch_record.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>

#include "export/frame_source.hpp"
#include "record/session_tools.hpp"
#include "scene/scene_yaml.hpp"
#include "support/process_support.hpp"

namespace tissue::app {
namespace {

using tissue::testing::TempDir;

scene::Scene beam() { return scene::load_scene_file(std::string(TISSUE_SOURCE_DIR) + "/config/scenes/beam.yaml"); }

// Steps `sim` n times, recording each step.
void run(physics::Simulation& sim, BatchRecorder& recorder, int n) {
  for (int i = 0; i < n; ++i) {
    ASSERT_TRUE(sim.step().ok);
    recorder.after_step(sim, 0.5);
  }
}

TEST(BatchRecorder, AFrameEveryIntervalOfSimulatedTimeAndTheLastState) {
  TempDir dir;
  const std::string path = dir / "beam.h5";
  physics::Simulation sim(beam());
  const double dt = sim.scene().integrator.dt_s;
  BatchRecorder recorder(path, sim, "scene text", "the command", 0.01);
  const int steps = static_cast<int>(std::lround(0.035 / dt));
  run(sim, recorder, steps);
  EXPECT_EQ(recorder.finish(sim, ""), "");

  const record::SessionInfo info = record::read_session_info(path);
  EXPECT_TRUE(info.closed_cleanly);
  EXPECT_EQ(info.duration_s, sim.time_s());  // in session time: simulated seconds
  EXPECT_EQ(info.rows.sim_rows, static_cast<std::uint64_t>(steps));
  EXPECT_EQ(info.rows.events, 2u);
  const auto frames = x3d::open_session_source(path);
  ASSERT_EQ(frames->frame_count(), 5u);  // 0, 0.01, 0.02, 0.03 and the end, 0.035 s
  for (std::size_t k = 0; k < 4; ++k) EXPECT_NEAR(frames->frame_time_s(k), 0.01 * static_cast<double>(k), 0.5 * dt);
  EXPECT_EQ(frames->frame_time_s(4), sim.time_s());
  // The rows carry the step's pace and the simulation's own figures.
  const record::SessionRows rows = record::read_session_rows(path);
  ASSERT_EQ(rows.sim.size(), static_cast<std::size_t>(steps));
  EXPECT_EQ(rows.sim.back().sim_time_s, sim.time_s());
  EXPECT_EQ(rows.sim.back().time_s, sim.time_s());  // session time is simulated time
  EXPECT_EQ(rows.sim.back().step_ms, 0.5);
  EXPECT_DOUBLE_EQ(rows.sim.back().real_time_factor, 1e3 * dt / 0.5);
  EXPECT_EQ(rows.sim.back().nodes, sim.body().mesh().node_count());
  EXPECT_EQ(rows.sim.back().elastic_J, sim.elastic_energy_J());
}

// Found by the review of the day's diff: once flushes synced the file to
// disk, a batch run synced at every frame (303 fdatasync calls, 1.3 s of a
// 4.7 s recorded run of 10 s of cantilever). A batch file is synced once,
// when it is closed; its frames are still flushed for readers as they come.
TEST(BatchRecorder, SyncsItsFileToDiskOnceWhenItIsClosed) {
  TempDir dir;
  const std::string path = dir / "beam.h5";
  physics::Simulation sim(beam());
  BatchRecorder recorder(path, sim, "", "", 0.01);
  int syncs = 0;
  recorder.set_sync_for_testing([&](int) {
    ++syncs;
    return 0;
  });
  run(sim, recorder, static_cast<int>(std::lround(0.035 / sim.scene().integrator.dt_s)));
  EXPECT_EQ(syncs, 0) << "after " << recorder.mesh_frames() << " frames";
  EXPECT_EQ(recorder.finish(sim, ""), "");
  EXPECT_EQ(syncs, 1);
  EXPECT_TRUE(record::read_session_info(path).closed_cleanly);
}

TEST(BatchRecorder, NeverOverwritesAFileAndRefusesANonsenseFrameInterval) {
  TempDir dir;
  const std::string path = dir / "taken.h5";
  std::ofstream(path) << "not ours";
  physics::Simulation sim(beam());
  try {
    BatchRecorder recorder(path, sim, "", "");
    ADD_FAILURE() << "recorded over an existing file";
  } catch (const record::RecordError& e) {
    EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
  }
  std::ifstream in(path);
  std::string text;
  std::getline(in, text);
  EXPECT_EQ(text, "not ours");
  for (const double bad : {0.0, -1.0, std::nan("")})
    EXPECT_THROW(BatchRecorder(dir / "new.h5", sim, "", "", bad), std::invalid_argument) << bad;
  EXPECT_FALSE(std::filesystem::exists(dir / "new.h5"));
}

// More rows than one write holds (1,000): every one reaches the file, in order.
TEST(BatchRecorder, RowsBeyondOneWriteAllArrive) {
  TempDir dir;
  const std::string path = dir / "long.h5";
  physics::Simulation sim(beam());
  BatchRecorder recorder(path, sim, "", "", 10.0);  // no frames but the first and the last
  run(sim, recorder, 2500);
  EXPECT_EQ(recorder.finish(sim, "a reason"), "");
  const record::SessionRows rows = record::read_session_rows(path);
  ASSERT_EQ(rows.sim.size(), 2500u);
  for (std::size_t i = 1; i < rows.sim.size(); ++i) ASSERT_GT(rows.sim[i].sim_time_s, rows.sim[i - 1].sim_time_s);
  EXPECT_EQ(record::read_session_info(path).rows.mesh_frames, 2u);
}

}  // namespace
}  // namespace tissue::app
