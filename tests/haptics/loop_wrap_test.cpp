#include "haptics/loop_wrap.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <memory>
#include <optional>
#include <string>

#include "haptics/haptic_loop.hpp"
#include "haptics/haptics_test_support.hpp"
#include "haptics/sim_device.hpp"

namespace tissue::haptics {
namespace {

// A looping track jumps from its last point to its first in one tick: longer
// than max_speed_m_per_s / rate_hz, the loop rejects the jump and the force
// ramps out at each wrap. Said once at start, naming the key and the numbers.
TEST(LoopWrap, AWrapLongerThanATickAllowsIsAWarningNamingTheKeyAndTheNumbers) {
  // 5 m/s at 1 kHz: 5 mm a tick. The review's 0.3 m wrap.
  const std::string w = loop_wrap_warning("device.replay.loop", 0.3, 5.0, 1000.0);
  EXPECT_EQ(w.rfind("device.replay.loop: the looping track goes from its last point back to its first in one tick, "
                    "a 0.3 m jump (device frame), more than the 0.005 m a tick the haptic loop accepts "
                    "(device.limits.max_speed_m_per_s 5 at haptics.rate_hz 1000): the force ramps out and back in "
                    "at every wrap",
                    0),
            0u)
      << w;
  EXPECT_NE(loop_wrap_warning("device.sim.waypoints", 0.006, 5.0, 1000.0).find("device.sim.waypoints: "),
            std::string::npos);
}

TEST(LoopWrap, AWrapWithinATickIsNoWarning) {
  EXPECT_EQ(loop_wrap_warning("device.replay.loop", 0.0, 5.0, 1000.0), "");  // ends where it starts
  EXPECT_EQ(loop_wrap_warning("device.replay.loop", 0.005, 5.0, 1000.0), "");
  EXPECT_EQ(loop_wrap_warning("device.sim.waypoints", 0.3, 5.0, 10.0), "");  // 0.5 m a tick at 10 Hz
}

// A looping replay whose wrap plays as no samples (the rows before the
// device's first sample, a tail after its last played so): the loop holds
// the last sample it accepted and judges the first one after the wrap
// against it over the wall time without samples, not over one tick. Warned
// about exactly when that is faster than device.limits.max_speed_m_per_s,
// saying how long the loop keeps rejecting (jump / max speed after the last
// accepted sample).
TEST(LoopWrap, AWrapThroughNoSamplesIsJudgedOverThatTime) {
  EXPECT_EQ(loop_wrap_warning("device.replay.loop", 0.3, 5.0, 1000.0, 0.07), "");         // 4.3 m/s
  const std::string w = loop_wrap_warning("device.replay.loop", 0.3, 5.0, 1000.0, 0.05);  // 6 m/s
  EXPECT_EQ(w.rfind("device.replay.loop: the looping track goes from its last sample back to its first through "
                    "0.05 s (wall time) without samples, a 0.3 m jump (device frame) the haptic loop judges over "
                    "that time: 6 m/s, more than device.limits.max_speed_m_per_s 5: it rejects the samples after "
                    "every wrap as too fast until 0.06 s after the last one it accepted",
                    0),
            0u)
      << w;
  // The loop reads once a tick: a shorter time is still a tick.
  EXPECT_EQ(loop_wrap_warning("device.replay.loop", 0.004, 5.0, 1000.0, 1e-4), "");
  EXPECT_NE(loop_wrap_warning("device.replay.loop", 0.006, 5.0, 1000.0, 1e-4), "");
}

// A looping simulated device whose last waypoint is jump_m from its first:
// it holds the first point for 0.5 s, moves to the last over 1 s, holds it
// for 1 s (the hand settles), then wraps at 2.5 s and holds the first point
// again for 0.5 s, so what the hand does just after the wrap is its answer
// to the jump alone.
config::DeviceSpec looping_sim(config::SimDeviceSpec::Mode mode, double jump_m) {
  config::DeviceSpec d;
  d.kind = config::DeviceSpec::Kind::kSim;
  d.sim.mode = mode;
  d.sim.loop = true;
  d.sim.waypoints = {{0.0, {-0.1, 0.0, 0.0}},
                     {0.5, {-0.1, 0.0, 0.0}},
                     {1.5, {-0.1 + jump_m, 0.0, 0.0}},
                     {2.5, {-0.1 + jump_m, 0.0, 0.0}}};
  d.limits.stale_model_s = 10.0;  // no model: only the device side is judged
  return d;
}

// The haptic loop's judgement of a simulated device ticked at rate_hz for
// duration_s (no model: only the device side is judged).
HapticStats run_the_loop(const config::DeviceSpec& device_spec, double rate_hz, double duration_s) {
  SimDevice device(device_spec.sim);
  EXPECT_TRUE(device.start(nullptr));
  config::HapticSpec haptic_spec;
  haptic_spec.rate_hz = rate_hz;
  auto models = std::make_unique<LocalModelBuffer>();
  auto samples = std::make_unique<ToolSampleRing>();
  HapticLoop loop(device, device_spec, haptic_spec, *models, *samples);
  const long ticks = std::lround(duration_s * rate_hz);
  for (long tick = 0; tick <= ticks; ++tick) {
    loop.tick(1000 * test::kMs + std::llround(static_cast<double>(tick) * 1e9 / rate_hz));
    ToolSample drained;
    while (samples->try_pop(drained)) {
    }
  }
  return loop.stats();
}

// The samples the haptic loop rejects (too fast or outside the workspace)
// over the first pass and three wraps, each followed by a whole period (what
// the warning checks), the device ticked at rate_hz.
std::uint64_t rejected_over_three_wraps(const config::DeviceSpec& device_spec, double rate_hz = 1000.0) {
  const auto& w = device_spec.sim.waypoints;
  const HapticStats st =
      run_the_loop(device_spec, rate_hz, w.back().time_s + 3.0 * (w.back().time_s - w.front().time_s));
  return st.rejected_speed + st.rejected_workspace;
}
std::uint64_t rejected_as_too_fast_around_the_wrap(const config::DeviceSpec& device_spec) {
  return rejected_over_three_wraps(device_spec);
}

// mode: trajectory jumps with the target at the wrap: loop_wrap_warning.
TEST(LoopWrap, ALoopingTrajectoryIsWarnedAboutItsJump) {
  const config::DeviceSpec d = looping_sim(config::SimDeviceSpec::Mode::kTrajectory, 0.3);
  EXPECT_EQ(sim_loop_wrap_warning(d, 1000.0), loop_wrap_warning("device.sim.waypoints", 0.3, 5.0, 1000.0));
  EXPECT_EQ(sim_loop_wrap_warning(looping_sim(config::SimDeviceSpec::Mode::kTrajectory, 0.004), 1000.0), "");
  config::DeviceSpec once = d;
  once.sim.loop = false;
  EXPECT_EQ(sim_loop_wrap_warning(once, 1000.0), "");
  EXPECT_GT(rejected_as_too_fast_around_the_wrap(d), 0u);
}

// mode: hand follows the jumped target through its spring, and a long wrap
// trips the loop's speed check all the same (the review's 0.3 m: 61 samples
// rejected and one device-lost trip per wrap); it was not warned about. The
// warning now says so exactly when the loop rejects the hand after the wrap.
TEST(LoopWrap, ALoopingHandThatFollowsALongWrapTooFastIsWarnedAboutIt) {
  const config::DeviceSpec review = looping_sim(config::SimDeviceSpec::Mode::kHand, 0.3);
  const std::string w = sim_loop_wrap_warning(review, 1000.0);
  EXPECT_EQ(w.rfind("device.sim.waypoints: the looping track's target goes from its last point back to its first "
                    "in one tick, a 0.3 m jump (device frame), and the hand (device.sim.mode hand) follows it "
                    "through its spring at up to ",
                    0),
            0u)
      << w;
  EXPECT_NE(w.find(" m/s, more than device.limits.max_speed_m_per_s 5: the force ramps out and back in at every "
                   "wrap"),
            std::string::npos)
      << w;
  for (const double jump_m : {0.05, 0.15, 0.17, 0.21, 0.25, 0.3}) {
    SCOPED_TRACE(jump_m);
    const config::DeviceSpec d = looping_sim(config::SimDeviceSpec::Mode::kHand, jump_m);
    EXPECT_EQ(sim_loop_wrap_warning(d, 1000.0).empty(), rejected_as_too_fast_around_the_wrap(d) == 0u);
  }
  EXPECT_GT(rejected_as_too_fast_around_the_wrap(review), 0u);
  EXPECT_EQ(rejected_as_too_fast_around_the_wrap(looping_sim(config::SimDeviceSpec::Mode::kHand, 0.15)), 0u);
}

// One rule for the warning and the loop: the jump from which the warning
// speaks splits the wraps the loop rejects from those it takes, within 2 %.
// The default hand (0.1 kg, 200 N/m, 4 N s/m) from about 0.19 m at 5 m/s
// (docs/daemon-config.md).
TEST(LoopWrap, TheHandsWrapWarningStartsWhereTheLoopStartsRejecting) {
  double quiet_m = 0.0, warned_m = 0.6;  // bisect the jump at which the warning starts
  for (int i = 0; i < 30; ++i) {
    const double mid_m = 0.5 * (quiet_m + warned_m);
    (sim_loop_wrap_warning(looping_sim(config::SimDeviceSpec::Mode::kHand, mid_m), 1000.0).empty() ? quiet_m
                                                                                                   : warned_m) = mid_m;
  }
  const double threshold_m = warned_m;
  EXPECT_NEAR(threshold_m, 0.19, 0.01);
  const config::DeviceSpec above = looping_sim(config::SimDeviceSpec::Mode::kHand, 1.02 * threshold_m);
  EXPECT_NE(sim_loop_wrap_warning(above, 1000.0), "");
  EXPECT_GT(rejected_as_too_fast_around_the_wrap(above), 0u);
  const config::DeviceSpec below = looping_sim(config::SimDeviceSpec::Mode::kHand, 0.98 * threshold_m);
  EXPECT_EQ(sim_loop_wrap_warning(below, 1000.0), "");
  EXPECT_EQ(rejected_as_too_fast_around_the_wrap(below), 0u);
  // A stiffer, lighter hand swings faster: the same wrap is then warned about.
  config::DeviceSpec stiff = below;
  stiff.sim.hand_stiffness_N_per_m = 800.0;
  EXPECT_NE(sim_loop_wrap_warning(stiff, 1000.0), "");
  EXPECT_GT(rejected_as_too_fast_around_the_wrap(stiff), 0u);
  // No spring: the hand never follows the jump.
  config::DeviceSpec limp = above;
  limp.sim.hand_stiffness_N_per_m = 0.0;
  EXPECT_EQ(sim_loop_wrap_warning(limp, 1000.0), "");
  EXPECT_EQ(rejected_as_too_fast_around_the_wrap(limp), 0u);
}

const char* const kHandWrapPrefix =
    "device.sim.waypoints: the looping track's target goes from its last point back to its first in one tick, a ";

// (a) Without damping the hand's swings do not die out between wraps: they
// add up. The old check simulated one jump from rest and said nothing of a
// 0.10 m jump (0.9 of the jump it warned from for this hand), which the loop
// rejects from the second wrap on.
TEST(LoopWrap, AnUndampedHandWhoseSwingsAddUpOverTheWrapsIsWarnedAboutIt) {
  config::DeviceSpec d = looping_sim(config::SimDeviceSpec::Mode::kHand, 0.10);
  d.sim.hand_damping_N_s_per_m = 0.0;
  ASSERT_GT(rejected_over_three_wraps(d), 0u);
  const std::string w = sim_loop_wrap_warning(d, 1000.0);
  EXPECT_EQ(w.rfind(kHandWrapPrefix, 0), 0u) << w;
  EXPECT_NE(w.find("0.1 m jump"), std::string::npos) << w;
}

// (b) A wrap while the hand moves toward the first point: its own speed adds
// to its answer to the jump. A 0.18 m jump (below the 0.19 m a jump from rest
// is warned from) that the loop rejects about 20 ms after every wrap.
TEST(LoopWrap, AWrapWhileTheHandMovesTowardTheFirstPointIsWarnedAboutIt) {
  config::DeviceSpec d = looping_sim(config::SimDeviceSpec::Mode::kHand, 0.0);
  d.sim.waypoints = {{0.0, {0.0, 0.0, 0.0}}, {0.1, {-0.1, 0.0, 0.0}}, {0.3, {0.3, 0.0, 0.0}}, {0.4, {0.18, 0.0, 0.0}}};
  ASSERT_GT(rejected_over_three_wraps(d), 0u);
  const std::string w = sim_loop_wrap_warning(d, 1000.0);
  EXPECT_EQ(w.rfind(kHandWrapPrefix, 0), 0u) << w;
  EXPECT_NE(w.find("0.18 m jump"), std::string::npos) << w;
}

// (c) Below about 31 Hz a SimDevice read integrates at most 64 sub-steps of
// 0.5 ms of hand time, however long the tick: the old check's window counted
// wall time and saw only the start of a slow hand's swing after the wrap. A
// hand with a 1 s period (damping ratio 0.3), read at 2 Hz under a 1 m/s
// limit, on a track slow enough that only the wrap is rejected.
TEST(LoopWrap, AHandReadBelow31HzIsJudgedAsTheLoopReadsIt) {
  for (const double jump_m : {0.25, 0.3}) {
    SCOPED_TRACE("jump " + std::to_string(jump_m) + " m");
    config::DeviceSpec d = looping_sim(config::SimDeviceSpec::Mode::kHand, jump_m);
    d.sim.waypoints = {{0.0, {-0.4, 0.0, 0.0}},
                       {20.0, {-0.4, 0.0, 0.0}},
                       {40.0, {-0.4 + jump_m, 0.0, 0.0}},
                       {60.0, {-0.4 + jump_m, 0.0, 0.0}}};
    d.sim.hand_mass_kg = 1.0;
    d.sim.hand_stiffness_N_per_m = 39.5;  // 2 pi sqrt(m / k): 1 s
    d.sim.hand_damping_N_s_per_m = 3.77;  // damping ratio 0.3
    d.limits.max_speed_m_per_s = 1.0;
    EXPECT_GT(rejected_over_three_wraps(d, 2.0), 0u);
    EXPECT_EQ(run_the_loop(d, 2.0, 59.9).rejected_speed, 0u);  // the first pass is taken
    const std::string w = sim_loop_wrap_warning(d, 2.0);
    EXPECT_EQ(w.rfind(kHandWrapPrefix, 0), 0u) << w;
  }
}

// The same rule judges the workspace: a hand that swings past
// device.limits.workspace_radius_m after the wrap (here with a speed limit it
// never reaches) is warned about as the loop rejects it.
TEST(LoopWrap, AHandThatSwingsOutOfTheWorkspaceAfterTheWrapIsWarnedAboutIt) {
  config::DeviceSpec d = looping_sim(config::SimDeviceSpec::Mode::kHand, 0.0);
  d.sim.waypoints = {{0.0, {-0.9, 0.0, 0.0}}, {0.5, {-0.9, 0.0, 0.0}}, {1.5, {0.0, 0.0, 0.0}}, {2.5, {0.0, 0.0, 0.0}}};
  d.limits.max_speed_m_per_s = 100.0;
  const HapticStats st = run_the_loop(d, 1000.0, 10.0);
  ASSERT_GT(st.rejected_workspace, 0u);
  EXPECT_EQ(run_the_loop(d, 1000.0, 2.5).rejected_workspace, 0u);  // not on the first pass
  const std::string w = sim_loop_wrap_warning(d, 1000.0);
  EXPECT_EQ(w.rfind(std::string(kHandWrapPrefix) + "0.9 m jump (device frame), and the hand (device.sim.mode hand) "
                                                   "follows it through its spring out to 1.",
                    0),
            0u)
      << w;
  EXPECT_NE(w.find("m from the device origin, beyond device.limits.workspace_radius_m 1: "), std::string::npos) << w;
}

// A track whose own motion the loop rejects is not blamed on the wrap: a
// trajectory segment at 6 m/s is rejected on every pass, wrap or not.
TEST(LoopWrap, ATrackTheLoopRejectsBeforeItWrapsIsSaidToBeTheTracksOwn) {
  config::DeviceSpec d = looping_sim(config::SimDeviceSpec::Mode::kTrajectory, 0.0);
  d.sim.waypoints = {{0.0, {0.0, 0.0, 0.0}}, {0.5, {0.0, 0.0, 0.0}}, {0.55, {0.3, 0.0, 0.0}}, {1.5, {0.0, 0.0, 0.0}}};
  ASSERT_GT(run_the_loop(d, 1000.0, 1.0).rejected_speed, 0u);
  EXPECT_EQ(sim_loop_wrap_warning(d, 1000.0),
            "device.sim.waypoints: the simulated tip (device.sim.mode trajectory) is rejected by the haptic loop "
            "0.5 s into the track's first pass, before it wraps (faster than device.limits.max_speed_m_per_s): the "
            "force ramps out and back in on every pass");
}

// The check is bounded (10^6 hand sub-steps) so the start stays fast: a long
// track is checked over fewer wraps, and the warning says what it checked
// (tracks too long for even one wrap: the two tests below).
TEST(LoopWrap, ALongTracksCheckIsBoundedAndSaysWhatItChecked) {
  config::DeviceSpec d = looping_sim(config::SimDeviceSpec::Mode::kHand, 0.3);
  d.sim.waypoints = {
      {0.0, {-0.1, 0.0, 0.0}}, {0.5, {-0.1, 0.0, 0.0}}, {1.5, {0.2, 0.0, 0.0}}, {400.0, {0.2, 0.0, 0.0}}};
  // At 1 kHz a read is 2 sub-steps: 5 * 10^5 reads, 500 s, the first pass and one wrap.
  const std::string w = sim_loop_wrap_warning(d, 1000.0);
  EXPECT_NE(w.find("(checked at start: the hand simulated with no rendered force, read at haptics.rate_hz 1000 over "
                   "the first 500 s, the first pass and 1 wrap)"),
            std::string::npos)
      << w;
  const std::string short_track = sim_loop_wrap_warning(looping_sim(config::SimDeviceSpec::Mode::kHand, 0.3), 1000.0);
  EXPECT_NE(short_track.find("over the first 10 s, the first pass and 3 wraps)"), std::string::npos) << short_track;
}

// A track longer than the check's budget is still checked at its wrap: the
// first pass no longer spends the 10^6 sub-steps before any wrap. A 1200 s
// trajectory (10^6 reads at 1 kHz would reach 1000 s) whose 0.2 m wrap the
// loop rejects is warned about exactly as its 10 s version.
TEST(LoopWrap, ATrajectoryLongerThanTheChecksBudgetIsStillWarnedAboutItsWrap) {
  config::DeviceSpec d = looping_sim(config::SimDeviceSpec::Mode::kTrajectory, 0.0);
  d.sim.waypoints = {{0.0, {-0.1, 0.0, 0.0}}, {1200.0, {0.1, 0.0, 0.0}}};
  ASSERT_GT(run_the_loop(d, 1000.0, 1201.0).rejected_speed, 0u);
  EXPECT_EQ(run_the_loop(d, 1000.0, 1199.0).rejected_speed, 0u);  // only the wrap
  EXPECT_EQ(sim_loop_wrap_warning(d, 1000.0), loop_wrap_warning("device.sim.waypoints", 0.2, 5.0, 1000.0));
  config::DeviceSpec short_track = d;
  short_track.sim.waypoints.back().time_s = 10.0;
  EXPECT_EQ(sim_loop_wrap_warning(short_track, 1000.0), sim_loop_wrap_warning(d, 1000.0));
}

// The same for the hand: a 600 s track (10^6 sub-steps at 1 kHz are 500 s)
// with a 0.5 m wrap is warned about, and the warning says what was checked:
// the start of the first pass, and the wrap from a lead-in before it.
TEST(LoopWrap, AHandTrackLongerThanTheChecksBudgetIsStillWarnedAboutItsWrap) {
  config::DeviceSpec d = looping_sim(config::SimDeviceSpec::Mode::kHand, 0.0);
  d.sim.waypoints = {{0.0, {-0.25, 0.0, 0.0}}, {600.0, {0.25, 0.0, 0.0}}};
  ASSERT_GT(run_the_loop(d, 1000.0, 601.0).rejected_speed, 0u);
  EXPECT_EQ(run_the_loop(d, 1000.0, 599.0).rejected_speed, 0u);  // only the wrap
  const std::string w = sim_loop_wrap_warning(d, 1000.0);
  EXPECT_EQ(w.rfind(std::string(kHandWrapPrefix) + "0.5 m jump (device frame), and the hand (device.sim.mode hand) "
                                                   "follows it through its spring at up to ",
                    0),
            0u)
      << w;
  EXPECT_NE(w.find("(checked at start: the hand simulated with no rendered force, read at haptics.rate_hz 1000 over "
                   "the first 250 s of the first pass, then from 590 s (started there on the track, at its velocity) "
                   "to 840 s, 1 wrap; the whole run would take more than the check's 10^6 hand sub-steps)"),
            std::string::npos)
      << w;
  config::DeviceSpec short_track = d;
  short_track.sim.waypoints.back().time_s = 10.0;
  EXPECT_NE(sim_loop_wrap_warning(short_track, 1000.0), "");
}

// The three steps of sim_loop_wrap_warning, each on its own.

// (a) The plan: one window from the start while the budget reaches the first
// wrap and 10 s past it; the reads it takes are the first pass and three
// wraps, each followed by a whole period, when they fit.
TEST(LoopWrapPlan, AShortTrackIsOneWindowOverTheFirstPassAndThreeWraps) {
  // 2.5 s track at 1 kHz: 10 s, reads 0 .. 10000.
  const SimLoopPlan p = plan_sim_loop_check(0.0, 2.5, 1000.0, true);
  EXPECT_EQ(p.first_pass.first_read, 0);
  EXPECT_EQ(p.first_pass.reads, 10001);
  EXPECT_EQ(p.wrap.reads, 0);
  // The span counts from the first waypoint: 1 s to 3.5 s repeats every 2.5 s too.
  EXPECT_EQ(plan_sim_loop_check(1.0, 3.5, 1000.0, false).first_pass.reads, 11001);
}

// A hand read costs its sub-steps: 2 at 1 kHz (1 ms / 0.5 ms), 64 below about
// 31 Hz; a trajectory read costs 1. A track whose three wraps do not fit but
// whose first wrap and 10 s past it do is one window of the whole budget.
TEST(LoopWrapPlan, TheBudgetIsHandSubStepsOrTrajectoryReads) {
  const SimLoopPlan hand = plan_sim_loop_check(0.0, 400.0, 1000.0, true);
  EXPECT_EQ(hand.first_pass.reads, 500000);
  EXPECT_EQ(hand.wrap.reads, 0);
  const SimLoopPlan tip = plan_sim_loop_check(0.0, 400.0, 1000.0, false);
  EXPECT_EQ(tip.first_pass.reads, 1000000);
  EXPECT_EQ(tip.wrap.reads, 0);
  const SimLoopPlan slow = plan_sim_loop_check(0.0, 5000.0, 2.0, true);  // 10^6 / 64 reads
  EXPECT_EQ(slow.first_pass.reads, 15625);
  EXPECT_EQ(slow.wrap.reads, 0);
  // 10 s track: 40001 reads wanted, the first wrap and 10 s past it 20001.
  const SimLoopPlan small = plan_sim_loop_check(0.0, 10.0, 1000.0, false, 20001.0);
  EXPECT_EQ(small.first_pass.reads, 20001);
  EXPECT_EQ(small.wrap.reads, 0);
}

// Too long for that: two windows of half the budget, the first pass from its
// start and the wrap from 10 s before it (reads at 1 kHz). The first pass
// between them is not read (the documented limit).
TEST(LoopWrapPlan, ATrackTooLongForItsFirstWrapIsTwoWindowsOfHalfTheBudget) {
  const SimLoopPlan hand = plan_sim_loop_check(0.0, 600.0, 1000.0, true);
  EXPECT_EQ(hand.first_pass.first_read, 0);
  EXPECT_EQ(hand.first_pass.reads, 250000);
  EXPECT_EQ(hand.wrap.first_read, 590000);
  EXPECT_EQ(hand.wrap.reads, 250000);
  EXPECT_LT(hand.first_pass.reads, hand.wrap.first_read) << "the windows met: the hand could be carried over";
  const SimLoopPlan tip = plan_sim_loop_check(0.0, 1200.0, 1000.0, false);
  EXPECT_EQ(tip.first_pass.reads, 500000);
  EXPECT_EQ(tip.wrap.first_read, 1190000);
  EXPECT_EQ(tip.wrap.reads, 500000);
  // A lead-in longer than a quarter of the budget is cut to it: 10000 reads
  // of budget, the wrap at read 2500, a 5000-read wrap window from read
  // 2500 - 2500; the first pass gets what is left up to the wrap window's
  // start: nothing, the wrap window reads it.
  const SimLoopPlan cut = plan_sim_loop_check(0.0, 2.5, 1000.0, false, 10000.0);
  EXPECT_EQ(cut.wrap.first_read, 0);
  EXPECT_EQ(cut.wrap.reads, 5000);
  EXPECT_EQ(cut.first_pass.reads, 0);
  const SimLoopPlan tight = plan_sim_loop_check(0.0, 2.5, 1000.0, false, 1000.0);
  EXPECT_EQ(tight.wrap.first_read, 2250);  // lead-in 250 reads, a quarter of the budget
  EXPECT_EQ(tight.wrap.reads, 500);
  EXPECT_EQ(tight.first_pass.reads, 500);
}

TEST(LoopWrapPlan, NoWindowsForATrackOrRateThatCannotBeRead) {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  for (const SimLoopPlan& p :
       {plan_sim_loop_check(0.0, 0.0, 1000.0, true), plan_sim_loop_check(1.0, 0.5, 1000.0, true),
        plan_sim_loop_check(0.0, 2.5, 0.0, true), plan_sim_loop_check(0.0, 2.5, std::nan(""), false),
        plan_sim_loop_check(0.0, 2.5, kInf, false), plan_sim_loop_check(0.0, kInf, 1000.0, false),
        plan_sim_loop_check(0.0, 2.5, 1000.0, false, 0.0)}) {
    EXPECT_EQ(p.first_pass.reads, 0);
    EXPECT_EQ(p.wrap.reads, 0);
  }
}

// (b) The check of one window: the trajectory's 0.3 m wrap at 2.5 s is the
// first rejection (too fast, a 0.3 m step), at the first read after it; the
// window of 10001 reads ends at 10 s, three wraps.
TEST(LoopWrapJudge, AWindowFromTheStartFindsTheFirstRejectionAndCountsTheWraps) {
  const config::DeviceSpec d = looping_sim(config::SimDeviceSpec::Mode::kTrajectory, 0.3);
  const std::optional<SimLoopJudged> j = judge_sim_loop_window(d, 1000.0, {0, 10001});
  ASSERT_TRUE(j.has_value());
  EXPECT_TRUE(j->rejected);
  EXPECT_NEAR(j->first_rejected_s, 2.501, 1e-9);
  EXPECT_EQ(j->first_verdict, SampleVerdict::kTooFast);
  EXPECT_NEAR(j->first_step_m, 0.3, 1e-9);
  EXPECT_NEAR(j->peak_m_per_s, 300.0, 1e-6);  // 0.3 m in 1 ms
  EXPECT_NEAR(j->farthest_m, 0.2, 1e-9);      // the last point, 0.2 m from the origin
  EXPECT_NEAR(j->checked_s, 10.0, 1e-9);
  EXPECT_EQ(j->wraps, 3);
  // Before the wrap: nothing rejected, nothing measured (peaks count from the first wrap on).
  const std::optional<SimLoopJudged> before = judge_sim_loop_window(d, 1000.0, {0, 2501});
  ASSERT_TRUE(before.has_value());
  EXPECT_FALSE(before->rejected);
  EXPECT_EQ(before->peak_m_per_s, 0.0);
  EXPECT_EQ(before->wraps, 0);
  EXPECT_NEAR(before->checked_s, 2.5, 1e-9);
}

// A window that starts later starts the copy there on the track, and its
// first sample is judged against nothing: a window from just after the wrap
// sees no jump until the next wrap at 5 s.
TEST(LoopWrapJudge, AWindowStartedLaterStartsThereAndJudgesItsFirstSampleAlone) {
  const config::DeviceSpec d = looping_sim(config::SimDeviceSpec::Mode::kTrajectory, 0.3);
  const std::optional<SimLoopJudged> quiet = judge_sim_loop_window(d, 1000.0, {2501, 2000});
  ASSERT_TRUE(quiet.has_value());
  EXPECT_FALSE(quiet->rejected);
  EXPECT_NEAR(quiet->checked_s, 4.5, 1e-9);
  EXPECT_EQ(quiet->wraps, 1);
  const std::optional<SimLoopJudged> next = judge_sim_loop_window(d, 1000.0, {2501, 3000});
  ASSERT_TRUE(next.has_value());
  EXPECT_TRUE(next->rejected);
  EXPECT_NEAR(next->first_rejected_s, 5.0, 1.5e-3);
  EXPECT_NEAR(next->first_step_m, 0.3, 1e-9);
}

// Windows fold: an earlier window's rejection stays the first, peaks are the
// larger of both, checked_s and wraps are the later window's.
TEST(LoopWrapJudge, ALaterWindowKeepsAnEarlierWindowsFirstRejection) {
  const config::DeviceSpec d = looping_sim(config::SimDeviceSpec::Mode::kTrajectory, 0.3);
  SimLoopJudged earlier;
  earlier.rejected = true;
  earlier.first_rejected_s = 1.0;
  earlier.first_verdict = SampleVerdict::kOutsideWorkspace;
  earlier.first_step_m = 0.01;
  earlier.peak_m_per_s = 1000.0;
  const std::optional<SimLoopJudged> j = judge_sim_loop_window(d, 1000.0, {2000, 3000}, earlier);
  ASSERT_TRUE(j.has_value());
  EXPECT_EQ(j->first_rejected_s, 1.0);
  EXPECT_EQ(j->first_verdict, SampleVerdict::kOutsideWorkspace);
  EXPECT_EQ(j->first_step_m, 0.01);
  EXPECT_EQ(j->peak_m_per_s, 1000.0);
  EXPECT_NEAR(j->farthest_m, 0.2, 1e-9);  // measured after the wrap, in this window
  EXPECT_NEAR(j->checked_s, 4.999, 1e-9);
  EXPECT_EQ(j->wraps, 1);
}

TEST(LoopWrapJudge, ADeviceThatDoesNotStartIsNoResult) {
  config::DeviceSpec d = looping_sim(config::SimDeviceSpec::Mode::kHand, 0.3);
  d.sim.hand_mass_kg = 0.0;
  EXPECT_FALSE(judge_sim_loop_window(d, 1000.0, {0, 10}).has_value());
  EXPECT_FALSE(judge_sim_loop_window(looping_sim(config::SimDeviceSpec::Mode::kHand, 0.3), 0.0, {0, 10}).has_value());
}

// (c) The message, from a result made up here.
TEST(LoopWrapMessage, NothingRejectedIsNoMessage) {
  const config::DeviceSpec d = looping_sim(config::SimDeviceSpec::Mode::kHand, 0.3);
  SimLoopJudged j;
  j.peak_m_per_s = 100.0;
  j.checked_s = 10.0;
  EXPECT_EQ(sim_loop_wrap_message(d, 1000.0, plan_sim_loop_check(0.0, 2.5, 1000.0, true), 10.0, j), "");
}

TEST(LoopWrapMessage, ATrajectoryWrapIsTheJumpRejected) {
  const config::DeviceSpec d = looping_sim(config::SimDeviceSpec::Mode::kTrajectory, 0.3);
  SimLoopJudged j;
  j.rejected = true;
  j.first_rejected_s = 2.501;
  j.first_verdict = SampleVerdict::kTooFast;
  j.first_step_m = 0.25;  // the step the loop rejected, not the waypoints' jump
  EXPECT_EQ(sim_loop_wrap_message(d, 1000.0, {}, 0.0, j), loop_wrap_warning("device.sim.waypoints", 0.25, 5.0, 1000.0));
  j.first_rejected_s = 0.75;
  j.first_verdict = SampleVerdict::kOutsideWorkspace;
  EXPECT_EQ(sim_loop_wrap_message(d, 1000.0, {}, 0.0, j),
            "device.sim.waypoints: the simulated tip (device.sim.mode trajectory) is rejected by the haptic loop "
            "0.75 s into the track's first pass, before it wraps (outside device.limits.workspace_radius_m): the "
            "force ramps out and back in on every pass");
}

TEST(LoopWrapMessage, AHandSaysHowFastOrHowFarAndWhatWasChecked) {
  const config::DeviceSpec d = looping_sim(config::SimDeviceSpec::Mode::kHand, 0.3);
  SimLoopJudged j;
  j.rejected = true;
  j.first_rejected_s = 2.52;
  j.first_verdict = SampleVerdict::kTooFast;
  j.peak_m_per_s = 6.5;
  j.farthest_m = 1.25;
  j.checked_s = 10.0;
  j.wraps = 3;
  EXPECT_EQ(sim_loop_wrap_message(d, 1000.0, plan_sim_loop_check(0.0, 2.5, 1000.0, true), 10.0, j),
            std::string(kHandWrapPrefix) +
                "0.3 m jump (device frame), and the hand (device.sim.mode hand) follows it through its spring at up "
                "to 6.5 m/s, more than device.limits.max_speed_m_per_s 5: the force ramps out and back in at every "
                "wrap (inputs rejected as too fast, then device lost); end the track where it starts for a seamless "
                "loop (checked at start: the hand simulated with no rendered force, read at haptics.rate_hz 1000 "
                "over the first 10 s, the first pass and 3 wraps)");
  j.first_verdict = SampleVerdict::kOutsideWorkspace;
  j.checked_s = 840.0;
  j.wraps = 1;
  SimLoopPlan two;
  two.first_pass = {0, 250000};
  two.wrap = {590000, 250000};
  EXPECT_EQ(sim_loop_wrap_message(d, 1000.0, two, 250.0, j),
            std::string(kHandWrapPrefix) +
                "0.3 m jump (device frame), and the hand (device.sim.mode hand) follows it through its spring out "
                "to 1.25 m from the device origin, beyond device.limits.workspace_radius_m 1: the force ramps out "
                "and back in at every wrap (inputs rejected outside the workspace, then device lost); end the track "
                "where it starts for a seamless loop (checked at start: the hand simulated with no rendered force, "
                "read at haptics.rate_hz 1000 over the first 250 s of the first pass, then from 590 s (started "
                "there on the track, at its velocity) to 840 s, 1 wrap; the whole run would take more than the "
                "check's 10^6 hand sub-steps)");
}

}  // namespace
}  // namespace tissue::haptics
