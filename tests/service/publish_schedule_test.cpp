#include "service/publish_schedule.hpp"

#include <gtest/gtest.h>

namespace tissue::service {
namespace {

using Clock = std::chrono::steady_clock;
using std::chrono::milliseconds;

config::DaemonConfig publishing_lcm(double mesh_rate_hz) {
  config::DaemonConfig c;
  c.publish.lcm.enabled = true;
  c.publish.mesh_rate_hz = mesh_rate_hz;
  return c;
}

// The publisher sends the newest snapshot and skips one it has sent: the sim
// thread has to make them at least as often, or 100 Hz goes out at 30.
TEST(PublishSchedule, SnapshotsComeAtLeastAsOftenAsAPublisherSendsThem) {
  for (const double hz : {30.0, 100.0, 500.0, 1000.0}) {
    const SimThreadOptions o = sim_thread_options(publishing_lcm(hz));
    EXPECT_LE(o.snapshot_every_s, 1.0 / hz) << hz << " Hz";
  }
  config::DaemonConfig dds = publishing_lcm(200.0);
  dds.publish.lcm.enabled = false;
  dds.publish.dds.enabled = true;
  EXPECT_LE(sim_thread_options(dds).snapshot_every_s, 1.0 / 200.0);
}

// export_x3d reads the snapshot too: a slow publisher, or none, keeps 30 Hz;
// a fast rate with nothing publishing costs the sim thread nothing.
TEST(PublishSchedule, SnapshotsStayAt30HzForExportsAndWithoutPublishers) {
  EXPECT_DOUBLE_EQ(sim_thread_options(publishing_lcm(1.0)).snapshot_every_s, 1.0 / 30.0);
  config::DaemonConfig off = publishing_lcm(1000.0);
  off.publish.lcm.enabled = false;
  EXPECT_DOUBLE_EQ(sim_thread_options(off).snapshot_every_s, 1.0 / 30.0);
}

TEST(PublishSchedule, StatusAndEnergiesFollowTheHapticAndStatsRates) {
  config::DaemonConfig c = publishing_lcm(30.0);
  c.publish.haptic_rate_hz = 500.0;
  c.publish.stats_rate_hz = 10.0;
  const SimThreadOptions o = sim_thread_options(c);
  EXPECT_DOUBLE_EQ(o.status_every_s, 1.0 / 500.0);
  EXPECT_DOUBLE_EQ(o.energy_every_s, 1.0 / 10.0);
}

// A publish that takes 4 ms of a 33 ms period does not push the next one
// back: deadlines stay on the grid.
TEST(PublishSchedule, DeadlinesStayOnTheirGridWhateverThePublishTook) {
  const Clock::time_point t0 = Clock::time_point{} + std::chrono::hours(1);
  const auto period = milliseconds(33);
  Clock::time_point deadline = next_publish_time(Clock::time_point{}, t0, period);
  EXPECT_EQ(deadline, t0 + period);
  for (int i = 2; i <= 100; ++i) {
    const Clock::time_point now = deadline + milliseconds(4);  // the publish ran 4 ms
    deadline = next_publish_time(deadline, now, period);
    ASSERT_EQ(deadline, t0 + i * period) << "period " << i;
  }
}

// A timer far behind (the process was stopped, a write took seconds) starts
// a new grid now instead of firing a burst of catch-up publishes.
TEST(PublishSchedule, ATimerFarBehindStartsANewGridInsteadOfABurst) {
  const Clock::time_point t0 = Clock::time_point{} + std::chrono::hours(1);
  const auto period = milliseconds(10);
  const Clock::time_point late = t0 + milliseconds(500);
  EXPECT_EQ(next_publish_time(t0, late, period), late);
  // Behind by less than a period: still the grid (the next deadline may be
  // due at once, which catches up one period without a burst).
  EXPECT_EQ(next_publish_time(t0, t0 + milliseconds(15), period), t0 + period);
}

}  // namespace
}  // namespace tissue::service
