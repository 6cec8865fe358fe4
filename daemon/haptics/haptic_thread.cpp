#include "haptics/haptic_thread.hpp"

#include <pthread.h>
#include <sched.h>
#include <sys/mman.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <string>
#include <vector>

namespace tissue::haptics {
namespace {

std::string rlimit_text(int resource) {
  rlimit lim{};
  if (getrlimit(resource, &lim) != 0) return "unknown";
  if (lim.rlim_cur == RLIM_INFINITY) return "unlimited";
  return std::to_string(static_cast<unsigned long long>(lim.rlim_cur));
}

timespec to_timespec(std::int64_t ns) {
  timespec ts{};
  ts.tv_sec = static_cast<time_t>(ns / 1000000000);
  ts.tv_nsec = static_cast<long>(ns % 1000000000);
  return ts;
}

void sleep_until_ns(std::int64_t deadline_ns) noexcept {
  const timespec ts = to_timespec(deadline_ns);
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
  }
}

std::int64_t period_ns_for(double rate_hz) {
  return (std::isfinite(rate_hz) && rate_hz > 0.0) ? static_cast<std::int64_t>(std::llround(1e9 / rate_hz)) : 1000000;
}

// Next period boundary after `now`, keeping the phase of `next`.
std::int64_t advance(std::int64_t next_ns, std::int64_t period_ns, std::int64_t now_ns, std::uint64_t* skipped) {
  next_ns += period_ns;
  if (next_ns <= now_ns) {
    const std::int64_t missed = (now_ns - next_ns) / period_ns + 1;
    *skipped += static_cast<std::uint64_t>(missed);
    next_ns += missed * period_ns;
  }
  return next_ns;
}

// VmLck of this process in bytes (0 if unknown).
std::size_t locked_bytes() {
  std::ifstream status("/proc/self/status");
  std::string line;
  while (std::getline(status, line))
    if (line.rfind("VmLck:", 0) == 0) return static_cast<std::size_t>(std::stoull(line.substr(6))) * 1024;
  return 0;
}

// CAP_IPC_LOCK in the effective set: RLIMIT_MEMLOCK does not bind us.
bool has_cap_ipc_lock() {
  constexpr int kCapIpcLock = 14;  // linux/capability.h
  std::ifstream status("/proc/self/status");
  std::string line;
  while (std::getline(status, line))
    if (line.rfind("CapEff:", 0) == 0) return (std::stoull(line.substr(7), nullptr, 16) >> kCapIpcLock) & 1ULL;
  return false;
}

}  // namespace

std::int64_t monotonic_now_ns() noexcept {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1000000000 + ts.tv_nsec;
}

std::string SchedulingReport::summary() const {
  return "haptic thread: " + policy + "; affinity " + affinity + "; timer slack " + timer_slack;
}

SchedulingReport configure_current_thread(const config::RealtimeSpec& realtime, int priority) {
  SchedulingReport r;
  // Default slack is 50 us: it alone would add ~50 us to every wake-up (STACK.md).
  if (prctl(PR_SET_TIMERSLACK, 1UL, 0, 0, 0) == 0) {
    r.timer_slack_set = true;
    r.timer_slack = "1 ns";
  } else {
    r.timer_slack = std::string("default (PR_SET_TIMERSLACK failed: ") + std::strerror(errno) + ")";
  }

  if (realtime.haptic_cpu >= 0) {
    cpu_set_t set;
    CPU_ZERO(&set);
    if (realtime.haptic_cpu < CPU_SETSIZE) CPU_SET(realtime.haptic_cpu, &set);
    const int rc =
        realtime.haptic_cpu < CPU_SETSIZE ? pthread_setaffinity_np(pthread_self(), sizeof(set), &set) : EINVAL;
    r.pinned = rc == 0;
    r.affinity =
        r.pinned ? "cpu " + std::to_string(realtime.haptic_cpu)
                 : "not pinned (cpu " + std::to_string(realtime.haptic_cpu) + " refused: " + std::strerror(rc) + ")";
  } else {
    r.affinity = "not pinned (not requested)";
  }

  if (realtime.sched_fifo) {
    sched_param param{};
    param.sched_priority = priority;
    const int rc = pthread_setschedparam(pthread_self(), SCHED_FIFO, &param);
    if (rc == 0) {
      r.realtime = true;
      r.priority = priority;
      r.policy = "SCHED_FIFO priority " + std::to_string(priority);
    } else {
      r.policy = "SCHED_OTHER (SCHED_FIFO " + std::to_string(priority) + " refused: " + std::strerror(rc) +
                 "; RLIMIT_RTPRIO " + rlimit_text(RLIMIT_RTPRIO) + ")";
    }
  } else {
    r.policy = "SCHED_OTHER (SCHED_FIFO not requested)";
  }
  return r;
}

MemoryLockReport lock_memory(bool wanted, std::size_t headroom_bytes) {
  MemoryLockReport r;
  if (!wanted) {
    r.message = "memory not locked (not requested)";
    return r;
  }
  rlimit lim{};
  getrlimit(RLIMIT_MEMLOCK, &lim);
  const std::string limit_text = lim.rlim_cur == RLIM_INFINITY
                                     ? std::string("unlimited")
                                     : std::to_string(static_cast<unsigned long long>(lim.rlim_cur >> 20)) + " MiB";
  if (mlockall(MCL_CURRENT | MCL_FUTURE) != 0) {
    r.message = std::string("memory not locked: mlockall failed: ") + std::strerror(errno) + " (RLIMIT_MEMLOCK " +
                limit_text + ")";
    return r;
  }
  const std::size_t locked = locked_bytes();
  // CAP_IPC_LOCK lifts the limit; without it, with MCL_FUTURE, every later
  // allocation counts against it.
  if (!has_cap_ipc_lock() && lim.rlim_cur != RLIM_INFINITY && locked + headroom_bytes > lim.rlim_cur) {
    munlockall();
    r.message = "memory not locked: RLIMIT_MEMLOCK " + limit_text + " leaves less than " +
                std::to_string(headroom_bytes >> 20) + " MiB above the " + std::to_string(locked >> 20) +
                " MiB already locked, so later allocations would fail; undone with munlockall";
    return r;
  }
  r.locked = true;
  r.message = "memory locked (" + std::to_string(locked >> 20) + " MiB now, RLIMIT_MEMLOCK " + limit_text + ")";
  return r;
}

TimingSummary summarize(const LatencyHistogram& lateness, const LatencyHistogram& compute, std::uint64_t overruns) {
  TimingSummary t;
  t.periods = lateness.count();
  t.overruns = overruns;
  t.lateness_p50_ns = lateness.percentile_ns(0.5);
  t.lateness_p99_ns = lateness.percentile_ns(0.99);
  t.lateness_p999_ns = lateness.percentile_ns(0.999);
  t.lateness_max_ns = lateness.max_ns();
  t.compute_p50_ns = compute.percentile_ns(0.5);
  t.compute_p99_ns = compute.percentile_ns(0.99);
  t.compute_p999_ns = compute.percentile_ns(0.999);
  t.compute_max_ns = compute.max_ns();
  return t;
}

double fixed_work(int iterations, const double* table) {
  double x = 1.0;
  for (int k = 0; k < iterations; ++k)
    x = std::sqrt(x * 1.0000001 + table[(static_cast<std::size_t>(k) * 67) % kFixedWorkTableSize]);
  return x;
}

void run_bare_timer_loop(double rate_hz, std::uint64_t periods, LatencyHistogram& lateness, LatencyHistogram* work_time,
                         int work_iterations) {
  const std::int64_t period_ns = period_ns_for(rate_hz);
  std::uint64_t skipped = 0;
  std::int64_t next_ns = monotonic_now_ns() + period_ns;
  const std::vector<double> table(work_time ? kFixedWorkTableSize : 0, 1.0);  // touched before the loop
  volatile double sink = 0.0;
  for (std::uint64_t i = 0; i < periods; ++i) {
    sleep_until_ns(next_ns);
    const std::int64_t wake_ns = monotonic_now_ns();
    lateness.record(wake_ns - next_ns);
    if (work_time) {
      sink = fixed_work(work_iterations, table.data());
      work_time->record(monotonic_now_ns() - wake_ns);
    }
    next_ns = advance(next_ns, period_ns, monotonic_now_ns(), &skipped);
  }
  (void)sink;
}

HapticThread::HapticThread(HapticLoop& loop, const config::HapticSpec& haptics, const config::RealtimeSpec& realtime)
    : loop_(loop), rate_hz_(haptics.rate_hz), realtime_(realtime) {}

HapticThread::~HapticThread() {
  if (thread_.joinable()) {
    request_stop();
    join();
  }
}

bool HapticThread::start(std::string* error) {
  if (thread_.joinable()) {
    if (error) *error = "haptic thread: already started";
    return false;
  }
  configured_.store(false, std::memory_order_relaxed);
  running_.store(true, std::memory_order_release);
  try {
    thread_ = std::thread([this] { run(); });
  } catch (const std::system_error& e) {
    running_.store(false, std::memory_order_release);
    if (error) *error = std::string("haptic thread: cannot start: ") + e.what();
    return false;
  }
  // The thread configures itself in its first microseconds; a short poll keeps
  // this free of condition variables the thread would have to signal.
  while (!configured_.load(std::memory_order_acquire)) {
    const timespec pause{0, 100000};
    nanosleep(&pause, nullptr);
  }
  return true;
}

bool HapticThread::set_control_work(int iterations) {
  if (thread_.joinable()) return false;  // the running loop reads these without synchronisation
  control_iterations_ = std::max(0, iterations);
  control_table_.assign(control_iterations_ > 0 ? kFixedWorkTableSize : 0, 1.0);
  return true;
}

void HapticThread::join() {
  if (thread_.joinable()) thread_.join();
}

void HapticThread::run() {
  scheduling_ = configure_current_thread(realtime_, realtime_.haptic_priority);
  configured_.store(true, std::memory_order_release);

  const std::int64_t period_ns = period_ns_for(rate_hz_);
  std::uint64_t skipped = 0;
  std::int64_t next_ns = monotonic_now_ns() + period_ns;
  loop_.start(next_ns - period_ns);
  for (;;) {
    sleep_until_ns(next_ns);
    const std::int64_t wake_ns = monotonic_now_ns();
    loop_.tick(wake_ns);
    const std::int64_t done_ns = monotonic_now_ns();
    lateness_.record(wake_ns - next_ns);
    compute_.record(done_ns - wake_ns);
    if (loop_.stopped()) break;
    std::int64_t end_ns = done_ns;
    if (control_iterations_ > 0) {
      control_sink_ = fixed_work(control_iterations_, control_table_.data());
      end_ns = monotonic_now_ns();
      control_.record(end_ns - done_ns);
    }
    next_ns = advance(next_ns, period_ns, end_ns, &skipped);
    overruns_.store(skipped, std::memory_order_relaxed);
  }
  running_.store(false, std::memory_order_release);
}

}  // namespace tissue::haptics
