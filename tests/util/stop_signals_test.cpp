// StopOnSignals: SIGINT and SIGTERM become a stop request while it lives, the
// dispositions and the mask before it come back after, an inherited SIG_IGN
// for SIGINT is kept, a repeat within the window changes nothing and a later
// one kills; threads started meanwhile have the signals blocked (no call of
// LCM's or Fast DDS's interrupted) and one started before takes them as a
// request, not death.
#include "util/stop_signals.hpp"

#include <gtest/gtest.h>
#include <pthread.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdlib>
#include <thread>

namespace tissue::util {
namespace {

using namespace std::chrono_literals;

void (*disposition(int signo))(int) {
  struct sigaction now {};
  sigaction(signo, nullptr, &now);
  return now.sa_handler;
}

bool blocked_here(int signo) {
  sigset_t mask;
  pthread_sigmask(SIG_BLOCK, nullptr, &mask);
  return sigismember(&mask, signo) == 1;
}

// As Ctrl-C, kill and timeout(1) do: to the process, not to one thread.
void signal_the_process(int signo) { ASSERT_EQ(::kill(::getpid(), signo), 0); }

// The watcher sets the flag a moment after the signal.
bool stopped_within(const StopOnSignals& stop, std::chrono::duration<double> limit) {
  const auto until = std::chrono::steady_clock::now() + limit;
  while (!stop.stopped() && std::chrono::steady_clock::now() < until) std::this_thread::sleep_for(1ms);
  return stop.stopped();
}

TEST(StopOnSignals, ASignalSetsTheFlagInsteadOfKilling) {
  for (const int signo : {SIGINT, SIGTERM}) {
    SCOPED_TRACE(signal_name(signo));
    const StopOnSignals stop;
    EXPECT_FALSE(stop.stopped());
    EXPECT_EQ(stop.signal(), 0);
    signal_the_process(signo);
    ASSERT_TRUE(stopped_within(stop, 5s));
    EXPECT_EQ(stop.signal(), signo);
    // The same request again at once (timeout(1) sends it twice): still alive.
    signal_the_process(signo);
    std::this_thread::sleep_for(100ms);
    EXPECT_EQ(stop.signal(), signo);
  }
}

// Asked again after the window, the signal kills: a run that does not stop
// soon enough can still be ended from the keyboard.
TEST(StopOnSignalsDeathTest, AskedAgainLaterItKills) {
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  for (const int signo : {SIGINT, SIGTERM}) {
    SCOPED_TRACE(signal_name(signo));
    EXPECT_EXIT(
        {
          const StopOnSignals stop;
          ::kill(::getpid(), signo);
          const bool first_taken = stopped_within(stop, 5s);
          std::this_thread::sleep_for(std::chrono::duration<double>(kRepeatWindow_s + 0.2));
          ::kill(::getpid(), signo);
          std::this_thread::sleep_for(2s);
          std::_Exit(first_taken ? 3 : 4);  // not reached when it kills
        },
        ::testing::KilledBySignal(signo), "");
  }
}

// The kernel may hand a process-directed signal to any thread that does not
// block it; one started before the StopOnSignals does not, and there the
// default action would kill the process. pthread_kill picks that thread.
TEST(StopOnSignalsDeathTest, AThreadStartedBeforeTakesItAsARequest) {
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  EXPECT_EXIT(
      {
        std::atomic<bool> quit{false};
        std::thread before([&] {
          while (!quit.load()) std::this_thread::sleep_for(1ms);
        });
        int code = 4;
        {
          const StopOnSignals stop;
          pthread_kill(before.native_handle(), SIGTERM);
          if (stopped_within(stop, 5s) && stop.signal() == SIGTERM) code = 0;
        }
        quit.store(true);
        before.join();
        std::_Exit(code);
      },
      ::testing::ExitedWithCode(0), "");
}

// raise() signals only the thread that made it, which blocks the signals:
// it waits until the destructor, which takes it as the request it was;
// restoring the mask must not then deliver it under the default action.
TEST(StopOnSignalsDeathTest, OneSentToTheCreatingThreadAloneIsNotDeathAfter) {
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  EXPECT_EXIT(
      {
        {
          const StopOnSignals stop;
          raise(SIGTERM);
        }
        std::this_thread::sleep_for(100ms);
        std::_Exit(0);
      },
      ::testing::ExitedWithCode(0), "");
}

// LCM's and Fast DDS's threads start while it lives: they inherit the mask,
// so no signal lands in (and interrupts) one of their calls. The mask of the
// thread that made it comes back after.
TEST(StopOnSignals, AThreadStartedWhileItLivesHasTheSignalsBlocked) {
  ASSERT_FALSE(blocked_here(SIGINT));
  ASSERT_FALSE(blocked_here(SIGTERM));
  {
    const StopOnSignals stop;
    bool int_blocked = false, term_blocked = false;
    std::thread meanwhile([&] {
      int_blocked = blocked_here(SIGINT);
      term_blocked = blocked_here(SIGTERM);
    });
    meanwhile.join();
    EXPECT_TRUE(int_blocked);
    EXPECT_TRUE(term_blocked);
  }
  EXPECT_FALSE(blocked_here(SIGINT));
  EXPECT_FALSE(blocked_here(SIGTERM));
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
    signal_the_process(SIGINT);
    std::this_thread::sleep_for(200ms);
    EXPECT_FALSE(stop.stopped());
    EXPECT_EQ(stop.signal(), 0);
  }
  EXPECT_EQ(disposition(SIGINT), SIG_IGN);
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
}  // namespace tissue::util
