#include "service/failing_steps.hpp"

#include <gtest/gtest.h>

#include <cstring>

namespace tissue::service {
namespace {

SimStatus status(std::int64_t steps, std::int64_t failed, const char* why, std::uint64_t generation = 1) {
  SimStatus s;
  s.generation = generation;
  s.steps = steps;
  s.failed_steps = failed;
  std::strncpy(s.last_error, why, sizeof s.last_error - 1);
  return s;
}

// A scene failing every step for ten minutes of 1 Hz status ticks: one
// notice when it starts and one a minute after, not one per tick.
TEST(FailingSteps, APersistentFailureIsSaidOnceAndThenOnceAMinute) {
  FailingSteps f;
  EXPECT_FALSE(f.update(status(100, 0, ""), 0.0));
  int notices = 0;
  for (int tick = 1; tick <= 600; ++tick) {
    const auto n = f.update(status(100, 1000 * tick, "forces are non-finite"), tick);
    if (!n) continue;
    ++notices;
    EXPECT_TRUE(n->error);
    EXPECT_NE(n->text.find("forces are non-finite"), std::string::npos) << n->text;
    if (tick == 1)
      EXPECT_EQ(n->text.rfind("1000 simulation steps failed since the last status", 0), 0u) << n->text;
    else
      EXPECT_EQ(n->text.rfind("60000 more simulation steps failed in the last 60 s (still failing)", 0), 0u) << n->text;
  }
  EXPECT_EQ(notices, 10);  // ticks 1, 61, 121, ..., 541
}

TEST(FailingSteps, ANewReasonIsSaidAtOnce) {
  FailingSteps f;
  ASSERT_TRUE(f.update(status(10, 5, "reason A"), 1.0));
  EXPECT_FALSE(f.update(status(10, 9, "reason A"), 2.0));
  const auto n = f.update(status(10, 12, "reason B"), 3.0);
  ASSERT_TRUE(n);
  EXPECT_EQ(n->text, "7 more simulation steps failed, now for another reason: reason B");
}

// Recovery is said once, with the failures no notice counted yet; a pause
// (no steps, no failures) says nothing either way.
TEST(FailingSteps, StepsSucceedingAgainAreSaidAndAPauseIsNot) {
  FailingSteps f;
  ASSERT_TRUE(f.update(status(10, 5, "reason A"), 1.0));
  EXPECT_FALSE(f.update(status(10, 8, "reason A"), 2.0));
  EXPECT_FALSE(f.update(status(10, 8, "reason A"), 3.0));  // paused: no step either way
  const auto n = f.update(status(25, 8, "reason A"), 4.0);
  ASSERT_TRUE(n);
  EXPECT_FALSE(n->error);
  EXPECT_EQ(n->text, "simulation steps succeed again (after 3 more failed); the last failure was: reason A");
  EXPECT_FALSE(f.update(status(40, 8, "reason A"), 5.0));
  // Failing again later starts over: said at once.
  const auto again = f.update(status(40, 9, "reason A"), 6.0);
  ASSERT_TRUE(again);
  EXPECT_EQ(again->text.rfind("1 simulation steps failed since the last status", 0), 0u) << again->text;
}

// A scene change (new runner, steps from 0) that ends the failures counts as
// recovery; failures whose reason a scene change cleared still get a notice.
TEST(FailingSteps, ASceneChangeEndsAFailureAndAClearedReasonIsSaidSo) {
  FailingSteps f;
  ASSERT_TRUE(f.update(status(10, 5, "reason A", 1), 1.0));
  const auto n = f.update(status(0, 5, "", 2), 2.0);
  ASSERT_TRUE(n);
  EXPECT_FALSE(n->error);
  const auto gone = f.update(status(3, 6, "", 2), 3.0);
  ASSERT_TRUE(gone);
  EXPECT_NE(gone->text.find("its reason is gone"), std::string::npos) << gone->text;
}

}  // namespace
}  // namespace tissue::service
