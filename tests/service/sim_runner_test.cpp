#include "service/sim_runner.hpp"

#include <gtest/gtest.h>

#include <vector>

#include "physics/physics_test_support.hpp"

namespace tissue::service {
namespace {

using physics::Vec3;

scene::Scene cantilever_with_tool() {
  scene::Scene s = physics::testing::cantilever_scene();
  s.loads.clear();
  s.tool = scene::ToolSpec{};
  return s;
}

// A tick pressing on the top-face triangle the runner's first model offers.
haptics::ToolSample press(const haptics::LocalModel& model, const Vec3& force_on_object_N) {
  haptics::ToolSample s;
  const auto& tr = model.triangle[0];
  s.contact = true;
  s.contact_node = {model.vertex_node[tr[0]], model.vertex_node[tr[1]], model.vertex_node[tr[2]]};
  s.contact_weight = {1.0 / 3, 1.0 / 3, 1.0 / 3};
  s.proxy_position_m = (model.vertex_m[tr[0]] + model.vertex_m[tr[1]] + model.vertex_m[tr[2]]) / 3.0;
  s.device_position_m = s.proxy_position_m - Vec3(0, 0, 0.002);
  s.force_on_object_N = force_on_object_N;
  s.force_on_device_N = -force_on_object_N;
  return s;
}

haptics::ToolSample hover(const Vec3& at_m) {
  haptics::ToolSample s;
  s.proxy_position_m = at_m;
  s.device_position_m = at_m;
  return s;
}

TEST(SimRunner, SceneWithoutAToolBuildsNoModel) {
  SimRunner runner(physics::testing::cantilever_scene());
  haptics::LocalModel model;
  const RunnerStep r = runner.step({}, &model);
  EXPECT_TRUE(r.ok);
  EXPECT_FALSE(r.model_built);
  EXPECT_FALSE(r.tool_pushing);
  EXPECT_FALSE(runner.simulation().has_tool());
}

TEST(SimRunner, AppliesTheMeanContactForceAndThePushedPointMoves) {
  SimRunner runner(cantilever_with_tool());
  haptics::LocalModel model;
  const haptics::ToolSample above = hover(Vec3(0.05, 0.05, 0.101));
  ASSERT_TRUE(runner.step(std::span(&above, 1), &model).model_built);
  EXPECT_FALSE(model.in_contact);
  EXPECT_GT(model.contact_stiffness_N_per_m(2, 2), 0.0);  // 1 mm away: engaged

  const std::vector<haptics::ToolSample> ticks{press(model, Vec3(0, 0, -1.0)), press(model, Vec3(0, 0, -3.0))};
  const Vec3 start = ticks[0].proxy_position_m;
  RunnerStep r = runner.step(ticks, &model);
  ASSERT_TRUE(r.ok);
  EXPECT_TRUE(r.tool_pushing);
  EXPECT_EQ(r.samples_used, 2);
  EXPECT_EQ(runner.simulation().tool_force_N(), Vec3(0, 0, -2.0));
  EXPECT_TRUE(model.in_contact);
  EXPECT_EQ(model.force_ref_N, Vec3(0, 0, -2.0));
  for (int i = 0; i < 200; ++i) r = runner.step(std::span(&ticks[1], 1), &model);
  EXPECT_LT(model.position_ref_m.z(), start.z() - 1e-3);  // pushed in by more than a millimetre
}

// Found by the review of the haptic proxy path: the force was the mean of
// the touching ticks only, so one touching tick among four applied its whole
// force for the whole step, four times its impulse. The contact point is
// still the newest touching tick's.
TEST(SimRunner, TicksOffTheObjectCountAsZeroInTheStepsMeanForce) {
  SimRunner runner(cantilever_with_tool());
  haptics::LocalModel model;
  const haptics::ToolSample above = hover(Vec3(0.05, 0.05, 0.101));
  ASSERT_TRUE(runner.step(std::span(&above, 1), &model).model_built);
  const haptics::ToolSample pressing = press(model, Vec3(0, 0, -4.0));
  const std::vector<haptics::ToolSample> ticks{pressing, above, above, above};
  const RunnerStep r = runner.step(ticks, &model);
  ASSERT_TRUE(r.ok);
  EXPECT_TRUE(r.tool_pushing);
  EXPECT_EQ(r.samples_used, 4);
  EXPECT_EQ(runner.simulation().tool_force_N(), Vec3(0, 0, -1.0));
  EXPECT_TRUE(model.in_contact);
  EXPECT_EQ(model.force_ref_N, Vec3(0, 0, -1.0));
  Vec3 pressed_point = Vec3::Zero();
  for (int k = 0; k < 3; ++k)
    pressed_point += pressing.contact_weight[k] * runner.simulation().body().x_m[pressing.contact_node[k]];
  EXPECT_TRUE(model.position_ref_m.isApprox(pressed_point, 1e-12));
}

TEST(SimRunner, NonFiniteSamplesAreIgnoredAndReleaseClearsTheForce) {
  SimRunner runner(cantilever_with_tool());
  haptics::LocalModel model;
  const haptics::ToolSample above = hover(Vec3(0.05, 0.05, 0.101));
  runner.step(std::span(&above, 1), &model);
  haptics::ToolSample bad = press(model, Vec3(0, 0, std::numeric_limits<double>::quiet_NaN()));
  RunnerStep r = runner.step(std::span(&bad, 1), &model);
  EXPECT_FALSE(r.tool_pushing);
  EXPECT_EQ(runner.simulation().tool_force_N(), Vec3::Zero());

  const haptics::ToolSample good = press(model, Vec3(0, 0, -1.0));
  EXPECT_TRUE(runner.step(std::span(&good, 1), &model).tool_pushing);
  // Ticks keep coming but none touches: the tool let go.
  r = runner.step(std::span(&above, 1), &model);
  EXPECT_FALSE(r.tool_pushing);
  EXPECT_FALSE(model.in_contact);
  // No ticks at all (the haptic thread is late): the last force holds.
  EXPECT_TRUE(runner.step(std::span(&good, 1), &model).tool_pushing);
  EXPECT_TRUE(runner.step({}, &model).tool_pushing);
}

}  // namespace
}  // namespace tissue::service
