#include "support/process_support.hpp"

#include <gtest/gtest.h>
#include <stdlib.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <system_error>
#include <thread>

namespace tissue::testing {

TempDir::TempDir() {
  const char* base = std::getenv("TMPDIR");
  std::string tmpl = std::string(base && *base && std::string(base).size() < 40 ? base : "/tmp") + "/tt.XXXXXX";
  if (::mkdtemp(tmpl.data()) == nullptr) throw std::runtime_error("mkdtemp failed for " + tmpl);
  path_ = tmpl;
}

TempDir::~TempDir() {
  std::error_code ec;
  std::filesystem::remove_all(path_, ec);
}

std::string quote(const std::string& s) {
  std::string out = "'";
  for (const char c : s) out += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return out + "'";
}

std::string slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

void write_text(const std::string& path, const std::string& text) {
  std::ofstream f(path, std::ios::binary);
  f << text;
  ASSERT_TRUE(f.good()) << path;
}

RunResult run(const std::string& command, const TempDir& scratch) {
  static int counter = 0;
  const std::string out = scratch / ("run" + std::to_string(counter) + ".out");
  const std::string err = scratch / ("run" + std::to_string(counter) + ".err");
  ++counter;
  const int status = std::system(("(" + command + ") >" + quote(out) + " 2>" + quote(err)).c_str());
  RunResult r;
  if (status != -1 && WIFEXITED(status)) r.exit_code = WEXITSTATUS(status);
  if (status != -1 && WIFSIGNALED(status)) r.signal = WTERMSIG(status);
  r.out = slurp(out);
  r.err = slurp(err);
  return r;
}

int gone_pid() {
  const pid_t child = ::fork();
  if (child < 0) throw std::runtime_error("fork failed");
  if (child == 0) ::_exit(0);
  if (::waitpid(child, nullptr, 0) != child) throw std::runtime_error("waitpid failed");
  return child;
}

BackgroundProcess::BackgroundProcess(const std::vector<std::string>& argv, const std::string& out_path,
                                     const std::string& err_path, bool ignore_sigint)
    : out_path_(out_path), err_path_(err_path) {
  std::vector<char*> args;
  for (const std::string& a : argv) args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);
  std::fflush(nullptr);  // nothing buffered is written twice
  pid_ = ::fork();
  if (pid_ != 0) return;
  // exec keeps an ignored disposition and the signal mask: ctest started by
  // a script with `&` runs with SIGINT ignored, and a test may run with
  // signals blocked (a StopOnSignals alive); the child would then ignore or
  // hold the SIGINT the test sends. It starts as from a terminal unless asked.
  std::signal(SIGINT, ignore_sigint ? SIG_IGN : SIG_DFL);
  sigset_t none;
  sigemptyset(&none);
  ::sigprocmask(SIG_SETMASK, &none, nullptr);
  if (!std::freopen(out_path_.c_str(), "w", stdout) || !std::freopen(err_path_.c_str(), "w", stderr)) ::_exit(120);
  ::execv(args[0], args.data());
  ::_exit(121);
}

BackgroundProcess::~BackgroundProcess() {
  if (pid_ > 0 && !exited_) {
    ::kill(pid_, SIGKILL);
    ::waitpid(pid_, nullptr, 0);
  }
}

bool BackgroundProcess::wait_for_output(const std::string& text, double seconds, bool in_stderr) const {
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  do {
    if ((in_stderr ? err() : out()).find(text) != std::string::npos) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  } while (std::chrono::steady_clock::now() < end);
  return false;
}

bool BackgroundProcess::signal(int signo) const { return pid_ > 0 && !exited_ && ::kill(pid_, signo) == 0; }

std::optional<int> BackgroundProcess::wait_for_exit(double seconds) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  do {
    int status = 0;
    if (::waitpid(pid_, &status, WNOHANG) == pid_) {
      exited_ = true;
      return status;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  } while (std::chrono::steady_clock::now() < end);
  return std::nullopt;
}

std::string BackgroundProcess::out() const { return slurp(out_path_); }
std::string BackgroundProcess::err() const { return slurp(err_path_); }

}  // namespace tissue::testing
