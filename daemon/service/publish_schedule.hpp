// When the service publishes: the sim thread's rates that the config's
// publish rates depend on, and the deadline of each publish timer. Free
// functions of plain values, so the rules are tested without threads.
#pragma once

#include <chrono>

#include "config/daemon_config.hpp"
#include "service/sim_thread.hpp"

namespace tissue::service {

// The sim thread's options for a config: it must refresh what a publisher
// sends at least as often as the publisher sends it, or the publisher finds
// the same snapshot again and skips it (a mesh_rate_hz of 100 went out at 30).
SimThreadOptions sim_thread_options(const config::DaemonConfig& c);

// The deadline after `previous` for a timer of period `period`: a fixed grid
// (previous + period), so the publish's own time does not stretch every
// period (a 4 ms mesh write turned 30 Hz into 27 Hz). A timer behind its grid
// by more than a period (a slow write, the process stopped) starts a new grid
// at `now` instead of publishing a burst to catch up; an unset `previous`
// (a timer never armed) starts one a period from now.
std::chrono::steady_clock::time_point next_publish_time(std::chrono::steady_clock::time_point previous,
                                                        std::chrono::steady_clock::time_point now,
                                                        std::chrono::steady_clock::duration period);

}  // namespace tissue::service
