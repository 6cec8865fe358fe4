#include "service/haptic_side.hpp"

#include <gtest/gtest.h>

#include <cstring>
#include <string>

namespace tissue::service {
namespace {

std::string summary_of(const haptics::HapticStats& stats, std::size_t size = 320,
                       const haptics::UdpDevice::Stats* link = nullptr) {
  std::string buffer(size, '#');
  format_haptic_summary(stats, link ? "udp" : "sim", link, buffer.data(), buffer.size());
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

TEST(HapticSummary, NamesWhyDeviceInputWasRefused) {
  haptics::HapticStats stats;
  stats.rejected_speed = 3;
  stats.rejected_nonfinite = 1;
  stats.rejected_inputs = 4;
  EXPECT_EQ(summary_of(stats), " | haptic sim F 0.00 N (inputs rejected: 3 too fast, 1 non-finite)");
  stats.rejected_speed = 0;
  stats.rejected_workspace = 2;
  stats.safety_trips = stats.device_lost_trips = 1;
  EXPECT_EQ(summary_of(stats),
            " | haptic sim F 0.00 N (safety trips: 1 device lost) (inputs rejected: 2 outside the workspace, 1 "
            "non-finite)");
}

TEST(HapticSummary, TheUdpBridgeSaysWhatItDroppedAndWhy) {
  haptics::HapticStats stats;
  haptics::UdpDevice::Stats link;
  link.received = link.accepted = 1000;
  EXPECT_EQ(summary_of(stats, 320, &link), " | haptic udp F 0.00 N") << "nothing dropped, nothing said";
  using R = haptics::UdpDevice::Reject;
  link.rejected[static_cast<int>(R::kSize)] = 5;
  link.rejected[static_cast<int>(R::kFingerprint)] = 100;
  link.rejected[static_cast<int>(R::kOtherSender)] = 7;
  link.out_of_order = 2;
  EXPECT_EQ(summary_of(stats, 320, &link),
            " | haptic udp F 0.00 N (udp dropped: 5 size, 100 fingerprint, 7 other_sender, 2 out of order)");
}

TEST(UdpLinkJson, EveryCounterByName) {
  haptics::UdpDevice::Stats link;
  link.received = 20;
  link.accepted = 10;
  link.rejected[static_cast<int>(haptics::UdpDevice::Reject::kVersion)] = 3;
  link.rejected[static_cast<int>(haptics::UdpDevice::Reject::kNonFinite)] = 4;
  link.out_of_order = 2;
  link.resyncs = 1;
  link.sessions = 1;
  link.sent = 9;
  link.reply_source_fallbacks = 5;
  const nlohmann::json j = udp_link_json(link);
  EXPECT_EQ(j.at("received"), 20);
  EXPECT_EQ(j.at("accepted"), 10);
  EXPECT_EQ(j.at("rejected"),
            (nlohmann::json{
                {"size", 0}, {"fingerprint", 0}, {"version", 3}, {"kind", 0}, {"non_finite", 4}, {"other_sender", 0}}));
  EXPECT_EQ(j.at("out_of_order"), 2);
  EXPECT_EQ(j.at("resyncs"), 1);
  EXPECT_EQ(j.at("sessions"), 1);
  EXPECT_EQ(j.at("receive_errors"), 0);
  EXPECT_EQ(j.at("sent"), 9);
  EXPECT_EQ(j.at("send_failures"), 0);
  EXPECT_EQ(j.value("reply_source_fallbacks", -1), 5) << "the fallback counter is not in haptics.link";
}

TEST(HapticSummary, TruncatesToTheBufferAndAlwaysTerminates) {
  haptics::HapticStats stats;
  stats.safety_trips = stats.stale_model_trips = 12345;
  const std::string whole = summary_of(stats);
  for (std::size_t size = 1; size <= whole.size() + 1; ++size) {
    std::string buffer(size + 8, '#');
    format_haptic_summary(stats, "sim", nullptr, buffer.data(), size);
    const std::size_t length = std::strlen(buffer.c_str());
    ASSERT_EQ(length, size - 1) << "size " << size;
    EXPECT_EQ(std::string(buffer.c_str()), whole.substr(0, size - 1));
    EXPECT_EQ(buffer[size], '#') << "wrote past the buffer at size " << size;
  }
  char untouched = '#';
  format_haptic_summary(stats, "sim", nullptr, &untouched, 0);
  EXPECT_EQ(untouched, '#');
}

}  // namespace
}  // namespace tissue::service
