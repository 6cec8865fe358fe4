// HapticThread: runs HapticLoop::tick at HapticSpec::rate_hz on its own
// thread, paced by clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME) with 1 ns
// timer slack, SCHED_FIFO and CPU pinning when the system allows them.
//
// Unprivileged (RLIMIT_RTPRIO 0) the thread stays SCHED_OTHER and says so in
// its SchedulingReport; the caller prints it. Lateness (wake-up minus the
// scheduled period boundary) and compute time (tick duration) of every period
// go into preallocated histograms, so percentiles can be read at any time.
// Missed periods are skipped (counted as overruns), keeping the phase.
//
// Stop: request_stop() asks the loop to ramp the force to zero (ramp_out_s,
// rate limited); the thread keeps ticking until the loop reports stopped(),
// then exits; join() waits for that.
#pragma once

#include <atomic>
#include <cstdint>
#include <string>
#include <thread>
#include <vector>

#include "config/daemon_config.hpp"
#include "haptics/haptic_loop.hpp"
#include "haptics/latency_histogram.hpp"

namespace tissue::haptics {

struct SchedulingReport {
  bool realtime = false;  // SCHED_FIFO obtained
  int priority = 0;       // its priority when realtime
  bool pinned = false;    // affinity set to the requested CPU
  bool timer_slack_set = false;
  std::string policy;           // e.g. "SCHED_FIFO priority 80" or "SCHED_OTHER (SCHED_FIFO 80 refused: ...)"
  std::string affinity;         // e.g. "cpu 1" or "not pinned (not requested)"
  std::string timer_slack;      // e.g. "1 ns" or "default (PR_SET_TIMERSLACK failed: ...)"
  std::string summary() const;  // one line for the log
};

// Applies the real-time settings to the CALLING thread (used by HapticThread
// and by benchmarks that must compare like with like).
SchedulingReport configure_current_thread(const config::RealtimeSpec& realtime, int priority);

struct MemoryLockReport {
  bool locked = false;
  std::string message;
};
// Tries mlockall(MCL_CURRENT | MCL_FUTURE) when wanted. Under a small
// RLIMIT_MEMLOCK, MCL_FUTURE would make later allocations fail, so when the
// limit leaves less than headroom_bytes above what is already locked the lock
// is undone (munlockall) and the report says so.
MemoryLockReport lock_memory(bool wanted, std::size_t headroom_bytes = std::size_t{256} << 20);

struct TimingSummary {
  std::uint64_t periods = 0;
  std::uint64_t overruns = 0;  // periods skipped because a tick ended past the next boundary
  std::int64_t lateness_p50_ns = 0, lateness_p99_ns = 0, lateness_p999_ns = 0, lateness_max_ns = 0;
  std::int64_t compute_p50_ns = 0, compute_p99_ns = 0, compute_p999_ns = 0, compute_max_ns = 0;
};
TimingSummary summarize(const LatencyHistogram& lateness, const LatencyHistogram& compute, std::uint64_t overruns);

// Monotonic clock in ns (same clock as std::chrono::steady_clock on Linux).
std::int64_t monotonic_now_ns() noexcept;

// A fixed workload for timing controls: `iterations` dependent square roots
// reading a table of kFixedWorkTableSize doubles (32 KB, as a tick reads its
// model and rings), the same instructions on every call. Timed beside a
// tick, its tail is what the machine alone (preemption, host interrupts,
// stalls of a virtual CPU) adds to a few microseconds of computing.
constexpr std::size_t kFixedWorkTableSize = 4096;
double fixed_work(int iterations, const double* table);

// A bare clock_nanosleep loop at rate_hz for `periods` periods on the calling
// thread, recording lateness: the baseline the haptic thread is judged against.
// With `work_time`, each period also runs fixed_work(work_iterations) and
// records how long it took.
void run_bare_timer_loop(double rate_hz, std::uint64_t periods, LatencyHistogram& lateness,
                         LatencyHistogram* work_time = nullptr, int work_iterations = 0);

class HapticThread {
 public:
  // Histograms: lateness in 1 us buckets up to 50 ms, compute time in 50 ns
  // buckets up to 2 ms.
  HapticThread(HapticLoop& loop, const config::HapticSpec& haptics, const config::RealtimeSpec& realtime);
  ~HapticThread();  // request_stop() + join()
  HapticThread(const HapticThread&) = delete;
  HapticThread& operator=(const HapticThread&) = delete;

  // Starts the thread and returns once it has applied its scheduling settings
  // (scheduling() is then valid). False if already started or the thread
  // could not be created.
  bool start(std::string* error);
  const SchedulingReport& scheduling() const noexcept { return scheduling_; }

  void request_stop() noexcept { loop_.request_stop(); }
  // Waits until the loop has ramped out and the thread exited.
  void join();
  bool running() const noexcept { return running_.load(std::memory_order_acquire); }

  TimingSummary timing() const { return summarize(lateness_, compute_, overruns_.load(std::memory_order_relaxed)); }
  const LatencyHistogram& lateness() const noexcept { return lateness_; }
  const LatencyHistogram& compute() const noexcept { return compute_; }

  // Benchmarks only: after every tick, run fixed_work of `iterations` (≤ 0:
  // none) in the same thread and period and record its time in control() —
  // a control measured in exactly the tick's conditions. Only before
  // start(): false (and nothing changed) once the thread was started.
  bool set_control_work(int iterations);
  const LatencyHistogram& control() const noexcept { return control_; }

 private:
  void run();

  HapticLoop& loop_;
  double rate_hz_;
  config::RealtimeSpec realtime_;
  SchedulingReport scheduling_;
  LatencyHistogram lateness_{1000, 50000};
  LatencyHistogram compute_{50, 40000};
  LatencyHistogram control_{50, 40000};
  int control_iterations_ = 0;
  volatile double control_sink_ = 0.0;
  std::vector<double> control_table_;
  std::atomic<std::uint64_t> overruns_{0};
  std::atomic<bool> configured_{false};
  std::atomic<bool> running_{false};
  std::thread thread_;
};

}  // namespace tissue::haptics
