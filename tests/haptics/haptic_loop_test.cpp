#include "haptics/haptic_loop.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <vector>

#include "haptics/haptics_test_support.hpp"
#include "haptics/sim_device.hpp"

namespace tissue::haptics {
namespace {

using test::kMs;
constexpr double kDt_s = 1e-3;

struct Rig {
  config::DeviceSpec device_spec;
  config::HapticSpec haptic_spec;
  test::ScriptedDevice device;
  std::unique_ptr<LocalModelBuffer> models = std::make_unique<LocalModelBuffer>();
  std::unique_ptr<ToolSampleRing> samples = std::make_unique<ToolSampleRing>();
  std::unique_ptr<HapticLoop> loop;
  std::int64_t now_ns = 1000 * kMs;
  std::uint64_t version = 0;

  void build(Device* dev = nullptr) {
    loop = std::make_unique<HapticLoop>(dev ? *dev : device, device_spec, haptic_spec, *models, *samples);
  }
  void publish(LocalModel m) {
    m.version = ++version;
    m.built_ns = now_ns;
    models->write(m);
  }
  // Advances 1 ms and ticks; returns the force written to the device.
  Vec3 tick() {
    now_ns += kMs;
    loop->tick(now_ns);
    return device.last_force_N;
  }
  void drain() {
    ToolSample s;
    while (samples->try_pop(s)) {
    }
  }
};

// Pressed 2 mm into a flat patch (free approach from above first).
void press(Rig& rig, const LocalModel& model, int ticks) {
  rig.device.position_m = Vec3(0, 0, 0.002);
  rig.publish(model);
  rig.tick();
  rig.device.position_m = Vec3(0, 0, -0.002);
  for (int i = 0; i < ticks; ++i) {
    rig.publish(model);
    rig.tick();
  }
}

// A rig with a 10 ms cross-fade and nothing else smoothing the force,
// pressing 2 mm into a flat patch of 600 N/m for 100 ticks: the patch.
LocalModel pressed_with_only_the_cross_fade(Rig& rig) {
  rig.device_spec.limits.max_force_rate_N_per_s = 1e9;  // isolate the cross-fade
  rig.device_spec.limits.ramp_in_s = 0.01;
  rig.device_spec.limits.stale_model_s = 10.0;
  rig.haptic_spec.crossfade_s = 0.01;
  rig.haptic_spec.coupling_damping_N_s_per_m = 0.0;
  rig.build();
  LocalModel before = test::make_flat_patch();
  test::set_linear_contact(before, 600.0);
  press(rig, before, 100);
  return before;
}

TEST(HapticLoop, CrossFadeBoundsTheForceChangeAtAModelUpdate) {
  Rig rig;
  const LocalModel before = pressed_with_only_the_cross_fade(rig);
  const Vec3 force_before = rig.device.last_force_N;
  // k_v k/(k_v+k) * 2 mm = 240 * 0.002
  ASSERT_NEAR(force_before.z(), 0.48, 1e-9);

  // The sim now pushes 1 N harder: a step in force_ref between two versions.
  LocalModel after = before;
  after.force_ref_N = Vec3(0, 0, -1.0);
  rig.publish(after);
  Vec3 previous = force_before;
  double largest_step_N = 0.0;
  for (int i = 0; i < 30; ++i) {
    const Vec3 f = rig.tick();
    largest_step_N = std::max(largest_step_N, (f - previous).norm());
    previous = f;
  }
  const Vec3 force_after = rig.device.last_force_N;
  const double jump_N = (force_after - force_before).norm();
  EXPECT_GT(jump_N, 0.2);  // the update really changes the force ...
  // ... but never faster than the cross-fade slope.
  EXPECT_LE(largest_step_N, jump_N * kDt_s / rig.haptic_spec.crossfade_s + 1e-9);
  // Steady state is the new model's balance: 400 (x + 0.002) = 1 - 600 x  ->  F = k_v (p - x_dev).
  const double proxy_z = (1.0 - 400.0 * 0.002) / 1000.0;
  EXPECT_NEAR(force_after.z(), 400.0 * (proxy_z + 0.002), 1e-9);
}

TEST(HapticLoop, OverlappingModelUpdatesKeepTheForceContinuous) {
  Rig rig;
  rig.device_spec.limits.max_force_rate_N_per_s = 1e9;
  rig.device_spec.limits.ramp_in_s = 0.01;
  rig.haptic_spec.crossfade_s = 0.01;
  rig.haptic_spec.coupling_damping_N_s_per_m = 0.0;
  rig.build();
  LocalModel m = test::make_flat_patch();
  test::set_linear_contact(m, 600.0);
  press(rig, m, 100);
  // A new version every tick, alternating force_ref by 1 N: the fade restarts
  // every tick from the force actually rendered.
  Vec3 previous = rig.device.last_force_N;
  for (int i = 0; i < 50; ++i) {
    m.force_ref_N = Vec3(0, 0, (i % 2) ? 0.0 : -1.0);
    rig.publish(m);
    const Vec3 f = rig.tick();
    EXPECT_LE((f - previous).norm(), 1.0 * 400.0 / 1000.0 * kDt_s / 0.01 + 1e-9);
    previous = f;
  }
}

// Found by the review of the haptic proxy path: the fade offset of a model
// switch was added whether or not the tool touched anything, so a hand that
// lifted off right after a 1 N update was pushed by the leftover 0.4 N while
// its samples said no contact (and the sim got no reaction).
TEST(HapticLoop, AFreeHandFeelsNoCrossFadeOffset) {
  Rig rig;
  const LocalModel before = pressed_with_only_the_cross_fade(rig);
  ASSERT_NEAR(rig.device.last_force_N.z(), 0.48, 1e-9);
  LocalModel after = before;
  after.force_ref_N = Vec3(0, 0, -1.0);  // the new model's force is 0.4 N higher
  rig.publish(after);
  rig.tick();
  ASSERT_TRUE(rig.loop->last_sample().contact);
  // Lifted clear in one tick (4.5 mm, within max_speed_m_per_s * 1 ms), well
  // above where the new model's force reaches zero (1 N / 600 N/m = 1.7 mm),
  // while the fade has most of its 10 ms to go.
  rig.device.position_m = Vec3(0, 0, 0.0025);
  for (int i = 0; i < 3; ++i) {
    const Vec3 f = rig.tick();
    EXPECT_FALSE(rig.loop->last_sample().contact) << "tick " << i;
    EXPECT_EQ(f, Vec3::Zero()) << "tick " << i;
    EXPECT_EQ(rig.loop->last_sample().force_on_device_N, Vec3::Zero()) << "tick " << i;
  }
}

TEST(HapticLoop, StaleModelRampsTheForceToZeroWithinRampOut) {
  Rig rig;
  rig.build();
  LocalModel m = test::make_flat_patch();
  press(rig, m, 700);  // past the 0.5 s ramp-in
  ASSERT_NEAR(rig.device.last_force_N.z(), 0.8, 1e-6);
  // No more models: after stale_model_s the force ramps out.
  const auto& limits = rig.device_spec.limits;
  Vec3 previous = rig.device.last_force_N;
  int ticks_to_zero = -1;
  const int stale_ticks = static_cast<int>(std::lround(limits.stale_model_s / kDt_s));
  for (int i = 1; i <= stale_ticks + 100; ++i) {
    const Vec3 f = rig.tick();
    EXPECT_LE((f - previous).norm(), limits.max_force_rate_N_per_s * kDt_s + 1e-12);
    previous = f;
    if (ticks_to_zero < 0 && f.isZero(0.0)) ticks_to_zero = i;
  }
  ASSERT_GT(ticks_to_zero, 0);
  EXPECT_LE((ticks_to_zero - stale_ticks) * kDt_s, limits.ramp_out_s + 2 * kDt_s);
  EXPECT_GE(ticks_to_zero, stale_ticks);  // not before the model is stale
  EXPECT_GE(rig.loop->stats().stale_model_trips, 1u);
}

// A paused sim re-publishes the same model (same version) with a newer
// build time: the loop must take it as fresh and keep rendering the frozen
// object. It kept the first build time, tripped "stale model" after
// stale_model_s and ramped the force to zero under a pressing hand.
TEST(HapticLoop, TheSameModelRepublishedStaysFreshAndKeepsPushingBack) {
  Rig rig;
  rig.build();
  LocalModel m = test::make_flat_patch();
  press(rig, m, 700);
  ASSERT_NEAR(rig.device.last_force_N.z(), 0.8, 1e-6);
  m.version = rig.version;  // from here on: the same model, re-affirmed every tick
  const int stale_ticks = static_cast<int>(std::lround(rig.device_spec.limits.stale_model_s / kDt_s));
  for (int i = 0; i < 5 * stale_ticks; ++i) {
    m.built_ns = rig.now_ns;
    rig.models->write(m);
    rig.tick();
  }
  EXPECT_NEAR(rig.device.last_force_N.z(), 0.8, 1e-6);
  EXPECT_EQ(rig.loop->stats().stale_model_trips, 0u);
  EXPECT_EQ(rig.loop->stats().safety_trips, 0u);
  // And once the re-publishing stops, staleness is still seen.
  for (int i = 0; i < stale_ticks + 2; ++i) rig.tick();
  EXPECT_GE(rig.loop->stats().stale_model_trips, 1u);
}

TEST(HapticLoop, DeviceTimeoutRampsTheForceOut) {
  Rig rig;
  rig.device_spec.limits.stale_model_s = 10.0;
  rig.build();
  press(rig, test::make_flat_patch(), 700);
  ASSERT_GT(rig.device.last_force_N.norm(), 0.5);
  rig.device.available = false;
  for (int i = 0; i < 80; ++i) rig.tick();
  EXPECT_TRUE(rig.device.last_force_N.isZero(0.0));
  const HapticStats st = rig.loop->stats();
  EXPECT_EQ(st.missing_samples, 80u);
  EXPECT_EQ(st.device_lost_trips, 1u);
}

// Each tick's sample says whether the device delivered a new sample the loop
// accepted (the session records it, so a replay knows a held pose from a new
// one): not on a tick without one, nor on one whose sample was rejected
// (the tick holds the last accepted pose), but on a re-sent, unchanged pose.
TEST(HapticLoop, EachSampleSaysWhetherANewDeviceSampleWasAccepted) {
  Rig rig;
  rig.device_spec.limits.stale_model_s = 10.0;
  rig.build();
  const auto tick = [&] {
    rig.tick();
    ToolSample s;
    EXPECT_TRUE(rig.samples->try_pop(s));
    return s;
  };
  rig.device.position_m = Vec3(0, 0, 0.01);
  ToolSample s = tick();
  EXPECT_TRUE(s.device_fresh) << "the first sample";
  rig.device.available = false;
  s = tick();
  EXPECT_FALSE(s.device_fresh) << "no sample this tick";
  EXPECT_EQ(s.device_position_m, Vec3(0, 0, 0.01));
  rig.device.available = true;
  rig.device.position_m = Vec3(0, 0, 0.011);
  s = tick();
  EXPECT_TRUE(s.device_fresh) << "a new pose";
  rig.device.position_m = Vec3(0, 0, 0.5);  // 489 mm in 1 ms: too fast
  s = tick();
  EXPECT_FALSE(s.device_fresh) << "a rejected sample";
  EXPECT_EQ(s.device_position_m, Vec3(0, 0, 0.011));
  EXPECT_EQ(rig.loop->stats().rejected_speed, 1u);
  rig.device.position_m = Vec3(0, 0, 0.011);
  s = tick();
  EXPECT_TRUE(s.device_fresh) << "the same pose, sent again";
}

TEST(HapticLoop, NonFiniteAndOutOfRangeInputIsRejectedAndCounted) {
  Rig rig;
  rig.device_spec.limits.stale_model_s = 10.0;
  rig.build();
  press(rig, test::make_flat_patch(), 700);
  const Vec3 good_force = rig.device.last_force_N;
  ASSERT_GT(good_force.norm(), 0.5);

  rig.device.position_m = Vec3(std::nan(""), 0, 0);
  Vec3 f = rig.tick();
  EXPECT_TRUE(f.allFinite());
  EXPECT_TRUE(f.isApprox(good_force, 1e-12));  // the last good sample is held
  rig.device.position_m = Vec3(0, 0, -0.002);
  rig.device.velocity_m_per_s = Vec3(0, INFINITY, 0);
  EXPECT_TRUE(rig.tick().allFinite());
  rig.device.velocity_m_per_s = Vec3(0, 0, 6.0);  // > 5 m/s
  rig.tick();
  rig.device.velocity_m_per_s = Vec3::Zero();
  rig.device.position_m = Vec3(0, 0, -0.05);  // a 48 mm jump in 1 ms: 48 m/s
  rig.tick();
  rig.device.position_m = Vec3(1.5, 0, 0);  // outside the 1 m workspace
  f = rig.tick();
  EXPECT_TRUE(f.isApprox(good_force, 1e-12));
  const HapticStats st = rig.loop->stats();
  EXPECT_EQ(st.rejected_nonfinite, 2u);
  EXPECT_EQ(st.rejected_speed, 2u);
  EXPECT_EQ(st.rejected_workspace, 1u);
  EXPECT_EQ(st.rejected_inputs, 5u);
  // A device that keeps sending garbage times out: force ramps to zero.
  rig.device.position_m = Vec3(std::nan(""), 0, 0);
  for (int i = 0; i < 80; ++i) ASSERT_TRUE(rig.tick().allFinite());
  EXPECT_TRUE(rig.device.last_force_N.isZero(0.0));
}

TEST(HapticLoop, StopAndWatchdogRampOutAndReportStopped) {
  Rig rig;
  rig.device_spec.limits.stale_model_s = 10.0;
  rig.build();
  press(rig, test::make_flat_patch(), 700);
  rig.loop->trip_watchdog();
  for (int i = 0; i < 60; ++i) rig.tick();
  EXPECT_TRUE(rig.device.last_force_N.isZero(0.0));
  EXPECT_FALSE(rig.loop->stopped());  // a watchdog is not a stop
  rig.loop->clear_watchdog();
  for (int i = 0; i < 600; ++i) rig.tick();
  ASSERT_GT(rig.device.last_force_N.norm(), 0.5);  // ramped back in
  rig.loop->request_stop();
  Vec3 previous = rig.device.last_force_N;
  int ticks = 0;
  while (!rig.loop->stopped() && ticks < 1000) {
    const Vec3 f = rig.tick();
    EXPECT_LE((f - previous).norm(), 300.0 * kDt_s + 1e-12);
    previous = f;
    ++ticks;
  }
  EXPECT_TRUE(rig.loop->stopped());
  EXPECT_LE(ticks * kDt_s, rig.device_spec.limits.ramp_out_s + 2 * kDt_s);
  EXPECT_TRUE(rig.device.last_force_N.isZero(0.0));
}

TEST(HapticLoop, SamplesHeartbeatAndRingDrops) {
  Rig rig;
  rig.device_spec.limits.stale_model_s = 10.0;
  rig.build();
  LocalModel m = test::make_flat_patch();
  m.vertex_node[0] = 77;
  press(rig, m, 700);
  const HapticStats st = rig.loop->stats();
  EXPECT_EQ(st.ticks, 701u);
  EXPECT_EQ(st.heartbeat, 701u);
  EXPECT_EQ(st.model_updates, 701u);
  EXPECT_TRUE(st.contact);
  ToolSample s, last;
  std::size_t popped = 0;
  std::uint64_t previous_ns = 0;
  while (rig.samples->try_pop(s)) {
    EXPECT_GT(static_cast<std::uint64_t>(s.time_ns), previous_ns);
    previous_ns = s.time_ns;
    last = s;
    ++popped;
  }
  EXPECT_EQ(popped, 701u);
  EXPECT_TRUE(last.contact);
  EXPECT_TRUE(last.force_on_object_N.isApprox(-last.force_on_device_N, 1e-15));
  EXPECT_NEAR(last.contact_weight[0] + last.contact_weight[1] + last.contact_weight[2], 1.0, 1e-12);
  EXPECT_EQ(last.model_version, rig.version);
  EXPECT_NEAR(last.proxy_position_m.z(), 0.0, 1e-12);
  // Nobody drains: the ring fills and further samples are dropped, not blocked on.
  const std::size_t ticks = ToolSampleRing::kCapacity + 100;
  for (std::size_t i = 0; i < ticks; ++i) rig.tick();
  EXPECT_EQ(rig.loop->stats().ring_drops, 100u);
  // Released: no force on the object.
  rig.drain();
  rig.device.position_m = Vec3(0, 0, 0.003);
  rig.tick();
  ASSERT_TRUE(rig.samples->try_pop(s));
  EXPECT_FALSE(s.contact);
  EXPECT_EQ(s.force_on_object_N, Vec3::Zero());
}

TEST(HapticLoop, InvalidModelsAreDroppedAndCounted) {
  Rig rig;
  rig.build();
  LocalModel bad = test::make_flat_patch();
  bad.vertex_m[2].y() = std::nan("");
  rig.publish(bad);
  rig.tick();
  const HapticStats st = rig.loop->stats();
  EXPECT_EQ(st.rejected_models, 1u);
  EXPECT_EQ(st.model_updates, 0u);
  EXPECT_EQ(st.model_version, 0u);
}

// Found by the review: a patch with finite but 1e80 m coordinates was
// accepted and put a NaN proxy into the tool samples. It is now rejected like
// a NaN one: the loop goes stale and ramps its force out, and no sample
// carries a non-finite number.
TEST(HapticLoop, AModelWithHugeCoordinatesIsRejectedAndTheForceRampsOut) {
  Rig rig;
  rig.build();
  // Pressed 2 mm in above the huge triangle's interior (where its arithmetic overflows).
  const LocalModel patch = test::make_flat_patch();
  rig.device.position_m = Vec3(0.01, 0.005, 0.002);
  rig.publish(patch);
  rig.tick();
  rig.device.position_m = Vec3(0.01, 0.005, -0.002);
  for (int i = 0; i < 700; ++i) {
    rig.publish(patch);
    rig.tick();
  }
  ASSERT_GT(rig.device.last_force_N.norm(), 0.5);
  LocalModel huge;
  huge.vertex_count = 3;
  huge.triangle_count = 1;
  huge.vertex_m[1] = Vec3(1e80, 0.0, 0.0);
  huge.vertex_m[2] = Vec3(0.5e80, 1e80, 0.0);
  huge.triangle[0] = {0, 1, 2};
  rig.drain();
  rig.publish(huge);
  rig.tick();
  EXPECT_EQ(rig.loop->stats().rejected_models, 1u);
  for (int i = 0; i < 1000 && !rig.device.last_force_N.isZero(0.0); ++i) rig.tick();
  EXPECT_TRUE(rig.device.last_force_N.isZero(0.0));
  EXPECT_GE(rig.loop->stats().stale_model_trips, 1u);
  ToolSample s;
  int samples = 0;
  while (rig.samples->try_pop(s)) {
    ++samples;
    EXPECT_TRUE(s.proxy_position_m.allFinite()) << s.proxy_position_m.transpose();
    for (double w : s.contact_weight) EXPECT_TRUE(std::isfinite(w));
  }
  EXPECT_GT(samples, 0);
}

// The scale-2 rigs: device offset (0, 0, 0.1) m and scale 2, so the flat
// patch (scene z = 0) is at device z = -0.05. Builds the rig with the limits
// and coupling the caller set, touches the patch from device z = -0.049 and
// moves the device 1 mm into it (z = -0.051, scene z = 0.1 + 2 * (-0.051) =
// -0.002); the caller ticks on. Returns the patch.
LocalModel build_scale_2_rig_pressed_1_mm(Rig& rig) {
  rig.device_spec.offset_m = {0.0, 0.0, 0.1};
  rig.device_spec.scale = 2.0;
  rig.device_spec.limits.stale_model_s = 10.0;
  rig.build();
  const LocalModel m = test::make_flat_patch();
  rig.device.position_m = Vec3(0, 0, -0.049);
  rig.publish(m);
  rig.tick();
  rig.device.position_m = Vec3(0, 0, -0.051);
  return m;
}

TEST(HapticLoop, FrameTransformMapsPositionsAndForcesInOnePlace) {
  Rig rig;
  // The hand feels 400 N/m * 2^2 = 1600 N/m: allowed here, so the coupling
  // is not clamped (the next test shows the clamp).
  rig.device_spec.limits.max_stiffness_N_per_m = 1600.0;
  build_scale_2_rig_pressed_1_mm(rig);
  for (int i = 0; i < 700; ++i) rig.tick();
  const ToolSample& s = rig.loop->last_sample();
  EXPECT_NEAR(s.device_position_m.z(), -0.002, 1e-12);
  EXPECT_NEAR(s.force_on_device_N.z(), 0.8, 1e-9);      // scene frame: 400 N/m * 2 mm
  EXPECT_NEAR(rig.device.last_force_N.z(), 1.6, 1e-9);  // device frame: power-consistent, x scale
}

// Found by the review of the haptics: device.limits.max_stiffness_N_per_m was
// applied in the scene frame, so with scale 2 the hand felt 1600 N/m (1.6 N
// for 1 mm of device travel) against a 1000 N/m limit.
TEST(HapticLoop, TheStiffnessLimitHoldsInTheDeviceFrameWhateverTheScale) {
  Rig rig;
  rig.device_spec.limits.max_stiffness_N_per_m = 1000.0;
  rig.haptic_spec.coupling_stiffness_N_per_m = 400.0;  // 1600 N/m at the hand: over the limit
  // Rigid: the hand feels the coupling, over 1 mm of device travel.
  const LocalModel m = build_scale_2_rig_pressed_1_mm(rig);
  for (int i = 0; i < 700; ++i) {
    rig.publish(m);
    rig.tick();
  }
  ASSERT_TRUE(rig.loop->stats().contact);
  const double device_stiffness_N_per_m = rig.device.last_force_N.z() / 0.001;
  EXPECT_GT(device_stiffness_N_per_m, 0.0);
  EXPECT_LE(device_stiffness_N_per_m, 1000.0 + 1e-6);
}

// A simulated hand presses a stiff-but-linear model, holds, and lets go.
TEST(HapticLoop, HandPressingALinearModelNeitherOscillatesNorGeneratesEnergy) {
  for (const bool deformable : {false, true}) {
    SCOPED_TRACE(deformable ? "deformable K_c = 1000 I" : "rigid patch");
    config::SimDeviceSpec hand;
    hand.mode = config::SimDeviceSpec::Mode::kHand;
    hand.waypoints = {{0.0, {0, 0, 0.01}},  {0.6, {0, 0, 0.01}}, {0.7, {0, 0, -0.01}},
                      {1.6, {0, 0, -0.01}}, {1.7, {0, 0, 0.02}}, {2.2, {0, 0, 0.02}}};
    SimDevice device(hand);
    ASSERT_TRUE(device.start(nullptr));
    Rig rig;
    rig.device_spec.limits.stale_model_s = 10.0;
    rig.build(&device);
    LocalModel m = test::make_flat_patch();
    if (deformable) test::set_linear_contact(m, 1000.0);
    rig.publish(m);
    std::vector<double> force_z;
    double min_energy_J = 0.0;
    for (int i = 0; i < 2200; ++i) {
      rig.now_ns += kMs;
      rig.loop->tick(rig.now_ns);
      rig.drain();
      const HapticStats st = rig.loop->stats();
      min_energy_J = std::min(min_energy_J, st.passivity_energy_J);
      force_z.push_back(rig.loop->last_sample().force_on_device_N.z());
    }
    // Peaks of successive half-cycles during the hold (0.75 s .. 1.6 s) never grow.
    std::vector<double> peaks;
    for (int i = 751; i < 1600; ++i)
      if (force_z[i] > force_z[i - 1] && force_z[i] >= force_z[i + 1]) peaks.push_back(force_z[i]);
    for (std::size_t k = 1; k < peaks.size(); ++k) EXPECT_LE(peaks[k], peaks[k - 1] + 1e-9) << "peak " << k;
    double max_force = 0.0;
    for (double f : force_z) max_force = std::max(max_force, f);
    EXPECT_GT(max_force, 0.5);  // the press really happened
    EXPECT_LE(max_force, rig.device_spec.limits.max_force_N + 1e-12);
    // Released and at rest: the hand is free and the force is zero.
    EXPECT_EQ(force_z.back(), 0.0);
    // Passivity: the environment never gave back more energy than it took.
    const HapticStats st = rig.loop->stats();
    EXPECT_GE(min_energy_J, -1e-6);
    EXPECT_GE(st.passivity_energy_J, 0.0);
    EXPECT_LT(st.passivity_energy_J, 0.1);  // bounded: a few mJ of coupling damping
    std::printf("  %s: peaks %zu, max force %.3f N, passivity energy %.3g J (min %.3g J)\n",
                deformable ? "deformable" : "rigid", peaks.size(), max_force, st.passivity_energy_J, min_energy_J);
  }
}

}  // namespace
}  // namespace tissue::haptics
