// Lints systemd/tissued.service with systemd's own tools. systemd-analyze
// exits 0 even on unknown keys or bad values (it prints "ignoring"), so the
// lint passes only when it prints nothing at all. ExecStart must name an
// existing executable, so the test rewrites it to the tissued just built.
#include <gtest/gtest.h>

#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iterator>
#include <optional>
#include <sstream>
#include <string>

#include "control/temp_dir.hpp"

namespace {

using tissue::control::testing::TempDir;

const std::string kUnit = std::string(TISSUE_SOURCE_DIR) + "/systemd/tissued.service";

std::string read_file(const std::string& path) {
  std::ifstream in(path);
  EXPECT_TRUE(in) << "cannot open " << path;
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

bool have_systemd_analyze() {
  for (const char* dir : {"/usr/bin", "/bin", "/usr/local/bin"})
    if (::access((std::string(dir) + "/systemd-analyze").c_str(), X_OK) == 0) return true;
  return false;
}

// The value of the first "Key=" line of a unit, or nullopt.
std::optional<std::string> directive(const std::string& unit, const std::string& key) {
  std::istringstream in(unit);
  for (std::string line; std::getline(in, line);)
    if (line.rfind(key + "=", 0) == 0) return line.substr(key.size() + 1);
  return std::nullopt;
}

bool all_digits(const std::string& s) { return !s.empty() && s.find_first_not_of("0123456789") == std::string::npos; }

// Runs a shell command; returns its exit status and combined stdout+stderr.
std::pair<int, std::string> run(const std::string& command) {
  std::string out;
  FILE* p = ::popen((command + " 2>&1").c_str(), "r");
  if (p == nullptr) return {-1, "popen failed"};
  char buf[4096];
  std::size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, p)) > 0) out.append(buf, n);
  const int status = ::pclose(p);
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, out};
}

// The built daemon, or the built client while the daemon is not built: verify
// only needs an existing executable.
std::string built_binary() {
  if (::access(TISSUED_BINARY, X_OK) == 0) return TISSUED_BINARY;
  return TISSUE_CLI_BINARY;
}

// The unit with ExecStart's binary replaced by a built one, in a temp dir.
std::string rewritten_unit(const TempDir& dir) {
  std::string text = read_file(kUnit);
  const std::string from = "ExecStart=/usr/local/bin/tissued ";
  const auto at = text.find(from);
  EXPECT_NE(at, std::string::npos) << "ExecStart must run /usr/local/bin/tissued";
  if (at != std::string::npos) text.replace(at, from.size(), "ExecStart=" + built_binary() + " ");
  const std::string path = dir / "tissued.service";
  std::ofstream(path) << text;
  return path;
}

TEST(SystemdUnit, HasTheDirectivesTheServiceRelies) {
  const std::string text = read_file(kUnit);
  for (const char* line :
       {"Type=notify\n", "NotifyAccess=main\n", "ExecStart=/usr/local/bin/tissued --config /etc/tissued/tissued.yaml\n",
        "ExecReload=/bin/kill -HUP $MAINPID\n", "StateDirectory=tissued\n", "RuntimeDirectory=tissued\n",
        "User=tissued\n", "ProtectSystem=strict\n", "ProtectHome=yes\n", "NoNewPrivileges=yes\n", "PrivateTmp=yes\n",
        "RestrictAddressFamilies=AF_UNIX AF_INET AF_INET6 AF_NETLINK\n", "MemoryDenyWriteExecute=yes\n"})
    EXPECT_NE(text.find(line), std::string::npos) << "missing: " << line;
  const auto watchdog = directive(text, "WatchdogSec");
  ASSERT_TRUE(watchdog.has_value());
  EXPECT_TRUE(watchdog->size() > 1 && watchdog->back() == 's' && all_digits(watchdog->substr(0, watchdog->size() - 1)))
      << *watchdog;
  const auto rtprio = directive(text, "LimitRTPRIO");
  ASSERT_TRUE(rtprio.has_value());
  ASSERT_TRUE(all_digits(*rtprio)) << *rtprio;
  EXPECT_GE(std::stoi(*rtprio), 81) << "the haptic thread asks for SCHED_FIFO 80";
  const auto memlock = directive(text, "LimitMEMLOCK");
  ASSERT_TRUE(memlock.has_value());
  EXPECT_FALSE(memlock->empty());
  // These would break SCHED_FIFO, multicast or DDS shared memory.
  for (const char* forbidden : {"RestrictRealtime=yes", "PrivateNetwork=yes", "PrivateDevices=yes"})
    EXPECT_EQ(text.find(forbidden), std::string::npos) << forbidden;
  // User= needs the sysusers.d entry that creates the user.
  EXPECT_NE(read_file(std::string(TISSUE_SOURCE_DIR) + "/systemd/tissued.sysusers.conf").find("u tissued "),
            std::string::npos);
}

TEST(SystemdUnit, VerifyPrintsNothing) {
  if (!have_systemd_analyze()) GTEST_SKIP() << "systemd-analyze is not installed (apt install systemd)";
  TempDir dir;
  const std::string unit = rewritten_unit(dir);
  const auto [status, output] = run("systemd-analyze verify '" + unit + "'");
  EXPECT_EQ(status, 0) << output;
  EXPECT_EQ(output, "") << "systemd-analyze verify must print nothing";
}

TEST(SystemdUnit, SecurityExposureStaysLow) {
  if (!have_systemd_analyze()) GTEST_SKIP() << "systemd-analyze is not installed (apt install systemd)";
  TempDir dir;
  const std::string unit = rewritten_unit(dir);
  const auto [status, output] = run("systemd-analyze security --offline=true --no-pager '" + unit + "'");
  const std::string marker = "Overall exposure level for ";
  const auto at = output.find(marker);
  ASSERT_NE(at, std::string::npos) << output;
  const auto colon = output.find(": ", at);
  ASSERT_NE(colon, std::string::npos) << output;
  const double exposure = std::strtod(output.c_str() + colon + 2, nullptr);
  EXPECT_GT(exposure, 0.0) << output;
  // 1.7 when written; what remains is what real time and lab networking need
  // (docs: systemd/README.md). A change that loosens the sandbox fails here.
  EXPECT_LE(exposure, 2.0) << output;
}

}  // namespace
