#include "util/lcm_url.hpp"

#include <gtest/gtest.h>

#include <string>

namespace tissue::util {
namespace {

// /proc/net/route prints each address as the 32-bit word of its
// network-order bytes (on this little-endian machine 192.0.2.0 reads
// 000200C0); the tables below are written that way.
const char kHeader[] = "Iface\tDestination\tGateway \tFlags\tRefCnt\tUse\tMetric\tMask\t\tMTU\tWindow\tIRTT\n";
const std::string kDefaultRoute = std::string(kHeader) +
                                  "eth0\t00000000\t010200C0\t0003\t0\t0\t0\t00000000\t0\t0\t0\n"
                                  "eth0\t000200C0\t00000000\t0001\t0\t0\t0\t00FFFFFF\t0\t0\t0\n";
const std::string kLanOnly = std::string(kHeader) + "eth0\t000200C0\t00000000\t0001\t0\t0\t0\t00FFFFFF\t0\t0\t0\n";
const std::string kMulticastOnLo = kLanOnly + "lo\t000000E0\t00000000\t0001\t0\t0\t0\t000000F0\t0\t0\t0\n";
const std::string kMulticastRouteDown = kLanOnly + "lo\t000000E0\t00000000\t0000\t0\t0\t0\t000000F0\t0\t0\t0\n";

constexpr std::uint32_t kLcmGroup = 239u << 24 | 255u << 16 | 76u << 8 | 67u;  // 239.255.76.67

TEST(LcmUrl, ARouteCoversAGroupWhenItsMaskedDestinationMatches) {
  EXPECT_TRUE(has_route_to(kLcmGroup, kDefaultRoute));
  EXPECT_TRUE(has_route_to(kLcmGroup, kMulticastOnLo));
  EXPECT_FALSE(has_route_to(kLcmGroup, kLanOnly));
  EXPECT_FALSE(has_route_to(kLcmGroup, kMulticastRouteDown));  // not RTF_UP
  EXPECT_FALSE(has_route_to(kLcmGroup, ""));
  EXPECT_FALSE(has_route_to(kLcmGroup, std::string(kHeader) + "garbage line\nlo\tzz\t0\t1\t0\t0\t0\tqq\n"));
  // 224.0.0.0/4 covers the whole multicast range, a /24 only its own.
  const std::string one_group = kLanOnly + "lo\t004CFFEF\t00000000\t0001\t0\t0\t0\t00FFFFFF\t0\t0\t0\n";
  EXPECT_TRUE(has_route_to(kLcmGroup, one_group));
  EXPECT_FALSE(has_route_to(239u << 24 | 1u, one_group));
}

// Only a udpm URL whose group no route covers is blamed on the route; any
// other failure points at LCM's own message.
TEST(LcmUrl, AStartFailureBlamesTheRouteOnlyWhenThereIsNone) {
  const std::string udpm = "udpm://239.255.76.67:7667?ttl=0";
  const std::string no_route = lcm_start_failure(udpm, kLanOnly);
  EXPECT_NE(no_route.find("no route covers its multicast group"), std::string::npos) << no_route;
  EXPECT_NE(no_route.find(udpm), std::string::npos) << no_route;
  for (const std::string& routed : {kDefaultRoute, kMulticastOnLo}) {
    const std::string why = lcm_start_failure(udpm, routed);
    EXPECT_EQ(why.find("route"), std::string::npos) << why;
    EXPECT_NE(why.find("LCM's own message"), std::string::npos) << why;
  }
  const std::string tcpq = lcm_start_failure("tcpq://127.0.0.1:1", kLanOnly);
  EXPECT_EQ(tcpq.find("route"), std::string::npos) << tcpq;
  EXPECT_NE(tcpq.find("tcpq://127.0.0.1:1"), std::string::npos) << tcpq;
}

TEST(LcmUrl, UdpmUrlProblemsAreNamed) {
  EXPECT_EQ(udpm_url_problem("udpm://239.255.76.67:7667?ttl=0"), "");
  EXPECT_EQ(udpm_url_problem("udpm://239.255.76.67"), "");
  EXPECT_EQ(udpm_url_problem("file:///tmp/log"), "");  // not udpm: not ours to judge
  EXPECT_NE(udpm_url_problem("udpm://10.0.0.1:7667").find("multicast address"), std::string::npos);
  EXPECT_NE(udpm_url_problem("udpm://239.255.76.67:99999").find("port"), std::string::npos);
  EXPECT_NE(udpm_url_problem("udpm://239.255.76.67:7667?ttl=-3").find("ttl"), std::string::npos);
  EXPECT_NE(udpm_url_problem("udpm://239.255.76.67:7667?ttl=256").find("ttl"), std::string::npos);
}

}  // namespace
}  // namespace tissue::util
