// Plays systemd: binds the datagram socket a service manager would, points
// NOTIFY_SOCKET / WATCHDOG_USEC at it and reads what the notifier sends.
#include "control/systemd_notify.hpp"

#include <gtest/gtest.h>

#include <sys/socket.h>
#include <sys/time.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <csignal>
#include <cstddef>
#include <cstdlib>
#include <cstring>
#include <optional>
#include <string>

#include "control/fake_systemd.hpp"
#include "control/temp_dir.hpp"

namespace tissue::control {
namespace {

using namespace std::chrono_literals;
using testing::TempDir;

using testing::FakeSystemd;
using testing::ScopedEnv;

TEST(SystemdNotify, SendsEachStateToAPathSocket) {
  TempDir dir;
  const std::string path = dir / "notify";
  FakeSystemd systemd(path);
  ScopedEnv s("NOTIFY_SOCKET", path.c_str());
  ScopedEnv w("WATCHDOG_USEC", "3000000");
  ScopedEnv p("WATCHDOG_PID", std::to_string(::getpid()).c_str());
  const SystemdNotifier n;
  ASSERT_TRUE(n.enabled()) << n.setup_error();
  ASSERT_TRUE(n.watchdog_interval().has_value());
  EXPECT_EQ(*n.watchdog_interval(), 3s);

  EXPECT_TRUE(n.ready());
  EXPECT_EQ(systemd.receive(), "READY=1");
  EXPECT_TRUE(n.status("serving cantilever\nat 1 kHz"));
  EXPECT_EQ(systemd.receive(), "STATUS=serving cantilever at 1 kHz");
  EXPECT_TRUE(n.ready("up"));
  EXPECT_EQ(systemd.receive(), "READY=1\nSTATUS=up");
  EXPECT_TRUE(n.watchdog());
  EXPECT_EQ(systemd.receive(), "WATCHDOG=1");
  EXPECT_TRUE(n.reloading());
  const auto reload = systemd.receive();
  ASSERT_TRUE(reload.has_value());
  EXPECT_EQ(reload->rfind("RELOADING=1\nMONOTONIC_USEC=", 0), 0u) << *reload;
  EXPECT_TRUE(n.stopping());
  EXPECT_EQ(systemd.receive(), "STOPPING=1");
  EXPECT_TRUE(systemd.quiet());
}

TEST(SystemdNotify, AbstractSocketAddress) {
  const std::string name = "@tissue-notify-test-" + std::to_string(::getpid());
  FakeSystemd systemd(name);
  ScopedEnv s("NOTIFY_SOCKET", name.c_str());
  const SystemdNotifier n;
  ASSERT_TRUE(n.enabled()) << n.setup_error();
  EXPECT_TRUE(n.ready());
  EXPECT_EQ(systemd.receive(), "READY=1");
}

TEST(SystemdNotify, WithoutSystemdEverythingIsANoOp) {
  ScopedEnv s("NOTIFY_SOCKET", nullptr);
  ScopedEnv w("WATCHDOG_USEC", nullptr);
  const SystemdNotifier n;
  EXPECT_FALSE(n.enabled());
  EXPECT_TRUE(n.setup_error().empty());
  EXPECT_FALSE(n.ready());
  EXPECT_FALSE(n.watchdog());
  EXPECT_FALSE(n.watchdog_interval().has_value());

  ScopedEnv bad("NOTIFY_SOCKET", "relative/path");
  const SystemdNotifier m;
  EXPECT_FALSE(m.enabled());
  EXPECT_FALSE(m.setup_error().empty());
}

TEST(SystemdNotify, WatchdogMeantForAnotherProcessIsIgnored) {
  ScopedEnv w("WATCHDOG_USEC", "1000000");
  {
    ScopedEnv p("WATCHDOG_PID", std::to_string(::getpid() + 1).c_str());
    EXPECT_FALSE(SystemdNotifier().watchdog_interval().has_value());
  }
  {
    ScopedEnv p("WATCHDOG_PID", nullptr);
    EXPECT_EQ(SystemdNotifier().watchdog_interval(), 1s);
  }
  {
    ScopedEnv p("WATCHDOG_PID", nullptr);
    ScopedEnv garbage("WATCHDOG_USEC", "12abc");
    EXPECT_FALSE(SystemdNotifier().watchdog_interval().has_value());
  }
}

// $WATCHDOG_USEC=10000000000000000 became an interval the feeder converted
// to nanoseconds, overflowing int64 (UB); a value past 11.6 days is refused
// as no watchdog, and said, as is one that is not a number.
TEST(SystemdNotify, AnAbsurdWatchdogIntervalIsNoWatchdogAndSaysSo) {
  std::string problem;
  EXPECT_EQ(parse_watchdog_usec("3000000", &problem), 3s);
  EXPECT_EQ(problem, "");
  EXPECT_EQ(parse_watchdog_usec("1000000000000", &problem), kMaxWatchdogInterval) << "the bound itself is fine";
  EXPECT_FALSE(parse_watchdog_usec(nullptr, &problem).has_value());
  EXPECT_EQ(problem, "");
  EXPECT_FALSE(parse_watchdog_usec("0", &problem).has_value());
  EXPECT_EQ(problem, "");
  for (const char* absurd : {"10000000000000000", "1000000000001", "18446744073709551615"}) {
    EXPECT_FALSE(parse_watchdog_usec(absurd, &problem).has_value()) << absurd;
    EXPECT_EQ(problem, "WATCHDOG_USEC=" + std::string(absurd) +
                           " is above 1000000000000 (11.6 days): not a watchdog (check WatchdogSec=)");
  }
  for (const char* garbage : {"12abc", "-5", "99999999999999999999999"}) {
    EXPECT_FALSE(parse_watchdog_usec(garbage, &problem).has_value()) << garbage;
    EXPECT_EQ(problem, "WATCHDOG_USEC=" + std::string(garbage) + " is not a number of microseconds");
  }
  ScopedEnv w("WATCHDOG_USEC", "10000000000000000");
  ScopedEnv p("WATCHDOG_PID", nullptr);
  const SystemdNotifier n;
  EXPECT_FALSE(n.watchdog_interval().has_value());
  EXPECT_NE(n.watchdog_error().find("is above"), std::string::npos) << n.watchdog_error();
  std::atomic<std::uint64_t> heartbeat{0};
  EXPECT_FALSE(WatchdogFeeder(n, heartbeat).enabled());
  EXPECT_FALSE(WatchdogFeeder(n, heartbeat, std::chrono::microseconds(10000000000000000)).enabled());
  EXPECT_TRUE(WatchdogFeeder(n, heartbeat, kMaxWatchdogInterval).enabled());
}

// The io thread sends these: a manager that stops reading (its queue full)
// must cost a dropped message, not a blocked thread. Sent from a child
// process so that a blocking send fails the test instead of hanging it.
TEST(SystemdNotify, AFullQueueDropsTheMessageInsteadOfBlocking) {
  TempDir dir;
  const std::string path = dir / "notify";
  FakeSystemd systemd(path);  // never read until the end
  ScopedEnv s("NOTIFY_SOCKET", path.c_str());
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    const SystemdNotifier n;
    int refused = 0;
    for (int i = 0; i < 100000 && refused == 0; ++i)
      if (!n.status("a status line that fills the queue")) refused = 1;
    ::_exit(refused == 1 ? 0 : 2);
  }
  int status = 0;
  pid_t done = 0;
  for (int i = 0; i < 500 && (done = ::waitpid(child, &status, WNOHANG)) == 0; ++i) ::usleep(10000);
  if (done == 0) {
    ::kill(child, SIGKILL);
    ::waitpid(child, &status, 0);
    FAIL() << "a send to a full queue blocked for 5 s";
  }
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << "status " << status;
  EXPECT_TRUE(systemd.receive().has_value()) << "the messages before the queue filled arrived";
}

TEST(SystemdNotify, FeederFeedsOnlyWhileTheHeartbeatMoves) {
  TempDir dir;
  const std::string path = dir / "notify";
  FakeSystemd systemd(path);
  ScopedEnv s("NOTIFY_SOCKET", path.c_str());
  ScopedEnv w("WATCHDOG_USEC", "2000000");  // 2 s: feed every 1 s
  ScopedEnv p("WATCHDOG_PID", nullptr);
  const SystemdNotifier n;
  std::atomic<std::uint64_t> heartbeat{41};
  WatchdogFeeder feeder(n, heartbeat);
  ASSERT_TRUE(feeder.enabled());
  EXPECT_EQ(feeder.feed_period(), std::chrono::steady_clock::duration(1s));
  EXPECT_EQ(feeder.poll_period(), std::chrono::steady_clock::duration(500ms));

  // A fake clock: poll() takes the time, so the test needs no sleeping.
  const auto t0 = std::chrono::steady_clock::time_point{} + 1000s;
  EXPECT_FALSE(feeder.poll(t0)) << "no beat yet";
  EXPECT_TRUE(systemd.quiet());

  heartbeat = 42;
  EXPECT_TRUE(feeder.poll(t0));
  EXPECT_EQ(systemd.receive(), "WATCHDOG=1");

  heartbeat = 43;
  EXPECT_FALSE(feeder.poll(t0 + 500ms)) << "half the interval has not passed";
  EXPECT_TRUE(systemd.quiet());
  EXPECT_TRUE(feeder.poll(t0 + 1s));
  EXPECT_EQ(systemd.receive(), "WATCHDOG=1");

  // The loop stalls: however much time passes, no feed.
  for (int i = 2; i < 10; ++i) EXPECT_FALSE(feeder.poll(t0 + std::chrono::seconds(i)));
  EXPECT_TRUE(systemd.quiet());

  // It recovers: feeding resumes at the next poll.
  heartbeat.fetch_add(1000);
  EXPECT_TRUE(feeder.poll(t0 + 10s));
  EXPECT_EQ(systemd.receive(), "WATCHDOG=1");
  EXPECT_TRUE(systemd.quiet());
}

TEST(SystemdNotify, FeederWithoutWatchdogNeverSends) {
  TempDir dir;
  const std::string path = dir / "notify";
  FakeSystemd systemd(path);
  ScopedEnv s("NOTIFY_SOCKET", path.c_str());
  ScopedEnv w("WATCHDOG_USEC", nullptr);
  const SystemdNotifier n;
  std::atomic<std::uint64_t> heartbeat{0};
  WatchdogFeeder feeder(n, heartbeat);
  EXPECT_FALSE(feeder.enabled());
  heartbeat = 5;
  EXPECT_FALSE(feeder.poll(std::chrono::steady_clock::now()));
  EXPECT_TRUE(systemd.quiet());
}

}  // namespace
}  // namespace tissue::control
