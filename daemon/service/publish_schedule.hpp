// When the service publishes: the sim thread's rates that the config's
// publish rates depend on, and the deadline of each publish timer. Free
// functions of plain values, so the rules are tested without threads.
#pragma once

#include <chrono>

#include "config/daemon_config.hpp"
#include "service/sim_thread.hpp"

namespace tissue::service {

// The sim thread's options for a config: it must refresh what a publisher
// sends more often than the publisher sends it, or the publisher finds the
// same snapshot again and skips it (a mesh_rate_hz of 100 went out at 30).
// Twice as often: the two run on separate clocks' grids (the sim thread's
// steps, the io thread's timer), so at equal rates the phase jitter between
// them would still leave some ticks without a new snapshot.
SimThreadOptions sim_thread_options(const config::DaemonConfig& c);

// The deadline after `previous` for a timer of period `period`: a fixed grid
// (previous + period), so the publish's own time does not stretch every
// period (a 4 ms mesh write turned 30 Hz into 27 Hz). A timer behind its grid
// by more than a period (a slow write, the process stopped) starts a new grid
// at `now` instead of publishing a burst to catch up; an unset `previous`
// (a timer never armed) starts one a period from now.
// When the sim thread makes its next snapshot, given the due time `due_ns`
// the one it just made at `now_ns` was for: the same fixed grid. Snapshots
// come at the end of a step, so "a period since the last one" rounded every
// period up to whole steps, plus the step's jitter (1/300 s at 1 ms steps
// gave 250 a second); on the grid they average the period. More than a
// period behind (a long step), the grid starts again a period after now.
std::int64_t next_snapshot_due_ns(std::int64_t due_ns, std::int64_t now_ns, std::int64_t period_ns);

std::chrono::steady_clock::time_point next_publish_time(std::chrono::steady_clock::time_point previous,
                                                        std::chrono::steady_clock::time_point now,
                                                        std::chrono::steady_clock::duration period);

}  // namespace tissue::service
