#include "util/stop_signals.hpp"

#include <pthread.h>
#include <time.h>

namespace tissue::util {

namespace {

// Touched from the handler: only lock-free atomics are async-signal-safe.
static_assert(std::atomic<int>::is_always_lock_free && std::atomic<bool>::is_always_lock_free &&
              std::atomic<long long>::is_always_lock_free);

std::atomic<int> g_signal{0};
std::atomic<bool> g_stop{false};
std::atomic<long long> g_first_ns{0};  // CLOCK_MONOTONIC of the first signal; 0 before it

constexpr long long kRepeatWindow_ns = static_cast<long long>(kRepeatWindow_s * 1e9);

long long monotonic_ns() {
  timespec now{};
  clock_gettime(CLOCK_MONOTONIC, &now);  // async-signal-safe
  return static_cast<long long>(now.tv_sec) * 1'000'000'000LL + now.tv_nsec;
}

// The default action of `signo`, from this thread, now. In the handler and
// in the watcher the signal is blocked: raised, it waits until unblocked.
// sigaction, raise and pthread_sigmask are async-signal-safe.
void die_of(int signo) {
  struct sigaction dfl {};
  dfl.sa_handler = SIG_DFL;
  sigemptyset(&dfl.sa_mask);
  sigaction(signo, &dfl, nullptr);
  raise(signo);
  sigset_t one;
  sigemptyset(&one);
  sigaddset(&one, signo);
  pthread_sigmask(SIG_UNBLOCK, &one, nullptr);
}

// Only the first: the destructor's late ones never kill.
bool note_first(int signo, long long now_ns, long long* first_ns) {
  *first_ns = 0;
  if (!g_first_ns.compare_exchange_strong(*first_ns, now_ns)) return false;
  g_signal.store(signo);
  g_stop.store(true, std::memory_order_release);  // the number before the flag: signal() after stopped()
  return true;
}

// From the handler (a thread that does not block the signals) and from the
// watcher (one that takes them): the same request, the same rules.
void note(int signo) {
  const long long now_ns = monotonic_ns();
  long long first_ns = 0;
  if (note_first(signo, now_ns, &first_ns)) return;
  if (now_ns - first_ns < kRepeatWindow_ns) return;  // the same request, delivered twice
  die_of(signo);                                     // asked again: the default action, death
}

void on_stop_signal(int signo) { note(signo); }

}  // namespace

StopOnSignals::StopOnSignals() {
  g_first_ns.store(0);
  g_signal.store(0);
  g_stop.store(false);
  sigaction(SIGINT, nullptr, &before_int_);
  sigaction(SIGTERM, nullptr, &before_term_);
  sigemptyset(&watched_);
  const bool int_ignored = !(before_int_.sa_flags & SA_SIGINFO) && before_int_.sa_handler == SIG_IGN;
  if (!int_ignored) sigaddset(&watched_, SIGINT);
  sigaddset(&watched_, SIGTERM);

  struct sigaction action {};
  action.sa_handler = on_stop_signal;
  action.sa_mask = watched_;  // one note() at a time per thread
  action.sa_flags = SA_RESTART;
  for (const int signo : {SIGINT, SIGTERM})
    if (sigismember(&watched_, signo)) sigaction(signo, &action, nullptr);

  pthread_sigmask(SIG_BLOCK, &watched_, &old_mask_);
  try {
    watcher_ = std::thread([this] {
      // Wakes every 50 ms to see whether it is still wanted.
      const timespec wait{0, 50'000'000};
      while (!done_.load(std::memory_order_relaxed)) {
        const int signo = sigtimedwait(&watched_, nullptr, &wait);
        if (signo > 0) note(signo);
      }
    });
  } catch (...) {
    // No thread to take them: the signals as they were, and the caller told.
    restore();
    throw;
  }
}

StopOnSignals::~StopOnSignals() {
  done_.store(true, std::memory_order_relaxed);
  watcher_.join();
  // What is still pending (sent to this thread alone, or in the watcher's
  // last instant) was sent while it lived: a request, not death under the
  // dispositions restored below.
  const timespec now{0, 0};
  for (int signo; (signo = sigtimedwait(&watched_, nullptr, &now)) > 0;) {
    long long first_ns = 0;
    note_first(signo, monotonic_ns(), &first_ns);
  }
  restore();
}

void StopOnSignals::restore() {
  sigaction(SIGINT, &before_int_, nullptr);
  sigaction(SIGTERM, &before_term_, nullptr);
  pthread_sigmask(SIG_SETMASK, &old_mask_, nullptr);
}

const std::atomic<int>& StopOnSignals::signal() const { return g_signal; }

const std::atomic<bool>& StopOnSignals::flag() const { return g_stop; }

std::string signal_name(int signo) {
  if (signo == SIGINT) return "SIGINT";
  if (signo == SIGTERM) return "SIGTERM";
  return "signal " + std::to_string(signo);
}

}  // namespace tissue::util
