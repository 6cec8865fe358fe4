// A looping device track (device.replay.loop; device.sim.loop with
// mode: trajectory) goes from its last point back to its first in one tick.
// No return path is added: one could press the hand through the object. When
// that jump is longer than the haptic loop accepts in one tick, the loop
// rejects it as a glitch (too fast) and, until the hand has been still long
// enough, takes the device as lost: the force ramps out at every wrap and back
// in after it. With device.sim mode: hand, the target jumps and the hand
// follows through its spring, over several ticks, but a long jump still swings
// it faster than the loop accepts. The daemon says so once when the device
// starts.
#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include "config/daemon_config.hpp"
#include "haptics/haptic_loop.hpp"

namespace tissue::haptics {

// The warning for a looping track whose wrap jumps jump_m (device frame) in
// one tick, when that is more than max_speed_m_per_s / rate_hz; empty
// otherwise. `key` is the config key to blame (e.g. "device.replay.loop").
// no_sample_s > 0: the wrap is no jump in one tick but passes through that
// much wall time without samples (a replay's rows before the device's first
// sample, or a tail after its last played as no samples,
// ReplayDevice::loop_wrap_no_sample_s): the loop judges the first sample
// after it against the last one before it over that time (at least a tick),
// so the warning comes when jump_m is more than max_speed_m_per_s times it.
std::string loop_wrap_warning(const std::string& key, double jump_m, double max_speed_m_per_s, double rate_hz,
                              double no_sample_s = 0.0);

// The warning for a looping simulated device (kind sim, device.sim.loop),
// blamed on device.sim.waypoints; empty when it does not loop or the loop
// takes it. Both modes, one check: a copy of the SimDevice (same spec) is read
// at rate_hz over the first pass and three wraps (each followed by a whole
// period; at most 10^6 hand sub-steps) with no rendered force, and every
// sample judged by the loop's rule (judge_device_sample), so what the hand
// does over several wraps, while moving, or read below ~31 Hz is what the
// loop will see. A track too long for that budget to reach its first wrap is
// checked in two windows of half the budget: the first pass from its start,
// and the wrap from 10 s before it, the copy started there on the track; so
// the wrap is always checked. A rejection before the first wrap is the
// track's own, and said so. Start-time code: allocates, runs for up to tens
// of milliseconds. The three steps below, in order:
// plan_sim_loop_check, judge_sim_loop_window (per window),
// sim_loop_wrap_message.
std::string sim_loop_wrap_warning(const config::DeviceSpec& device, double rate_hz);

// Wraps checked after the first pass, each followed by a whole period.
inline constexpr int kSimLoopWrapsChecked = 3;
// The check's cost bound: hand sub-steps (reads for a trajectory), so the
// daemon's start stays fast whatever the track's length.
inline constexpr double kSimLoopCheckSubsteps = 1e6;
// How far before the wrap the wrap window of a two-window check starts: long
// enough for a damped hand to forget that it was started on the target.
inline constexpr double kSimLoopWrapLeadIn_s = 10.0;

// Reads first_read .. first_read + reads - 1 of the device copy, read k at
// k / rate_hz of the timeline (the loop's own cadence).
struct SimLoopWindow {
  std::int64_t first_read = 0;
  std::int64_t reads = 0;
};

// The windows the check reads. One window (wrap.reads == 0) from the start
// when the budget reaches the first wrap and kSimLoopWrapLeadIn_s past it:
// the first pass and as many of kSimLoopWrapsChecked wraps as fit. Otherwise
// two windows of half the budget each: first_pass from the start and wrap
// from kSimLoopWrapLeadIn_s before the wrap (at most a quarter of the budget)
// through as many wraps as fit, so the wrap is always checked.
//
// Known limits, both because the budget bounds the daemon's start (a track
// may be hours long; checking all of it would be unbounded):
//  - the first pass between the two windows is not read: a rejection there
//    (the track's own, on every pass) is not warned about;
//  - the wrap window starts the hand fresh on the track (on the target,
//    moving with it; SimDevice::start_timeline_at), not where the first pass
//    left it. A damped hand forgets how it got there within a few of its time
//    constants 2 m / c (50 ms for the default hand), well inside the lead-in;
//    an undamped hand's swing left from before the lead-in is not carried in.
//    Carrying it would mean simulating the whole first pass: the unbounded
//    cost the budget exists to avoid. (The windows never meet for real
//    rates: that needs a budget under about 4 lead-ins of reads, a rate
//    above ~25 kHz.)
// No windows (both reads 0) for a span, rate or budget that is not positive
// and finite. `hand`: device.sim.mode hand, whose read costs
// SimDevice::hand_substeps(1 / rate_hz) sub-steps (a trajectory's costs 1).
struct SimLoopPlan {
  SimLoopWindow first_pass;
  SimLoopWindow wrap;
};
SimLoopPlan plan_sim_loop_check(double first_s, double last_s, double rate_hz, bool hand,
                                double max_substeps = kSimLoopCheckSubsteps);

// What the device copy did as the loop judged it, over the windows checked
// so far.
struct SimLoopJudged {
  bool rejected = false;
  double first_rejected_s = 0.0;  // timeline time of the first rejected sample
  SampleVerdict first_verdict = SampleVerdict::kAccepted;
  double first_step_m = 0.0;  // its distance from the last accepted sample of its window
  double peak_m_per_s = 0.0;  // fastest as the loop measures it (velocity or jump), from the first wrap on
  double farthest_m = 0.0;    // farthest from the origin, from the first wrap on
  double checked_s = 0.0;     // timeline time of the last read
  int wraps = 0;              // wraps at or before checked_s
};

// Reads a fresh copy of device.sim (kind sim, looping, two or more waypoints)
// over `window` at rate_hz with no rendered force, started on the track at
// the window's first read (SimDevice::start_timeline_at), and judges every
// sample with judge_device_sample and device.limits; the window's first
// sample has nothing to be judged against, as the loop's own first. Folds
// the window into `earlier` (what earlier windows found: their first
// rejection stays the first, peaks and farthest are the larger, checked_s
// and wraps are this window's end). nullopt when the copy does not start or
// read (SimDevice::start says why when the device itself starts).
std::optional<SimLoopJudged> judge_sim_loop_window(const config::DeviceSpec& device, double rate_hz,
                                                   const SimLoopWindow& window, const SimLoopJudged& earlier = {});

// The warning for what the check found: empty when nothing was rejected; the
// track's own when the first rejection is before the first wrap; for a
// trajectory loop_wrap_warning's text with the rejected step; for a hand the
// jump, how fast or far the hand swung, and what was checked (plan; the
// first pass window ended at first_pass_checked_s).
std::string sim_loop_wrap_message(const config::DeviceSpec& device, double rate_hz, const SimLoopPlan& plan,
                                  double first_pass_checked_s, const SimLoopJudged& judged);

}  // namespace tissue::haptics
