// Shared by every suite that touches files or runs programs: a scratch
// directory that cleans up after itself, and running a shell command line
// with its output captured.
#pragma once

#include <optional>
#include <string>
#include <vector>

namespace tissue::testing {

// A fresh private directory under $TMPDIR (or /tmp), removed with everything
// in it at the end of the test. Its path is short (a long $TMPDIR is ignored)
// because Unix socket paths inside it must fit 107 bytes.
class TempDir {
 public:
  TempDir();
  ~TempDir();
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  const std::string& path() const { return path_; }
  std::string operator/(const std::string& name) const { return path_ + "/" + name; }

 private:
  std::string path_;
};

struct RunResult {
  int exit_code = -1;  // -1: killed by a signal
  int signal = 0;      // the signal that ended it, 0 if none
  std::string out, err;
};

// Runs a shell command line (sh -c), its stdout and stderr captured through
// files in `scratch` (each run gets its own, kept for a failing test to show).
RunResult run(const std::string& command, const TempDir& scratch);
// `s` single-quoted for the shell.
std::string quote(const std::string& s);
// A file's bytes; empty when it cannot be read.
std::string slurp(const std::string& path);
// Writes `text` to `path` (a failed write fails the test).
void write_text(const std::string& path, const std::string& text);

// A program running in the background (fork + exec, no shell), its stdout
// and stderr in files, for tests that signal a long run mid-way. Killed and
// reaped at the end if it still runs.
class BackgroundProcess {
 public:
  // `argv[0]` is the program's path. `ignore_sigint`: the child starts with
  // SIGINT ignored, as `cmd &` in a script would start it; otherwise at its
  // default action (whatever the test process has), no signal blocked.
  BackgroundProcess(const std::vector<std::string>& argv, const std::string& out_path, const std::string& err_path,
                    bool ignore_sigint = false);
  ~BackgroundProcess();
  BackgroundProcess(const BackgroundProcess&) = delete;
  BackgroundProcess& operator=(const BackgroundProcess&) = delete;

  bool started() const { return pid_ > 0; }
  // Waits up to `seconds` for `text` to appear in its stdout (`in_stderr`:
  // stderr); false if it did not.
  bool wait_for_output(const std::string& text, double seconds, bool in_stderr = false) const;
  bool signal(int signo) const;
  // Waits up to `seconds` for it to end: its wait status, or nullopt while it
  // still runs.
  std::optional<int> wait_for_exit(double seconds);
  std::string out() const;
  std::string err() const;

 private:
  std::string out_path_, err_path_;
  int pid_ = -1;
  bool exited_ = false;
};

// The pid of a process that has exited and been reaped: a pid nothing runs
// under (until the kernel reuses it), for tests of stale-pid handling.
int gone_pid();

}  // namespace tissue::testing
