#include "support/process_support.hpp"

#include <gtest/gtest.h>

#include <signal.h>
#include <sys/wait.h>

#include <optional>
#include <string>
#include <vector>

namespace tissue::testing {
namespace {

// Says "ready" once it runs (a signal sent sooner would reach the forked
// child before it set its dispositions), then sleeps as the same process.
const std::vector<std::string> kSleeper = {"/bin/sh", "-c", "echo ready; exec sleep 30"};

// ctest launched by a script with `&` runs with SIGINT ignored, and exec
// keeps an ignored disposition: a child the test meant to start as from a
// terminal (ignore_sigint false) ignored the SIGINT the test sent, and the
// live stop tests' SIGINT cases failed after their 60 s wait. The child
// starts with SIGINT at its default action whatever the test process had.
TEST(BackgroundProcess, AChildNotAskedToIgnoreSigintTakesItEvenWhenTheTestIgnoresIt) {
  struct sigaction ignore {};
  ignore.sa_handler = SIG_IGN;
  sigemptyset(&ignore.sa_mask);
  struct sigaction before {};
  ASSERT_EQ(sigaction(SIGINT, &ignore, &before), 0);
  const TempDir dir;  // fresh: a "ready" left by an earlier run is not this child's
  std::optional<int> status;
  {
    BackgroundProcess sleeper(kSleeper, dir / "out.txt", dir / "err.txt");
    ASSERT_TRUE(sleeper.wait_for_output("ready", 10.0));
    ASSERT_TRUE(sleeper.signal(SIGINT));
    status = sleeper.wait_for_exit(10.0);
  }
  sigaction(SIGINT, &before, nullptr);
  ASSERT_TRUE(status.has_value()) << "the child ignored SIGINT (still running 10 s after it)";
  EXPECT_TRUE(WIFSIGNALED(*status) && WTERMSIG(*status) == SIGINT) << "status " << *status;
}

// And one asked to ignore it does (the `cmd &` case the stop tests cover).
TEST(BackgroundProcess, AChildAskedToIgnoreSigintIgnoresIt) {
  const TempDir dir;
  BackgroundProcess sleeper(kSleeper, dir / "out.txt", dir / "err.txt", /*ignore_sigint=*/true);
  ASSERT_TRUE(sleeper.wait_for_output("ready", 10.0));
  ASSERT_TRUE(sleeper.signal(SIGINT));
  EXPECT_FALSE(sleeper.wait_for_exit(0.5).has_value());
  ASSERT_TRUE(sleeper.signal(SIGTERM));
  const std::optional<int> status = sleeper.wait_for_exit(10.0);
  ASSERT_TRUE(status.has_value());
  EXPECT_TRUE(WIFSIGNALED(*status) && WTERMSIG(*status) == SIGTERM) << "status " << *status;
}

}  // namespace
}  // namespace tissue::testing
