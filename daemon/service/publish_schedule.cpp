#include "service/publish_schedule.hpp"

#include <algorithm>

namespace tissue::service {

SimThreadOptions sim_thread_options(const config::DaemonConfig& c) {
  SimThreadOptions o;
  o.priority = c.realtime.sched_fifo ? c.realtime.sim_priority : 0;
  // Status feeds the haptic_state messages too: refresh it at their rate.
  o.status_every_s = 1.0 / std::max(c.publish.haptic_rate_hz, 20.0);
  // Energies are only read by sim_stats and `status`: sum them at the stats rate.
  o.energy_every_s = 1.0 / std::max(c.publish.stats_rate_hz, 1.0);
  // Snapshots feed export_x3d as well, so never below 30 Hz; faster only for
  // a publisher (building one costs the sim thread), twice its rate.
  const bool publishing = c.publish.lcm.enabled || c.publish.dds.enabled;
  o.snapshot_every_s = 1.0 / std::max(publishing ? 2.0 * c.publish.mesh_rate_hz : 0.0, 30.0);
  return o;
}

std::int64_t next_snapshot_due_ns(std::int64_t due_ns, std::int64_t now_ns, std::int64_t period_ns) {
  const std::int64_t next = due_ns + period_ns;
  return next + period_ns < now_ns ? now_ns + period_ns : next;
}

std::chrono::steady_clock::time_point next_publish_time(std::chrono::steady_clock::time_point previous,
                                                        std::chrono::steady_clock::time_point now,
                                                        std::chrono::steady_clock::duration period) {
  if (previous == std::chrono::steady_clock::time_point{}) return now + period;
  const auto next = previous + period;
  return next + period < now ? now : next;
}

}  // namespace tissue::service
