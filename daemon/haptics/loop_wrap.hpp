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

#include <string>

#include "config/daemon_config.hpp"

namespace tissue::haptics {

// The warning for a looping track whose wrap jumps jump_m (device frame) in
// one tick, when that is more than max_speed_m_per_s / rate_hz; empty
// otherwise. `key` is the config key to blame (e.g. "device.replay.loop").
std::string loop_wrap_warning(const std::string& key, double jump_m, double max_speed_m_per_s, double rate_hz);

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
// of milliseconds.
std::string sim_loop_wrap_warning(const config::DeviceSpec& device, double rate_hz);

}  // namespace tissue::haptics
