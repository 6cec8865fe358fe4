#include "service/sim_thread.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <limits>
#include <thread>
#include <vector>

#include "config/daemon_config.hpp"
#include "haptics/closest_point.hpp"
#include "haptics/haptic_thread.hpp"
#include "haptics/sim_device.hpp"
#include "physics/physics_test_support.hpp"
#include "record/record_test_support.hpp"
#include "record/recorder.hpp"
#include "record/session_tools.hpp"
#include "support/process_support.hpp"
#include "transport/dds_messages.hpp"
#include "transport/lcm_messages.hpp"

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

// Tool samples of a proxy hovering 2 mm above the cantilever's top face, one
// a millisecond for `how_long`, as the haptic thread would push them.
void hover_over_the_top_face(ToolSampleRing& samples, std::chrono::milliseconds how_long) {
  haptics::ToolSample hover;
  hover.proxy_position_m = haptics::Vec3(0.05, 0.05, 0.102);
  const auto end = std::chrono::steady_clock::now() + how_long;
  while (std::chrono::steady_clock::now() < end) {
    samples.try_push(hover);
    std::this_thread::sleep_for(1ms);
  }
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
  // 0.3 s: no one-second window measured yet. The pace is NaN ("not
  // measured", as status says null), not 0 (a sim standing still), in what
  // is recorded and published.
  EXPECT_FALSE(s.real_time_factor_measured);
  EXPECT_TRUE(std::isnan(s.real_time_factor)) << s.real_time_factor;
}

// The daemon prints scheduling() right after start(): it must be decided by
// then (it was "" in most runs of `tissued --set device.kind=none`).
TEST(SimThread, SchedulingIsKnownWhenStartReturns) {
  ToolSampleRing samples;
  LocalModelChannel models;
  for (const int priority : {0, 1}) {
    SimThreadOptions options;
    options.priority = priority;  // 1: SCHED_FIFO, granted or refused
    SimThread thread(std::make_unique<SimRunner>(cantilever_with_tool()), &samples, &models, options);
    EXPECT_EQ(thread.scheduling(), "");
    thread.start();
    const std::string scheduling = thread.scheduling();
    thread.stop();
    EXPECT_EQ(scheduling.rfind("SCHED_", 0), 0u) << "'" << scheduling << "'";
  }
}

SimThreadOptions fast_status() {
  SimThreadOptions options;
  options.status_every_s = 0.005;
  return options;
}

// A tick with the tool over the cantilever's loaded free end, out of engage
// distance.
haptics::ToolSample hovering_over_the_free_end() {
  haptics::ToolSample hover;
  hover.proxy_position_m = haptics::Vec3(0.09, 0.05, 0.112);
  return hover;
}

// haptic_state's local_model_version is the model the loop rendered
// against, taken from its tick: a loop still on version 1 while the sim has
// published newer ones shows 1 (a stale loop's version stops increasing).
TEST(SimThread, StatusCarriesTheModelVersionTheTickRenderedAgainst) {
  ToolSampleRing samples;
  LocalModelChannel models;
  SimThread thread(std::make_unique<SimRunner>(cantilever_with_tool()), &samples, &models, fast_status());
  haptics::ToolSample hover = hovering_over_the_free_end();
  hover.model_version = 1;
  ASSERT_TRUE(samples.try_push(hover));
  thread.start();
  ASSERT_TRUE(wait_for([&] { return thread.status().samples >= 1 && thread.status().model_version > 3; }));
  const SimStatus status = thread.status();
  thread.stop();
  EXPECT_EQ(status.tick_model_version, 1u);
  EXPECT_EQ(transport::haptic_message(status, 1).local_model_version, 1);
  EXPECT_EQ(transport::to_dds_haptic(status, 1).local_model_version(), 1);
}

TEST(SimThread, PauseStopsTimeButKeepsTheModelFresh) {
  ToolSampleRing samples;
  LocalModelChannel models;
  SimThread thread(std::make_unique<SimRunner>(cantilever_with_tool()), &samples, &models, fast_status());
  // The tool hovers over the loaded free end, so the patch is the surface
  // that moves from the first steps. With no tick the tool is parked 1 km up
  // and the patch is the highest triangle: on the clamped face (velocities
  // exactly zero) while the load bends the beam down, so nothing moved until
  // the load's release at 1 s of sim time.
  ASSERT_TRUE(samples.try_push(hovering_over_the_free_end()));
  thread.start();
  ASSERT_TRUE(wait_for([&] { return thread.status().steps > 5; }));
  const auto moving = [&] {
    const haptics::LocalModel& m = *models.read().value;
    for (int i = 0; i < m.vertex_count; ++i)
      if (!m.vertex_velocity_m_per_s[i].isZero(0.0)) return true;
    return false;
  };
  ASSERT_TRUE(wait_for(moving)) << "the loaded cantilever swings";
  thread.pause();
  ASSERT_TRUE(wait_for([&] { return thread.status().paused; }));
  std::this_thread::sleep_for(20ms);
  const double t_paused = thread.status().sim_time_s;
  const std::int64_t built_before = models.read().value->built_ns;
  std::this_thread::sleep_for(50ms);
  EXPECT_EQ(thread.status().sim_time_s, t_paused);
  EXPECT_GT(models.read().value->built_ns, built_before);  // re-stamped while paused
  // Paused, the surface stands still: the model the haptic side holds has
  // no velocity to extrapolate (the cantilever was swinging when paused),
  // and re-affirming it does not make new versions.
  const haptics::LocalModel& held = *models.read().value;
  ASSERT_GT(held.vertex_count, 0);
  for (int i = 0; i < held.vertex_count; ++i)
    EXPECT_EQ(held.vertex_velocity_m_per_s[i], haptics::Vec3::Zero()) << "vertex " << i;
  const std::uint64_t paused_version = held.version;
  std::this_thread::sleep_for(30ms);
  EXPECT_EQ(models.read().value->version, paused_version);
  thread.resume();
  EXPECT_TRUE(wait_for([&] { return thread.status().sim_time_s > t_paused; }));
}

// The unloaded cantilever with a tool: it stands still, so where its
// surface is does not depend on when the thread is paused.
scene::Scene resting_cantilever_with_tool() {
  scene::Scene s = cantilever_with_tool();
  s.loads.clear();
  return s;
}

haptics::ToolSample hovering_at(const haptics::Vec3& at_m) {
  haptics::ToolSample s;
  s.proxy_position_m = at_m;
  s.device_position_m = at_m;
  return s;
}

// Distance from `at_m` to the nearest triangle of the model's patch.
double patch_distance_m(const haptics::LocalModel& m, const haptics::Vec3& at_m) {
  double nearest_m = std::numeric_limits<double>::infinity();
  for (int t = 0; t < m.triangle_count; ++t) {
    const auto& tr = m.triangle[t];
    const haptics::TriangleClosest c =
        haptics::closest_point_on_triangle(at_m, m.vertex_m[tr[0]], m.vertex_m[tr[1]], m.vertex_m[tr[2]]);
    nearest_m = std::min(nearest_m, (c.point_m - at_m).norm());
  }
  return nearest_m;
}

// "pause: the haptic loop keeps rendering the frozen model" means the frozen
// object, wherever the hand goes: the patch follows the tool over the frozen
// surface. It stayed around where the tool was at the pause, so touching the
// object 50 mm away met the old patch's edge (3 N sideways at max_force_N).
// The frozen surface is a rigid wall (no force reference, no velocities):
// the paused body is not pushed, so it must not feel as if it yields.
TEST(SimThread, WhilePausedTheModelFollowsTheToolOverTheFrozenSurface) {
  ToolSampleRing samples;
  LocalModelChannel models;
  SimThread thread(std::make_unique<SimRunner>(resting_cantilever_with_tool()), &samples, &models, fast_status());
  // 5 mm above the top face (z = 0.1 m), within engage distance.
  const haptics::Vec3 at_pause_m(0.02, 0.05, 0.105), later_m(0.07, 0.05, 0.105);
  ASSERT_TRUE(samples.try_push(hovering_at(at_pause_m)));
  thread.start();
  ASSERT_TRUE(wait_for([&] { return thread.status().samples >= 1 && thread.status().steps > 5; }));
  thread.pause();
  ASSERT_TRUE(wait_for([&] { return thread.status().paused; }));
  std::this_thread::sleep_for(20ms);
  const haptics::LocalModel at_pause = *models.read().value;
  const double t_paused = thread.status().sim_time_s;
  ASSERT_LT(patch_distance_m(at_pause, at_pause_m), 0.006);
  // The pause-time patch does not reach the surface under the new position.
  ASSERT_GT(patch_distance_m(at_pause, later_m), 0.006);

  ASSERT_TRUE(samples.try_push(hovering_at(later_m)));
  const auto follows = [&] { return patch_distance_m(*models.read().value, later_m) < 0.006; };
  const bool followed = wait_for(follows, 1000ms);
  const haptics::LocalModel later = *models.read().value;
  thread.stop();
  EXPECT_TRUE(followed) << "the patch's nearest triangle is " << patch_distance_m(later, later_m)
                        << " m from the tool, 0.005 m above the surface (patch_radius_m 0.02)";
  EXPECT_GT(later.version, at_pause.version);
  EXPECT_EQ(later.sim_time_s, t_paused);  // rebuilt, not stepped
  EXPECT_EQ(thread.status().sim_time_s, t_paused);
  EXPECT_FALSE(later.in_contact);
  EXPECT_EQ(later.force_ref_N, haptics::Vec3::Zero());
  for (int i = 0; i < later.vertex_count; ++i)
    EXPECT_EQ(later.vertex_velocity_m_per_s[i], haptics::Vec3::Zero()) << "vertex " << i;
}

// A reset / load / set while paused hands the haptic side the new scene's
// first model at once: it rendered the old scene's model until that went
// stale, and safety then ramped the force out and recorded a false trip.
TEST(SimThread, ANewRunnerWhilePausedPublishesItsFirstModel) {
  ToolSampleRing samples;
  LocalModelChannel models;
  SimThread thread(std::make_unique<SimRunner>(cantilever_with_tool()), &samples, &models, fast_status());
  ASSERT_TRUE(samples.try_push(hovering_over_the_free_end()));
  thread.start();
  ASSERT_TRUE(wait_for([&] { return thread.status().samples >= 1 && thread.status().sim_time_s > 0.02; }));
  thread.pause();
  ASSERT_TRUE(wait_for([&] { return thread.status().paused; }));
  std::this_thread::sleep_for(20ms);
  const std::uint64_t old_version = models.read().value->version;
  thread.replace_runner(std::make_unique<SimRunner>(cantilever_with_tool()));
  const double stale_model_s = config::ForceLimits{}.stale_model_s;
  std::this_thread::sleep_for(std::chrono::duration<double>(3.0 * stale_model_s));
  const haptics::LocalModel model = *models.read().value;
  const std::int64_t age_ns = now_ns() - model.built_ns;
  const SimStatus status = thread.status();
  thread.stop();
  EXPECT_EQ(status.generation, 1u);
  EXPECT_TRUE(status.paused);
  EXPECT_GT(model.version, old_version) << "the haptic side still holds the old scene's model";
  EXPECT_EQ(model.sim_time_s, 0.0);  // the new runner's, not stepped
  EXPECT_GT(model.triangle_count, 0);
  EXPECT_LT(age_ns, static_cast<std::int64_t>(stale_model_s * 1e9)) << "the model went stale";
}

// A tick pressing on the first triangle of `model`, rendered against it.
haptics::ToolSample press(const haptics::LocalModel& model) {
  haptics::ToolSample s;
  const auto& tr = model.triangle[0];
  s.contact = true;
  s.model_version = model.version;
  s.contact_node = {model.vertex_node[tr[0]], model.vertex_node[tr[1]], model.vertex_node[tr[2]]};
  s.contact_weight = {1.0 / 3, 1.0 / 3, 1.0 / 3};
  s.proxy_position_m = (model.vertex_m[tr[0]] + model.vertex_m[tr[1]] + model.vertex_m[tr[2]]) / 3.0;
  s.device_position_m = s.proxy_position_m;
  s.force_on_object_N = haptics::Vec3(0.0, 0.0, -2.0);
  s.force_on_device_N = -s.force_on_object_N;
  return s;
}

// Ticks rendered against the old runner's model name the old mesh's nodes.
// Drained after a reset / load / set, they must not push on the new mesh
// (same ids, other nodes or none): the new runner starts untouched. They are
// still recorded as rendered: the device was touching (the recorded contact
// column said 0 for them).
TEST(SimThread, TicksRenderedBeforeANewRunnerPushNothingOnIt) {
  const tissue::testing::TempDir scratch;
  const std::string& dir = scratch.path();
  ToolSampleRing samples;
  LocalModelChannel models;
  SimThreadOptions options;
  options.status_every_s = 0.002;
  scene::Scene scene = cantilever_with_tool();
  scene.loads.clear();
  SimThread thread(std::make_unique<SimRunner>(scene), &samples, &models, options);
  auto recorder = record::Recorder::start(dir, "masked.h5", record::SessionMetadata{});
  ASSERT_TRUE(thread.set_recorder(recorder.get()));
  thread.start();
  ASSERT_TRUE(wait_for([&] { return models.read().value->version > 0; }));
  const haptics::LocalModel model = *models.read().value;
  const haptics::ToolSample pressed = press(model);
  // The press is real: on the runner it was rendered against, it pushes.
  ASSERT_TRUE(samples.try_push(pressed));
  ASSERT_TRUE(wait_for([&] { return thread.status().tool_pushing; }));
  // Hold the thread between a drain and its step, queue the same press and
  // a new runner: the next loop takes the runner first, then drains the press.
  thread.inject_stall(300ms);
  std::this_thread::sleep_for(50ms);
  for (int i = 0; i < 3; ++i) ASSERT_TRUE(samples.try_push(pressed));
  thread.replace_runner(std::make_unique<SimRunner>(scene));
  ASSERT_TRUE(wait_for([&] { return thread.status().generation == 1 && thread.status().steps >= 3; }));
  const SimStatus st = thread.status();
  ASSERT_TRUE(thread.set_recorder(nullptr));
  thread.stop();
  recorder->stop();
  EXPECT_FALSE(st.tool_pushing);
  EXPECT_EQ(st.tool_force_N, (std::array<double, 3>{0.0, 0.0, 0.0}));

  const hid_t file = H5Fopen((dir + "/masked.h5").c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  ASSERT_GE(file, 0);
  const std::vector<std::uint8_t> contact = record::testing::read_u8(file, "/haptic/contact");
  H5Fclose(file);
  ASSERT_EQ(contact.size(), 4u);  // the four presses, nothing else was pushed
  for (std::size_t i = 0; i < contact.size(); ++i) EXPECT_EQ(int{contact[i]}, 1) << "press " << i;
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

// A step that throws (std::bad_alloc while refining, a broken mesh
// invariant) halts the runner instead of ending the daemon through
// std::terminate: the thread keeps publishing status with the reason, stops
// stepping the half-changed state, publishing models from it and recording
// sim rows from it (haptic rows still go in), and a new runner starts afresh.
TEST(SimThread, AStepThatThrowsHaltsTheRunnerAndTheThreadKeepsServing) {
  const tissue::testing::TempDir scratch;
  const std::string& dir = scratch.path();
  record::RecorderOptions recording;
  recording.flush_interval_s = 0.01;  // rows are written (and counted) within 10 ms of their push
  auto recorder = record::Recorder::start(dir, "halt.h5", record::SessionMetadata{}, recording);
  ToolSampleRing samples;
  LocalModelChannel models;
  SimThreadOptions options;
  options.status_every_s = 0.002;
  SimThread thread(std::make_unique<SimRunner>(cantilever_with_tool()), &samples, &models, options);
  thread.start();
  ASSERT_TRUE(thread.set_recorder(recorder.get()));
  const auto feed = [&](std::chrono::milliseconds how_long) { hover_over_the_top_face(samples, how_long); };
  ASSERT_TRUE(wait_for([&] { return thread.status().steps > 20 && models.read().value->version > 0; }));
  EXPECT_FALSE(thread.status().halted);

  thread.inject_step_exception();
  EXPECT_TRUE(wait_for([&] { return thread.status().halted; }));
  const SimStatus at_halt = thread.status();
  const haptics::LocalModel model_at_halt = *models.read().value;
  feed(100ms);  // what was pushed before the halt is written
  const record::RecorderStats rows_at_halt = recorder->stats();
  feed(200ms);
  const SimStatus later = thread.status();
  EXPECT_TRUE(later.halted);
  EXPECT_NE(std::string(later.last_error).find("injected step fault"), std::string::npos) << later.last_error;
  EXPECT_NE(std::string(later.last_error).find("reset or load a scene"), std::string::npos) << later.last_error;
  EXPECT_EQ(later.steps, at_halt.steps);                     // not stepped again
  EXPECT_EQ(later.sim_time_s, at_halt.sim_time_s);           // time stands
  EXPECT_GT(later.failed_steps, at_halt.failed_steps + 20);  // every step it cannot take fails, with the reason
  EXPECT_FALSE(later.tool_pushing);
  // The haptic side sees the model stop refreshing (it ramps its force out).
  const haptics::LocalModel model_later = *models.read().value;
  EXPECT_EQ(model_later.version, model_at_halt.version);
  EXPECT_EQ(model_later.built_ns, model_at_halt.built_ns);
  // Recording: the device's rows still go in, the halted sim's do not.
  ASSERT_TRUE(thread.set_recorder(nullptr));
  const record::RecorderStats rows_later = recorder->stats();
  EXPECT_EQ(rows_later.sim_rows_written, rows_at_halt.sim_rows_written);
  EXPECT_EQ(rows_later.sim_drops, rows_at_halt.sim_drops);
  EXPECT_GT(rows_later.haptic_rows_written, rows_at_halt.haptic_rows_written + 20);

  thread.replace_runner(std::make_unique<SimRunner>(cantilever_with_tool()));
  EXPECT_TRUE(wait_for([&] { return thread.status().generation == 1 && thread.status().steps > 20; }));
  const SimStatus fresh = thread.status();
  EXPECT_FALSE(fresh.halted);
  EXPECT_STREQ(fresh.last_error, "");
  EXPECT_TRUE(wait_for([&] { return models.read().value->version > model_at_halt.version; }));
  const std::int64_t failed = thread.status().failed_steps;
  feed(50ms);
  EXPECT_EQ(thread.status().failed_steps, failed);  // the new runner steps
  thread.stop();
  recorder->stop();
}

// The explicit rung's energy bound refuses a step as its sub-step cap does:
// the thread neither spins nor halts. Each refused step is counted with its
// reason, at the thread's pace, time stands, models keep being built from
// the state kept, and a new runner steps again.
TEST(SimThread, AStepRefusedAtTheExplicitEnergyBoundIsCountedAtThePaceAndTheThreadKeepsServing) {
  scene::Scene s = cantilever_with_tool();
  s.integrator.kind = scene::IntegratorKind::kExplicit;
  s.material.rayleigh_beta_s = 0.0;           // undamped: its energy swings by up to ~0.1 of the budget
  s.integrator.explicit_energy_slack = 1e-3;  // so the bound refuses within a few steps
  ToolSampleRing samples;
  LocalModelChannel models;
  SimThreadOptions options;
  options.status_every_s = 0.002;
  SimThread thread(std::make_unique<SimRunner>(s), &samples, &models, options);
  thread.start();
  const auto feed = [&](std::chrono::milliseconds how_long) { hover_over_the_top_face(samples, how_long); };
  ASSERT_TRUE(wait_for([&] { return thread.status().failed_steps > 0; })) << thread.status().steps << " steps";
  const SimStatus first = thread.status();
  const std::uint64_t version = models.read().value->version;
  const auto t0 = std::chrono::steady_clock::now();
  feed(200ms);
  const double wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const SimStatus later = thread.status();
  EXPECT_FALSE(later.halted);
  EXPECT_NE(std::string(later.last_error).find("integrator.explicit_energy_slack = 0.001"), std::string::npos)
      << later.last_error;
  // Whole, with its advice: the status's buffer cut it at 255 characters.
  EXPECT_NE(std::string(later.last_error).find("or use the implicit integrator"), std::string::npos)
      << later.last_error;
  EXPECT_EQ(later.steps, first.steps);  // refused again at every try: time stands
  EXPECT_EQ(later.sim_time_s, first.sim_time_s);
  // Paced: about one try per dt (1 ms), not a spin (generous: shared machine).
  EXPECT_GT(later.failed_steps, first.failed_steps + 20);
  EXPECT_LT(static_cast<double>(later.failed_steps - first.failed_steps), 1e3 * wall_s * 1.5 + 10);
  EXPECT_GT(models.read().value->version, version);  // models still built, from the state kept

  thread.replace_runner(std::make_unique<SimRunner>(cantilever_with_tool()));
  EXPECT_TRUE(wait_for([&] { return thread.status().generation == 1 && thread.status().steps > 20; }));
  EXPECT_STREQ(thread.status().last_error, "");
  thread.stop();
}

// The haptic rows drained in the loop whose step throws are written like
// any others: they were recorded only after the step, inside the exception
// barrier, so the throw lost them.
TEST(SimThread, HapticRowsDrainedInALoopWhoseStepThrowsAreRecorded) {
  const tissue::testing::TempDir scratch;
  const std::string& dir = scratch.path();
  ToolSampleRing samples;
  LocalModelChannel models;
  SimThread thread(std::make_unique<SimRunner>(cantilever_with_tool()), &samples, &models, fast_status());
  auto recorder = record::Recorder::start(dir, "thrown.h5", record::SessionMetadata{});
  ASSERT_TRUE(thread.set_recorder(recorder.get()));
  // Queued before the thread starts, so its first loop drains them all,
  // and that loop's step throws.
  std::vector<double> pushed_s;
  const std::int64_t t0_ns = now_ns();
  for (int k = 0; k < 10; ++k) {
    haptics::ToolSample s = hovering_over_the_free_end();
    s.time_ns = t0_ns + k * 1000000;
    ASSERT_TRUE(samples.try_push(s));
    pushed_s.push_back(recorder->session_time_s(s.time_ns));
  }
  thread.inject_step_exception();
  thread.start();
  ASSERT_TRUE(wait_for([&] { return thread.status().halted; }));
  ASSERT_TRUE(thread.set_recorder(nullptr));
  thread.stop();
  recorder->stop();
  const hid_t file = H5Fopen((dir + "/thrown.h5").c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  ASSERT_GE(file, 0);
  const std::vector<double> recorded_s = record::testing::read_f64(file, "/haptic/time_s");
  H5Fclose(file);
  EXPECT_EQ(recorded_s, pushed_s);
}

// Each tick's device_fresh (a new device sample accepted that tick) is
// recorded as its row's /haptic/device_fresh: the replay device spreads each
// step over the time since the row before that had one.
TEST(SimThread, EachTicksDeviceFreshFlagIsRecorded) {
  const tissue::testing::TempDir scratch;
  const std::string& dir = scratch.path();
  ToolSampleRing samples;
  LocalModelChannel models;
  SimThread thread(std::make_unique<SimRunner>(cantilever_with_tool()), &samples, &models, fast_status());
  auto recorder = record::Recorder::start(dir, "fresh.h5", record::SessionMetadata{});
  ASSERT_TRUE(thread.set_recorder(recorder.get()));
  std::vector<std::uint8_t> pushed;
  const std::int64_t t0_ns = now_ns();
  for (int k = 0; k < 40; ++k) {
    haptics::ToolSample s = hovering_over_the_free_end();
    s.time_ns = t0_ns + k * 1000000;
    s.device_fresh = k % 4 == 1 || k == 6;  // a 250 Hz device, and one stray
    ASSERT_TRUE(samples.try_push(s));
    pushed.push_back(s.device_fresh ? 1 : 0);
  }
  thread.start();
  ASSERT_TRUE(wait_for([&] { return samples.size() == 0; }));
  ASSERT_TRUE(thread.set_recorder(nullptr));
  thread.stop();
  recorder->stop();
  EXPECT_EQ(record::read_haptic_track(dir + "/fresh.h5").device_fresh, pushed);
}

// The status carries the solver's work: CG iterations per step and the
// steps that stopped at cg_max_iterations (none with the shipped tolerance;
// every one when one iteration must reach 1e-12).
TEST(SimThread, StatusCarriesTheSolverWork) {
  SimThreadOptions options;
  options.status_every_s = 0.005;
  options.pace = false;
  for (const bool capped : {false, true}) {
    scene::Scene s = physics::testing::cantilever_scene();
    if (capped) {
      s.integrator.cg_max_iterations = 1;
      s.integrator.cg_tolerance = 1e-12;
    }
    SimThread thread(std::make_unique<SimRunner>(s), nullptr, nullptr, options);
    thread.start();
    ASSERT_TRUE(wait_for([&] { return thread.status().steps > 20; }));
    thread.stop();
    const SimStatus st = thread.status();
    EXPECT_EQ(st.substeps_per_step, 1.0);
    EXPECT_STREQ(st.integrator, "implicit");
    if (capped) {
      EXPECT_EQ(st.solver_iterations_per_step, 1.0);
      EXPECT_EQ(st.unconverged_steps, st.steps);
    } else {
      EXPECT_GT(st.solver_iterations_per_step, 1.0);
      EXPECT_EQ(st.unconverged_steps, 0);
    }
  }
}

// The status names the rung that runs, as the batch report does: here the
// explicit one in single precision, with its sub-steps.
TEST(SimThread, StatusNamesTheIntegrator) {
  SimThreadOptions options;
  options.status_every_s = 0.005;
  options.pace = false;
  scene::Scene s = physics::testing::cantilever_scene();
  s.integrator.kind = scene::IntegratorKind::kExplicit;
  s.integrator.explicit_precision = scene::ExplicitPrecision::kFloat;
  SimThread thread(std::make_unique<SimRunner>(s), nullptr, nullptr, options);
  thread.start();
  ASSERT_TRUE(wait_for([&] { return thread.status().steps > 5; }));
  thread.stop();
  const SimStatus st = thread.status();
  EXPECT_STREQ(st.integrator, "explicit float");
  EXPECT_GT(st.substeps_per_step, 1.0);
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

// Stall injection: the sim thread blocks for 400 ms with the user pressing.
// The haptic thread keeps its rate, the force never exceeds its limits nor
// changes faster than the rate limit, ramps out on the stale model and comes
// back once the sim does.
TEST(SimThread, AStallKeepsTheHapticRateAndRampsTheForceOut) {
  scene::Scene s = cantilever_with_tool();
  s.loads.clear();
  config::DeviceSpec device_spec;
  device_spec.sim.mode = config::SimDeviceSpec::Mode::kHand;
  // From 10 mm above the top face to 6 mm into it, then held.
  device_spec.sim.waypoints = {{0.0, {0.05, 0.05, 0.11}}, {0.3, {0.05, 0.05, 0.094}}};
  device_spec.limits.ramp_in_s = 0.1;
  config::HapticSpec haptic_spec;
  config::RealtimeSpec realtime;
  realtime.sched_fifo = false;
  realtime.lock_memory = false;

  auto samples = std::make_unique<ToolSampleRing>();
  auto models = std::make_unique<LocalModelChannel>();
  haptics::SimDevice device(device_spec.sim);
  std::string error;
  ASSERT_TRUE(device.start(&error)) << error;
  haptics::HapticLoop loop(device, device_spec, haptic_spec, *models, *samples);
  haptics::HapticThread haptic(loop, haptic_spec, realtime);
  SimThread sim(std::make_unique<SimRunner>(s), samples.get(), models.get(), SimThreadOptions{});
  sim.start();
  ASSERT_TRUE(haptic.start(&error)) << error;
  ASSERT_TRUE(wait_for([&] { return loop.stats().contact && loop.stats().force_N > 0.1; }, 3000ms));

  const std::uint64_t stale_before = loop.stats().stale_model_trips;
  const std::uint64_t ticks_before = loop.stats().ticks;
  const auto t0 = std::chrono::steady_clock::now();
  sim.inject_stall(400ms);
  double last_force = loop.stats().force_N, worst_jump_N_per_s = 0.0, peak = 0.0;
  auto last_t = t0;
  while (std::chrono::steady_clock::now() - t0 < 380ms) {
    std::this_thread::sleep_for(1ms);
    const auto now = std::chrono::steady_clock::now();
    const double f = loop.stats().force_N, dt = std::chrono::duration<double>(now - last_t).count();
    worst_jump_N_per_s = std::max(worst_jump_N_per_s, std::abs(f - last_force) / dt);
    peak = std::max(peak, f);
    last_force = f;
    last_t = now;
  }
  const std::uint64_t ticks = loop.stats().ticks - ticks_before;
  EXPECT_GT(ticks, 200u);  // ~380 expected; generous for a shared machine and sanitizers
  EXPECT_LE(peak, device_spec.limits.max_force_N + 1e-9);
  // The stats are read from another thread between ticks: allow one tick of
  // slack on the measured interval.
  EXPECT_LE(worst_jump_N_per_s, 2.0 * device_spec.limits.max_force_rate_N_per_s);
  EXPECT_GT(loop.stats().stale_model_trips, stale_before);
  EXPECT_LT(loop.stats().force_N, 0.05);  // ramped out while the model was stale
  // The sim is back: contact force returns.
  EXPECT_TRUE(wait_for([&] { return loop.stats().force_N > 0.1; }, 3000ms));
  haptic.request_stop();
  haptic.join();
  sim.stop();
  EXPECT_EQ(loop.stats().force_N, 0.0);
}

// The surface snapshot for readers off the hot threads: published at its
// rate, consistent (indices in range, one level per vertex), moving on.
TEST(SimThread, PublishesSurfaceSnapshots) {
  SimThreadOptions options;
  options.snapshot_every_s = 0.01;
  SimThread thread(std::make_unique<SimRunner>(physics::testing::cantilever_scene()), nullptr, nullptr, options);
  EXPECT_EQ(thread.snapshot().sequence, 0u);
  thread.start();
  ASSERT_TRUE(wait_for([&] { return thread.snapshot().sequence > 0; }));
  const MeshSnapshot first = thread.snapshot();
  ASSERT_TRUE(wait_for([&] { return thread.snapshot().sequence > first.sequence + 3; }));
  const MeshSnapshot& s = thread.snapshot();
  EXPECT_GT(s.sim_time_s, first.sim_time_s);
  ASSERT_FALSE(s.triangles.empty());
  EXPECT_EQ(s.vertex_level.size(), s.vertices_m.size());
  for (const auto& t : s.triangles)
    for (std::uint32_t v : t) EXPECT_LT(v, s.vertices_m.size());
  thread.stop();
}

// A sim thread stalled through a recorder hand-over: set_recorder gives up
// after its bound and says so (the caller must keep the old recorder alive),
// and once the sim thread moves again a hand-over completes. While stalled
// the old recorder is still the one the thread holds, so it must stay valid;
// stopped, it refuses what the thread pushes instead of writing it.
TEST(SimThread, RecorderHandOverReportsAStalledSimThread) {
  const tissue::testing::TempDir scratch;
  const std::string& dir = scratch.path();
  auto recorder = record::Recorder::start(dir, "handover.h5", record::SessionMetadata{});
  SimThreadOptions options;
  SimThread thread(std::make_unique<SimRunner>(physics::testing::cantilever_scene()), nullptr, nullptr, options);
  thread.start();
  ASSERT_TRUE(thread.set_recorder(recorder.get()));
  thread.inject_stall(3000ms);
  std::this_thread::sleep_for(100ms);  // the stall has begun (steps are 1 ms apart)
  const auto t0 = std::chrono::steady_clock::now();
  EXPECT_FALSE(thread.set_recorder(nullptr, 0.05));
  EXPECT_LT(std::chrono::steady_clock::now() - t0, 600ms);  // bounded by the wait asked for
  // The default wait gives up well inside the watchdog's margin (the io
  // thread calls this and feeds the watchdog: 5 s in the unit, fed every
  // 2.5 s), not after the stall.
  const auto t1 = std::chrono::steady_clock::now();
  EXPECT_FALSE(thread.set_recorder(nullptr));
  EXPECT_LT(std::chrono::steady_clock::now() - t1, 2000ms);
  recorder->stop();                                 // the file closes; the stalled thread still holds the recorder
  EXPECT_TRUE(thread.set_recorder(nullptr, 10.0));  // the stall ends, the thread lets go
  thread.stop();
  EXPECT_TRUE(thread.set_recorder(nullptr, 0.0));  // a stopped thread holds nothing
}

// A hand-over from one recorder to the next (a rotation, a record_start)
// loses no row: tool samples numbered 0, 1, 2, … (in device x) pushed
// without pause through the switch all land in one file or the other, each
// once. (Stopping the old recorder before the new one was in, the samples
// the sim thread drained in between were in neither file.)
TEST(SimThread, AHandOverBetweenRecordersLosesNoRow) {
  const tissue::testing::TempDir scratch;
  const std::string& dir = scratch.path();
  ToolSampleRing samples;
  LocalModelChannel models;
  SimThread thread(std::make_unique<SimRunner>(cantilever_with_tool()), &samples, &models, SimThreadOptions{});
  thread.start();
  std::unique_ptr<record::Recorder> current;
  std::vector<std::unique_ptr<record::Recorder>> retired;
  hand_over_recorder(&thread, current, record::Recorder::start(dir, "a.h5", record::SessionMetadata{}), retired);
  std::atomic<bool> stop_pushing{false};
  std::atomic<int> pushed{0};
  std::thread producer([&] {
    haptics::ToolSample s;
    for (int k = 0; !stop_pushing.load(); ++k) {
      s.time_ns = now_ns();
      s.device_position_m = haptics::Vec3(k, 0.0, 0.0);
      while (!samples.try_push(s)) std::this_thread::yield();  // never dropped at the ring
      pushed.store(k + 1);
      std::this_thread::sleep_for(200us);
    }
  });
  ASSERT_TRUE(wait_for([&] { return pushed.load() >= 200; }));
  hand_over_recorder(&thread, current, record::Recorder::start(dir, "b.h5", record::SessionMetadata{}), retired);
  const int at_hand_over = pushed.load();
  ASSERT_TRUE(wait_for([&] { return pushed.load() >= at_hand_over + 200; }));
  stop_pushing.store(true);
  producer.join();
  ASSERT_TRUE(wait_for([&] { return samples.size() == 0; }));
  hand_over_recorder(&thread, current, nullptr, retired);  // after the thread took the last samples
  thread.stop();
  EXPECT_TRUE(retired.empty());
  std::vector<int> seen;
  for (const char* name : {"a.h5", "b.h5"})
    for (const auto& p : record::read_haptic_track(dir + "/" + name).device_position_m)
      seen.push_back(static_cast<int>(p[0]));
  std::sort(seen.begin(), seen.end());
  ASSERT_EQ(seen.size(), static_cast<std::size_t>(pushed.load())) << "rows lost (or doubled) at the hand-over";
  for (int k = 0; k < pushed.load(); ++k) ASSERT_EQ(seen[static_cast<std::size_t>(k)], k);
}

// A scene change while recording hands the new runner and its recorder over
// together: while the sim thread stalls the hand-over times out (the caller
// keeps the recorder before alive), and once it moves again it takes both:
// the new runner's rows go to the new recorder.
TEST(SimThread, ARunnerWithItsRecorderIsTakenAfterAStallItTimedOutOn) {
  const tissue::testing::TempDir scratch;
  const std::string& dir = scratch.path();
  auto before = record::Recorder::start(dir, "before.h5", record::SessionMetadata{});
  auto after = record::Recorder::start(dir, "after.h5", record::SessionMetadata{});
  SimThread thread(std::make_unique<SimRunner>(physics::testing::cantilever_scene()), nullptr, nullptr,
                   SimThreadOptions{});
  thread.start();
  ASSERT_TRUE(thread.set_recorder(before.get()));
  thread.inject_stall(1000ms);
  std::this_thread::sleep_for(100ms);  // the stall has begun (steps are 1 ms apart)
  EXPECT_FALSE(
      thread.replace_runner(std::make_unique<SimRunner>(physics::testing::cantilever_scene()), after.get(), 0.05));
  EXPECT_EQ(thread.status().generation, 0u);  // not taken yet
  ASSERT_TRUE(wait_for([&] { return thread.status().generation == 1 && thread.status().steps >= 20; }));
  ASSERT_TRUE(thread.set_recorder(nullptr, 10.0));
  thread.stop();
  before->stop();
  after->stop();
  EXPECT_GE(after->stats().sim_rows_written, 20u);  // the new runner's rows, in the new file
}

// Two scene changes during one stall (load_scene A times out, load_scene B
// comes before the step ends): the second replaces the first while pending,
// and the sim thread takes one runner for both. A later hand-over completes
// as soon as the thread takes it. (Counting the runners taken, one behind the
// hand-overs for good, every later one waited its whole wait and failed.)
TEST(SimThread, TwoHandOversDuringOneStallLeaveTheNextOnePrompt) {
  const tissue::testing::TempDir scratch;
  const std::string& dir = scratch.path();
  auto r0 = record::Recorder::start(dir, "r0.h5", record::SessionMetadata{});
  auto r1 = record::Recorder::start(dir, "r1.h5", record::SessionMetadata{});
  auto r2 = record::Recorder::start(dir, "r2.h5", record::SessionMetadata{});
  auto r3 = record::Recorder::start(dir, "r3.h5", record::SessionMetadata{});
  SimThread thread(std::make_unique<SimRunner>(physics::testing::cantilever_scene()), nullptr, nullptr,
                   SimThreadOptions{});
  thread.start();
  ASSERT_TRUE(thread.set_recorder(r0.get()));
  thread.inject_stall(1000ms);
  std::this_thread::sleep_for(100ms);  // the stall has begun
  EXPECT_FALSE(
      thread.replace_runner(std::make_unique<SimRunner>(physics::testing::cantilever_scene()), r1.get(), 0.05));
  EXPECT_FALSE(
      thread.replace_runner(std::make_unique<SimRunner>(physics::testing::cantilever_scene()), r2.get(), 0.05));
  ASSERT_TRUE(wait_for([&] { return thread.status().generation == 1; }));  // the stall has ended
  // 2 s: far more than a step takes, a hand-over that waits it out has failed.
  EXPECT_TRUE(thread.replace_runner(std::make_unique<SimRunner>(physics::testing::cantilever_scene()), r3.get(), 2.0));
  ASSERT_TRUE(thread.set_recorder(nullptr, 10.0));
  thread.stop();
  for (auto* r : {r0.get(), r1.get(), r2.get(), r3.get()}) r->stop();
  EXPECT_EQ(r1->stats().sim_rows_written, 0u);  // replaced before the thread took it
}

// set_recorder(nullptr) (record_stop) while a runner handed over with a
// recorder is still pending: the recorder goes with it, the thread never
// pushes to it (the caller stops and frees it).
TEST(SimThread, StoppingRecordingWhileARunnerWithARecorderIsPendingDropsThatRecorder) {
  const tissue::testing::TempDir scratch;
  const std::string& dir = scratch.path();
  ToolSampleRing samples;
  auto pending = record::Recorder::start(dir, "pending.h5", record::SessionMetadata{});
  SimThread thread(std::make_unique<SimRunner>(cantilever_with_tool()), &samples, nullptr, SimThreadOptions{});
  thread.start();
  thread.inject_stall(500ms);
  std::this_thread::sleep_for(100ms);  // the stall has begun
  EXPECT_FALSE(thread.replace_runner(std::make_unique<SimRunner>(cantilever_with_tool()), pending.get(), 0.05));
  EXPECT_FALSE(thread.set_recorder(nullptr, 0.05));
  // Ticks drained after the switch would be haptic rows in `pending`.
  haptics::ToolSample s;
  for (int i = 0; i < 5; ++i) {
    s.time_ns = now_ns();
    ASSERT_TRUE(samples.try_push(s));
  }
  ASSERT_TRUE(wait_for([&] { return thread.status().generation == 1 && thread.status().steps >= 20; }));
  ASSERT_TRUE(wait_for([&] { return samples.size() == 0; }));
  EXPECT_TRUE(thread.set_recorder(nullptr, 10.0));
  thread.stop();
  pending->stop();
  EXPECT_EQ(pending->stats().sim_rows_written, 0u);
  EXPECT_EQ(pending->stats().haptic_rows_written, 0u);
}

// Status at 200 Hz, energies at 4 Hz: the energies in consecutive statuses
// repeat between refreshes while time moves on (the loaded cantilever's
// kinetic energy changes every step, so fresh sums would all differ).
TEST(SimThread, EnergiesRefreshAtTheirOwnRate) {
  const auto distinct_energies = [](double energy_every_s, std::size_t* statuses) {
    SimThreadOptions options;
    options.status_every_s = 0.005;
    options.energy_every_s = energy_every_s;
    SimThread thread(std::make_unique<SimRunner>(physics::testing::cantilever_scene()), nullptr, nullptr, options);
    thread.start();
    std::vector<double> kinetic, times;
    const auto end = std::chrono::steady_clock::now() + 400ms;
    while (std::chrono::steady_clock::now() < end) {
      const SimStatus s = thread.status();
      if (times.empty() || s.sim_time_s != times.back()) {
        times.push_back(s.sim_time_s);
        kinetic.push_back(s.kinetic_energy_J);
        // The energies say when they were summed: never later than the
        // status, and exactly then when summed for every status.
        EXPECT_LE(s.energy_sim_time_s, s.sim_time_s);
        if (energy_every_s == 0.0) {
          EXPECT_EQ(s.energy_sim_time_s, s.sim_time_s);
        }
      }
      std::this_thread::sleep_for(1ms);
    }
    thread.stop();
    *statuses = times.size();
    std::sort(kinetic.begin(), kinetic.end());
    return static_cast<std::size_t>(std::unique(kinetic.begin(), kinetic.end()) - kinetic.begin());
  };
  std::size_t statuses = 0;
  const std::size_t slow = distinct_energies(0.25, &statuses);
  ASSERT_GE(statuses, 10u);  // statuses kept coming
  EXPECT_LE(slow, 4u);       // 400 ms at 4 Hz: the first sum plus at most two refreshes (and one spare)
  const std::size_t every = distinct_energies(0.0, &statuses);
  ASSERT_GE(statuses, 10u);
  EXPECT_GE(every, statuses / 2);  // summed for every status: the values move
}

}  // namespace
}  // namespace tissue::service
