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
// thread has to make them more often (twice: the two grids drift against
// each other), or 100 Hz goes out at 30.
TEST(PublishSchedule, SnapshotsComeTwiceAsOftenAsAPublisherSendsThem) {
  for (const double hz : {30.0, 100.0, 500.0, 1000.0}) {
    const SimThreadOptions o = sim_thread_options(publishing_lcm(hz));
    EXPECT_LE(o.snapshot_every_s, 0.5 / hz) << hz << " Hz";
  }
  config::DaemonConfig dds = publishing_lcm(200.0);
  dds.publish.lcm.enabled = false;
  dds.publish.dds.enabled = true;
  EXPECT_LE(sim_thread_options(dds).snapshot_every_s, 0.5 / 200.0);
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

// Snapshots are made at the end of a sim step (1 ms paced steps, each
// ending 0 to 100 us late): on the due-time grid they come at the asked
// rate; "a period since the last one" rounded 1/300 s up to 4 steps (250/s).
TEST(PublishSchedule, SnapshotsAtStepEndsKeepTheAskedRate) {
  for (const double hz : {30.0, 100.0, 300.0, 500.0}) {
    const std::int64_t period_ns = static_cast<std::int64_t>(1e9 / hz);
    std::int64_t due_ns = 0;
    int made = 0;
    std::uint32_t jitter = 12345;  // a fixed LCG: the same "random" lateness every run
    for (std::int64_t step = 1; step <= 10'000; ++step) {
      jitter = jitter * 1664525u + 1013904223u;
      const std::int64_t end_ns = std::int64_t{1'000'000'000} + step * 1'000'000 + (jitter >> 8) % 100'000;
      if (end_ns < due_ns) continue;
      ++made;
      due_ns = next_snapshot_due_ns(due_ns, end_ns, period_ns);
    }
    // 10 s of steps: hz * 10 snapshots, give or take the first one.
    EXPECT_NEAR(made, hz * 10.0, 2.0) << hz << " Hz";
  }
}

// A step far longer than the period (a stall) re-anchors the grid: no burst
// of snapshots on the steps after it.
TEST(PublishSchedule, AStallDoesNotMakeABurstOfSnapshots) {
  const std::int64_t period_ns = 10'000'000;
  const std::int64_t due_ns = next_snapshot_due_ns(1'000'000'000, 1'000'000'000, period_ns);
  EXPECT_EQ(due_ns, 1'010'000'000);
  const std::int64_t after_stall_ns = 1'500'000'000;
  EXPECT_EQ(next_snapshot_due_ns(due_ns, after_stall_ns, period_ns), after_stall_ns + period_ns);
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
