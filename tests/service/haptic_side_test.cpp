#include "service/haptic_side.hpp"

#include <gtest/gtest.h>

#include <cstring>
#include <string>

namespace tissue::service {
namespace {

std::string summary_of(const haptics::HapticStats& stats, std::size_t size = 256) {
  std::string buffer(size, '#');
  format_haptic_summary(stats, "sim", buffer.data(), buffer.size());
  return std::string(buffer.c_str());
}

TEST(HapticSummary, NamesTheDeviceTheForceAndContact) {
  haptics::HapticStats stats;
  stats.force_N = 0.756;
  EXPECT_EQ(summary_of(stats), " | haptic sim F 0.76 N");
  stats.contact = true;
  EXPECT_EQ(summary_of(stats), " | haptic sim F 0.76 N contact");
}

TEST(HapticSummary, NamesWhichFaultsTrippedTheSafetyRamp) {
  haptics::HapticStats stats;
  stats.force_N = 0.0;
  stats.safety_trips = 1;
  stats.stale_model_trips = 1;
  EXPECT_EQ(summary_of(stats), " | haptic sim F 0.00 N (safety trips: 1 stale model)");
  stats.safety_trips = 6;
  stats.device_lost_trips = 2;
  EXPECT_EQ(summary_of(stats), " | haptic sim F 0.00 N (safety trips: 1 stale model, 2 device lost, 3 other)");
  stats.stale_model_trips = 0;
  stats.safety_trips = 2;
  EXPECT_EQ(summary_of(stats), " | haptic sim F 0.00 N (safety trips: 2 device lost)");
}

TEST(HapticSummary, TruncatesToTheBufferAndAlwaysTerminates) {
  haptics::HapticStats stats;
  stats.safety_trips = stats.stale_model_trips = 12345;
  const std::string whole = summary_of(stats);
  for (std::size_t size = 1; size <= whole.size() + 1; ++size) {
    std::string buffer(size + 8, '#');
    format_haptic_summary(stats, "sim", buffer.data(), size);
    const std::size_t length = std::strlen(buffer.c_str());
    ASSERT_EQ(length, size - 1) << "size " << size;
    EXPECT_EQ(std::string(buffer.c_str()), whole.substr(0, size - 1));
    EXPECT_EQ(buffer[size], '#') << "wrote past the buffer at size " << size;
  }
  char untouched = '#';
  format_haptic_summary(stats, "sim", &untouched, 0);
  EXPECT_EQ(untouched, '#');
}

}  // namespace
}  // namespace tissue::service
