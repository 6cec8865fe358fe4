// SIGINT (Ctrl-C) and SIGTERM as a request to stop, not as death: for the
// work that runs until it is stopped or for a long while. `tissued --batch`
// and the trade study stop after the step in progress and keep what they
// measured; `tissue session replay` stops at its next wait and prints its
// summary; live `tissue x3d --animate` / `tissue render --sequence` stop
// collecting and export what came. The loops read flag() (or signal()).
// One implementation for all of them (tissue_util: no simulation, no LCM).
#pragma once

#include <signal.h>

#include <atomic>
#include <string>
#include <thread>

namespace tissue::util {

// A second signal sooner than this after the first is the same request.
inline constexpr double kRepeatWindow_s = 1.0;

// For as long as it lives, SIGINT and SIGTERM set flag() and signal()
// instead of killing.
// - How: the two signals are blocked in the thread that makes it, and so in
//   every thread started meanwhile (LCM's and Fast DDS's receive threads
//   inherit the mask), and a watcher thread takes them with sigtimedwait. No
//   such thread's system call is interrupted: a handler breaks off the call
//   the signal lands in whatever SA_RESTART says (select, poll, sleeps), and
//   an interrupted select() inside LCM comes back as an error the subscriber
//   takes for "LCM stopped receiving". A handler (SA_RESTART) is installed
//   as well, for a thread started before it that does not block them: the
//   kernel may hand a process-directed signal to such a thread, where the
//   default action would kill.
// - Asked again later than kRepeatWindow_s after the first, a signal takes
//   its default action and kills, for a user whose run does not stop soon
//   enough; within the window it is the same request delivered twice
//   (timeout(1) signals the command and then its whole process group) and
//   changes nothing.
// - A SIGINT ignored from the start stays ignored, as the shell meant: a
//   non-interactive shell starts `cmd &` with SIGINT ignored, so Ctrl-C in
//   the terminal of a script that started it is not for it (nohup ignores
//   SIGHUP, not SIGINT).
// - SIGTERM is honoured even when it was ignored at start (`trap '' TERM`
//   in the parent), as daemon/app/stop_signals.cpp did on purpose before
//   (keep_if_ignored=false): it is how kill, timeout(1) and a service
//   manager ask a run to stop, and a run deaf to it could only be SIGKILLed,
//   losing the report, the session's close or the frames collected.
// - SIGHUP is not taken: a closed terminal ends the process as before
//   (`nohup` or tmux for a long take). tissued as a service reloads on
//   SIGHUP with its own asio signal_set (service/service.cpp), not this.
// - The dispositions and the creating thread's mask before it are restored
//   after: a signal after that (during an export) acts as usual.
// Signals are process-wide: one at a time per process. A signal sent to the
// creating thread alone (raise(), pthread_kill) waits, blocked, until the
// destructor, which takes it as a request; kill(), Ctrl-C and timeout(1)
// signal the process and are seen at once.
class StopOnSignals {
 public:
  StopOnSignals();
  ~StopOnSignals();
  StopOnSignals(const StopOnSignals&) = delete;
  StopOnSignals& operator=(const StopOnSignals&) = delete;

  // 0 until a signal arrived, then the number of the first one (the one
  // that ended the run).
  const std::atomic<int>& signal() const;
  // false until a signal arrived: for loops that take a plain stop flag.
  const std::atomic<bool>& flag() const;
  bool stopped() const { return flag().load(std::memory_order_acquire); }

 private:
  void restore();  // the dispositions and this thread's mask before it

  sigset_t watched_{};
  sigset_t old_mask_{};
  struct sigaction before_int_ {};
  struct sigaction before_term_ {};
  std::atomic<bool> done_{false};
  std::thread watcher_;
};

// "SIGINT", "SIGTERM", or "signal N".
std::string signal_name(int signo);

// The exit code of a run a signal stopped: 128 + its number, as a shell
// reports a process the signal killed (SIGINT 130, SIGTERM 143).
constexpr int exit_code_for_signal(int signo) { return 128 + signo; }

}  // namespace tissue::util
