#include "app/stop_signals.hpp"

#include <time.h>

namespace tissue::app {

namespace {

// Written only by on_stop_signal, read by the long loops.
volatile std::sig_atomic_t g_stop_signal = 0;
timespec g_first_signal{};  // when g_stop_signal was set

void on_stop_signal(int signo) {
  // clock_gettime, signal and raise are async-signal-safe.
  timespec now{};
  clock_gettime(CLOCK_MONOTONIC, &now);
  if (g_stop_signal == 0) {
    g_first_signal = now;
    g_stop_signal = signo;
    return;
  }
  const double since_s = static_cast<double>(now.tv_sec - g_first_signal.tv_sec) +
                         1e-9 * static_cast<double>(now.tv_nsec - g_first_signal.tv_nsec);
  if (since_s < kRepeatWindow_s) return;  // the same request, delivered twice
  std::signal(signo, SIG_DFL);            // asked again: the default action, death
  std::raise(signo);
}

void install(int signo, struct sigaction* before, bool keep_if_ignored) {
  sigaction(signo, nullptr, before);
  if (keep_if_ignored && before->sa_handler == SIG_IGN) return;
  struct sigaction action {};
  action.sa_handler = on_stop_signal;
  sigemptyset(&action.sa_mask);
  action.sa_flags = SA_RESTART;
  sigaction(signo, &action, nullptr);
}

}  // namespace

StopOnSignals::StopOnSignals() {
  g_stop_signal = 0;
  install(SIGINT, &before_int_, /*keep_if_ignored=*/true);
  install(SIGTERM, &before_term_, /*keep_if_ignored=*/false);
}

StopOnSignals::~StopOnSignals() {
  sigaction(SIGINT, &before_int_, nullptr);
  sigaction(SIGTERM, &before_term_, nullptr);
}

const volatile std::sig_atomic_t* StopOnSignals::flag() const { return &g_stop_signal; }

std::string signal_name(int signo) {
  if (signo == SIGINT) return "SIGINT";
  if (signo == SIGTERM) return "SIGTERM";
  return "signal " + std::to_string(signo);
}

}  // namespace tissue::app
