// SIGINT (Ctrl-C) and SIGTERM as a request to stop, for the `tissue` work
// that runs until it is stopped or collects for a while: `session replay`
// (stops and prints its summary), live `x3d --animate` and `render
// --sequence` (stop collecting and export what came).
//
// While a StopSignals lives, the two signals are blocked in the thread that
// made it, and so in every thread started meanwhile (LCM's and Fast DDS's
// receive threads inherit the mask), and a watcher thread takes them with
// sigtimedwait and sets flag(). No thread's system call is interrupted: a
// signal handler breaks off whatever call the signal lands in, and an
// interrupted wait inside LCM (its select()) can come back as an error,
// which the subscriber takes for "LCM stopped receiving". SIGINT ignored
// when the StopSignals is made (`nohup`, `cmd &` in a script) stays ignored,
// as tissue-batch does.
// The destructor unblocks them in its thread: a signal after that (during an
// export) ends the process as usual.
#pragma once

#include <signal.h>

#include <atomic>
#include <thread>

namespace tissue::cli {

class StopSignals {
 public:
  StopSignals();
  ~StopSignals();
  StopSignals(const StopSignals&) = delete;
  StopSignals& operator=(const StopSignals&) = delete;

  const std::atomic<bool>& flag() const { return stop_; }
  bool stopped() const { return stop_.load(std::memory_order_acquire); }
  // The signal that set the flag ("SIGINT", "SIGTERM"); "" before one came.
  const char* signal_name() const;

 private:
  sigset_t watched_{};
  sigset_t old_mask_{};
  std::atomic<bool> stop_{false};
  std::atomic<bool> done_{false};
  std::atomic<int> signo_{0};
  std::thread watcher_;
};

}  // namespace tissue::cli
