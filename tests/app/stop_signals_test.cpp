// StopOnSignals: SIGINT and SIGTERM become a stop request while it lives, the
// dispositions before it come back after, an inherited SIG_IGN for SIGINT is
// kept, a repeat within the window changes nothing and a later one kills.
#include "app/stop_signals.hpp"

#include <gtest/gtest.h>

#include <chrono>
#include <csignal>
#include <cstdlib>
#include <thread>

namespace tissue::app {
namespace {

void (*disposition(int signo))(int) {
  struct sigaction now {};
  sigaction(signo, nullptr, &now);
  return now.sa_handler;
}

TEST(StopOnSignals, ASignalSetsTheFlagInsteadOfKilling) {
  for (const int signo : {SIGINT, SIGTERM}) {
    const StopOnSignals stop;
    EXPECT_EQ(*stop.flag(), 0);
    ASSERT_EQ(std::raise(signo), 0);
    EXPECT_EQ(*stop.flag(), signo) << signal_name(signo);
    // The same request again at once (timeout(1) sends it twice): still alive.
    ASSERT_EQ(std::raise(signo), 0);
    EXPECT_EQ(*stop.flag(), signo) << signal_name(signo);
  }
}

// Asked again after the window, the signal kills: a run that does not stop
// soon enough can still be ended from the keyboard.
TEST(StopOnSignalsDeathTest, AskedAgainLaterItKills) {
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  EXPECT_EXIT(
      {
        const StopOnSignals stop;
        std::raise(SIGINT);
        std::this_thread::sleep_for(std::chrono::duration<double>(kRepeatWindow_s + 0.2));
        std::raise(SIGINT);
        std::_Exit(*stop.flag() == SIGINT ? 3 : 4);  // not reached when it kills
      },
      ::testing::KilledBySignal(SIGINT), "");
}

TEST(StopOnSignals, TheDispositionsBeforeComeBack) {
  const auto before_int = disposition(SIGINT), before_term = disposition(SIGTERM);
  {
    const StopOnSignals stop;
    EXPECT_NE(disposition(SIGINT), before_int);
    EXPECT_NE(disposition(SIGTERM), before_term);
  }
  EXPECT_EQ(disposition(SIGINT), before_int);
  EXPECT_EQ(disposition(SIGTERM), before_term);
}

TEST(StopOnSignals, AnIgnoredSigintStaysIgnored) {
  const auto before = std::signal(SIGINT, SIG_IGN);
  {
    const StopOnSignals stop;
    EXPECT_EQ(disposition(SIGINT), SIG_IGN);
    ASSERT_EQ(std::raise(SIGINT), 0);
    EXPECT_EQ(*stop.flag(), 0);
  }
  std::signal(SIGINT, before);
}

TEST(StopOnSignals, NamesAndExitCodes) {
  EXPECT_EQ(signal_name(SIGINT), "SIGINT");
  EXPECT_EQ(signal_name(SIGTERM), "SIGTERM");
  EXPECT_EQ(signal_name(SIGHUP), "signal " + std::to_string(SIGHUP));
  EXPECT_EQ(exit_code_for_signal(SIGINT), 130);
  EXPECT_EQ(exit_code_for_signal(SIGTERM), 143);
}

}  // namespace
}  // namespace tissue::app
