// Ctrl-C (SIGINT) and SIGTERM as a request to stop a long run at the next
// step and keep what it measured (a batch run, a trade study's sweep), not
// as death. The long loops read flag() before each step.
#pragma once

#include <signal.h>

#include <csignal>
#include <string>

namespace tissue::app {

// A second signal sooner than this after the first is the same request.
inline constexpr double kRepeatWindow_s = 1.0;

// For as long as it lives, SIGINT and SIGTERM set flag() to their number
// instead of killing; the dispositions before it are restored after.
// Asked again later than kRepeatWindow_s after the first, a signal takes its
// default action and kills, for a user whose run does not stop soon enough;
// within the window it is the same request delivered twice (timeout(1)
// signals the command and then its whole process group) and changes
// nothing. SA_RESTART: a file write the signal lands in is resumed, not
// failed with EINTR. A SIGINT ignored from the start (nohup, `cmd &` in a
// script) stays ignored, as the shell meant. One at a time per process (the
// flag is process-wide).
class StopOnSignals {
 public:
  StopOnSignals();
  ~StopOnSignals();
  StopOnSignals(const StopOnSignals&) = delete;
  StopOnSignals& operator=(const StopOnSignals&) = delete;
  // 0 until a signal arrived, then its number.
  const volatile std::sig_atomic_t* flag() const;

 private:
  struct sigaction before_int_ {};
  struct sigaction before_term_ {};
};

// "SIGINT", "SIGTERM", or "signal N".
std::string signal_name(int signo);

// The exit code of a run a signal stopped: 128 + its number, as a shell
// reports a process the signal killed (SIGINT 130, SIGTERM 143).
constexpr int exit_code_for_signal(int signo) { return 128 + signo; }

}  // namespace tissue::app
