#include "service/sim_thread.hpp"

#include <gtest/gtest.h>

#include <chrono>
#include <thread>

#include "physics/physics_test_support.hpp"

namespace tissue::service {
namespace {

using namespace std::chrono_literals;

scene::Scene cantilever_with_tool() {
  scene::Scene s = physics::testing::cantilever_scene();
  s.tool = scene::ToolSpec{};
  return s;
}

template <typename Pred>
bool wait_for(Pred pred, std::chrono::milliseconds timeout = 5000ms) {
  const auto end = std::chrono::steady_clock::now() + timeout;
  while (std::chrono::steady_clock::now() < end) {
    if (pred()) return true;
    std::this_thread::sleep_for(2ms);
  }
  return pred();
}

// Paced to the wall clock: over ~0.3 s of wall time it simulates about as
// much (a generous band: the machine is shared), and models flow out with
// increasing versions.
TEST(SimThread, PacedStepsPublishModelsAndStatus) {
  ToolSampleRing samples;
  LocalModelChannel models;
  SimThreadOptions options;
  options.status_every_s = 0.01;
  SimThread thread(std::make_unique<SimRunner>(cantilever_with_tool()), &samples, &models, options);
  thread.start();
  haptics::ToolSample hover;
  hover.proxy_position_m = haptics::Vec3(0.05, 0.05, 0.102);
  const auto t0 = std::chrono::steady_clock::now();
  std::uint64_t last_version = 0;
  int versions_seen = 0;
  while (std::chrono::steady_clock::now() - t0 < 300ms) {
    samples.try_push(hover);
    const auto read = models.read();
    if (read.is_new) {
      EXPECT_GT(read.value->version, last_version);
      last_version = read.value->version;
      ++versions_seen;
    }
    std::this_thread::sleep_for(1ms);
  }
  const double wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  ASSERT_TRUE(wait_for([&] { return thread.status().steps > 0; }));
  thread.stop();
  const SimStatus s = thread.status();
  EXPECT_GT(versions_seen, 20);
  EXPECT_GT(s.samples, 0u);
  EXPECT_LE(s.sim_time_s, wall_s + 0.05);  // paced: never ahead of the wall clock
  EXPECT_GT(s.sim_time_s, 0.1 * wall_s);   // and not stalled (generous: shared machine, sanitizers)
  EXPECT_EQ(s.failed_steps, 0);
  EXPECT_FALSE(thread.scheduling().empty());
}

TEST(SimThread, PauseStopsTimeButKeepsTheModelFresh) {
  LocalModelChannel models;
  SimThreadOptions options;
  options.status_every_s = 0.005;
  SimThread thread(std::make_unique<SimRunner>(cantilever_with_tool()), nullptr, &models, options);
  thread.start();
  ASSERT_TRUE(wait_for([&] { return thread.status().steps > 5; }));
  thread.pause();
  ASSERT_TRUE(wait_for([&] { return thread.status().paused; }));
  std::this_thread::sleep_for(20ms);
  const double t_paused = thread.status().sim_time_s;
  const std::int64_t built_before = models.read().value->built_ns;
  std::this_thread::sleep_for(50ms);
  EXPECT_EQ(thread.status().sim_time_s, t_paused);
  EXPECT_GT(models.read().value->built_ns, built_before);  // re-stamped while paused
  thread.resume();
  EXPECT_TRUE(wait_for([&] { return thread.status().sim_time_s > t_paused; }));
}

TEST(SimThread, ReplacingTheRunnerStartsANewGeneration) {
  SimThreadOptions options;
  options.status_every_s = 0.005;
  SimThread thread(std::make_unique<SimRunner>(physics::testing::cantilever_scene()), nullptr, nullptr, options);
  thread.start();
  ASSERT_TRUE(wait_for([&] { return thread.status().sim_time_s > 0.02; }));
  thread.replace_runner(std::make_unique<SimRunner>(physics::testing::cantilever_scene()));
  ASSERT_TRUE(wait_for([&] { return thread.status().generation == 1; }));
  EXPECT_LT(thread.status().sim_time_s, 0.02 + 0.05);
  thread.stop();
  thread.stop();  // idempotent
}

// A stall (here: steps far slower than dt) sheds adaptation and re-anchors
// the schedule instead of bursting.
TEST(SimThread, FallingBehindShedsAdaptationAndCountsOverruns) {
  scene::Scene s = physics::testing::cantilever_scene();
  s.integrator.dt_s = 1e-5;  // 100 kHz: no machine keeps up
  SimThreadOptions options;
  options.status_every_s = 0.005;
  options.max_lag_s = 0.002;
  options.shed_after_lag_s = 0.0005;
  SimThread thread(std::make_unique<SimRunner>(s), nullptr, nullptr, options);
  thread.start();
  EXPECT_TRUE(wait_for([&] {
    const SimStatus st = thread.status();
    return st.adaptation_shed && st.overruns > 0;
  }));
  thread.stop();
}

}  // namespace
}  // namespace tissue::service
