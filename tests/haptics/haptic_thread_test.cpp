#include "haptics/haptic_thread.hpp"

#include <gtest/gtest.h>

#include <sys/mman.h>

#include <chrono>
#include <cstdio>
#include <limits>
#include <thread>
#include <vector>

#include "haptics/haptics_test_support.hpp"
#include "haptics/sim_device.hpp"

namespace tissue::haptics {
namespace {

TEST(HapticThread, RunsAt1kHzWithASimDeviceAndStopsWithTheForceRampedToZero) {
  config::DeviceSpec device_spec;
  device_spec.limits.ramp_in_s = 0.05;
  device_spec.sim.mode = config::SimDeviceSpec::Mode::kHand;
  device_spec.sim.waypoints = {{0.0, {0, 0, 0.005}}, {0.05, {0, 0, -0.005}}};  // press and hold
  SimDevice device(device_spec.sim);
  ASSERT_TRUE(device.start(nullptr));
  config::HapticSpec haptic_spec;  // 1 kHz
  config::RealtimeSpec realtime;   // tries SCHED_FIFO 80; unprivileged it falls back
  auto models = std::make_unique<LocalModelBuffer>();
  auto samples = std::make_unique<ToolSampleRing>();
  HapticLoop loop(device, device_spec, haptic_spec, *models, *samples);
  HapticThread thread(loop, haptic_spec, realtime);

  const LocalModel patch = test::make_flat_patch();
  std::uint64_t version = 0;
  auto publish = [&] {
    LocalModel& m = models->write_buffer();
    m = patch;
    m.version = ++version;
    m.built_ns = monotonic_now_ns();
    models->publish();
  };
  publish();
  std::string error;
  ASSERT_TRUE(thread.start(&error)) << error;
  const SchedulingReport& sched = thread.scheduling();
  std::printf("  %s\n", sched.summary().c_str());
  EXPECT_FALSE(sched.policy.empty());
  EXPECT_FALSE(sched.affinity.empty());
  EXPECT_TRUE(sched.timer_slack_set) << sched.timer_slack;

  // Act as the sim: keep the model fresh and consume the samples until 250 ticks ran.
  double max_force_N = 0.0;
  std::size_t consumed = 0;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  while (loop.heartbeat().load() < 250 && std::chrono::steady_clock::now() < deadline) {
    publish();
    consumed +=
        samples->drain([&](const ToolSample& s) { max_force_N = std::max(max_force_N, s.force_on_device_N.norm()); });
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  ASSERT_GE(loop.heartbeat().load(), 250u);
  EXPECT_GT(max_force_N, 0.5) << "the hand should be pressing by now";
  EXPECT_TRUE(thread.running());

  const auto stop_requested = std::chrono::steady_clock::now();
  thread.request_stop();
  // Keep the model fresh so only the stop drives the ramp-out.
  while (thread.running()) {
    publish();
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  thread.join();
  const double stop_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - stop_requested).count();
  std::vector<double> tail;
  samples->drain([&](const ToolSample& s) { tail.push_back(s.force_on_device_N.norm()); });
  ASSERT_FALSE(tail.empty());
  EXPECT_EQ(tail.back(), 0.0);
  for (std::size_t i = 1; i < tail.size(); ++i)
    EXPECT_LE(std::abs(tail[i] - tail[i - 1]), device_spec.limits.max_force_rate_N_per_s * 4e-3 + 1e-12);
  EXPECT_TRUE(loop.stopped());
  EXPECT_LT(stop_s, 1.0);

  const TimingSummary t = thread.timing();
  EXPECT_GE(t.periods, 250u);
  EXPECT_GT(t.compute_p50_ns, 0);
  std::printf(
      "  %llu periods, lateness p50 %lld us p99 %lld us max %lld us; compute p50 %lld ns p99.9 %lld ns; "
      "overruns %llu; ramp-out %.0f ms\n",
      static_cast<unsigned long long>(t.periods), static_cast<long long>(t.lateness_p50_ns / 1000),
      static_cast<long long>(t.lateness_p99_ns / 1000), static_cast<long long>(t.lateness_max_ns / 1000),
      static_cast<long long>(t.compute_p50_ns), static_cast<long long>(t.compute_p999_ns),
      static_cast<unsigned long long>(t.overruns), 1e3 * stop_s);
}

TEST(HapticThread, MemoryLockIsKeptOnlyWhenItCannotStarveLaterAllocations) {
  const MemoryLockReport r = lock_memory(true);
  std::printf("  %s\n", r.message.c_str());
  EXPECT_FALSE(r.message.empty());
  // Whatever happened, the process must still be able to allocate a lot.
  std::vector<char> big(std::size_t{64} << 20, 1);
  EXPECT_EQ(big[12345], 1);
  if (r.locked) munlockall();  // leave the test process as we found it
  EXPECT_EQ(lock_memory(false).message, "memory not locked (not requested)");
}

TEST(LatencyHistogram, PercentilesAreBucketUpperEdges) {
  LatencyHistogram h(1000, 100);
  for (int i = 0; i < 1000; ++i) h.record(i * 50);  // 0 .. 49,950 ns uniformly
  EXPECT_EQ(h.count(), 1000u);
  EXPECT_EQ(h.percentile_ns(0.5), 25000);
  EXPECT_EQ(h.percentile_ns(0.99), 50000);
  EXPECT_EQ(h.count_at_least(40000), 200u);  // 40,000 .. 49,950
  EXPECT_EQ(h.count_at_least(0), 1000u);
  h.record(10'000'000);  // overflow
  EXPECT_EQ(h.percentile_ns(1.0), 10'000'000);
  EXPECT_EQ(h.max_ns(), 10'000'000);
  EXPECT_EQ(h.count_at_least(40000), 201u);
  EXPECT_EQ(h.count_at_least(200'000), 1u);  // past the last bucket: the overflow only
}

// The daemon's histograms are never reset while the haptic thread runs: a
// service up for months puts more than 2^32 ticks in one bucket (49.7 days at
// 1 kHz), where 32-bit counts wrapped and the percentiles went wrong.
TEST(LatencyHistogram, BucketsCountYearsOfOneKilohertzTicks) {
  constexpr std::uint64_t kTenYearsOfTicks = 10ull * 366 * 86'400 * 1000;
  EXPECT_GE(std::numeric_limits<LatencyHistogram::Count>::max(), kTenYearsOfTicks);
}

// The benchmark control: fixed work after every tick, timed in its own
// histogram, one sample per tick; off unless asked for.
TEST(HapticThread, ControlWorkIsTimedAfterEveryTickOnlyWhenAsked) {
  for (const int iterations : {0, 200}) {
    config::DeviceSpec spec;
    spec.sim.waypoints = {{0.0, {0, 0, 0.01}}};  // held above the (absent) object
    SimDevice device(spec.sim);
    std::string error;
    ASSERT_TRUE(device.start(&error)) << error;
    config::HapticSpec haptics;
    auto models = std::make_unique<LocalModelBuffer>();
    auto samples = std::make_unique<ToolSampleRing>();
    HapticLoop loop(device, spec, haptics, *models, *samples);
    config::RealtimeSpec realtime;
    realtime.sched_fifo = false;
    HapticThread thread(loop, haptics, realtime);
    ASSERT_TRUE(thread.set_control_work(iterations));
    ASSERT_TRUE(thread.start(&error)) << error;
    EXPECT_FALSE(thread.set_control_work(iterations + 100)) << "changed under the running loop";
    while (loop.heartbeat().load() < 50) std::this_thread::sleep_for(std::chrono::milliseconds(5));
    thread.request_stop();
    thread.join();
    if (iterations == 0) {
      EXPECT_EQ(thread.control().count(), 0u);
    } else {
      EXPECT_GE(thread.control().count(), 49u);
      EXPECT_LE(thread.control().count(), thread.compute().count());
      EXPECT_GT(thread.control().percentile_ns(0.5), 0);
    }
  }
}

}  // namespace
}  // namespace tissue::haptics
