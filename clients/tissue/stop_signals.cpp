#include "tissue/stop_signals.hpp"

#include <pthread.h>

#include <ctime>

namespace tissue::cli {

StopSignals::StopSignals() {
  sigemptyset(&watched_);
  struct sigaction current {};
  if (sigaction(SIGINT, nullptr, &current) != 0 || current.sa_handler != SIG_IGN) sigaddset(&watched_, SIGINT);
  sigaddset(&watched_, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &watched_, &old_mask_);
  watcher_ = std::thread([this] {
    // Wakes every 50 ms to see whether it is still wanted.
    const timespec wait{0, 50'000'000};
    while (!done_.load(std::memory_order_relaxed)) {
      const int signo = sigtimedwait(&watched_, nullptr, &wait);
      if (signo > 0 && !stop_.load(std::memory_order_relaxed)) {
        signo_.store(signo, std::memory_order_relaxed);
        stop_.store(true, std::memory_order_release);  // signo_ before the flag: signal_name() after stopped()
      }
    }
  });
}

StopSignals::~StopSignals() {
  done_.store(true, std::memory_order_relaxed);
  watcher_.join();
  pthread_sigmask(SIG_SETMASK, &old_mask_, nullptr);
}

const char* StopSignals::signal_name() const {
  switch (signo_.load(std::memory_order_relaxed)) {
    case SIGINT:
      return "SIGINT";
    case SIGTERM:
      return "SIGTERM";
    default:
      return "";
  }
}

}  // namespace tissue::cli
