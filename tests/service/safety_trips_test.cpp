// SafetyTrips (daemon/service/safety_trips): one event per rise of the haptic
// loop's trip counters, with the counts by kind, per haptic side.
#include "service/safety_trips.hpp"

#include <gtest/gtest.h>

namespace tissue::service {
namespace {

haptics::HapticStats trips(std::uint64_t all, std::uint64_t stale, std::uint64_t lost) {
  haptics::HapticStats h;
  h.safety_trips = all;
  h.stale_model_trips = stale;
  h.device_lost_trips = lost;
  return h;
}

// The event text for trips of `kinds` ("1 stale model, 2 other").
std::string said(const std::string& kinds) {
  return "haptic safety tripped (" + kinds + "): the force ramped to zero, and back in once clear";
}

TEST(SafetyTrips, EachRiseIsSaidOnceWithItsKinds) {
  SafetyTrips t;
  EXPECT_FALSE(t.update(trips(0, 0, 0), 1));
  EXPECT_EQ(t.update(trips(1, 1, 0), 1), said("1 stale model"));
  EXPECT_FALSE(t.update(trips(1, 1, 0), 1));  // nothing new
  EXPECT_EQ(t.update(trips(4, 2, 1), 1), said("1 stale model, 1 device lost, 1 other"));
}

// A restarted side counts from zero: its trips are its own, whatever the
// old side's counts were (the side was told by its address, which the
// allocator handed straight back to the new side: equal totals said
// nothing, fewer of one kind wrapped to 18446744073709551615).
TEST(SafetyTrips, ARestartedSideCountsFromZero) {
  SafetyTrips t;
  ASSERT_TRUE(t.update(trips(1, 1, 0), 1));
  EXPECT_EQ(t.update(trips(1, 0, 1), 2), said("1 device lost"));
  SafetyTrips u;
  ASSERT_TRUE(u.update(trips(3, 3, 0), 1));
  EXPECT_EQ(u.update(trips(5, 0, 2), 2), said("2 device lost, 3 other"));
}

// A kind's counter read behind the total (relaxed reads, one by one) never
// wraps: the difference saturates at zero.
TEST(SafetyTrips, AKindCounterBehindTheTotalNeverWraps) {
  SafetyTrips t;
  ASSERT_TRUE(t.update(trips(2, 2, 0), 1));
  const std::optional<std::string> text = t.update(trips(3, 1, 0), 1);
  ASSERT_TRUE(text);
  EXPECT_EQ(text->find("18446744073709551615"), std::string::npos) << *text;
  EXPECT_NE(text->find("(1 other)"), std::string::npos) << *text;
}

}  // namespace
}  // namespace tissue::service
