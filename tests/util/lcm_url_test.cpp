#include "util/lcm_url.hpp"

#include <gtest/gtest.h>

#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <climits>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <future>
#include <string>
#include <thread>
#include <utility>

#include "support/loopback_listener.hpp"

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

// The group is four dotted octets of 1 to 3 digits, each at most 255:
// sscanf's %d took "4294967535" (2^32 + 239, overflowing int: UB) as 239,
// and signs, spaces and leading zeros (octal to LCM's inet_aton) as well.
TEST(LcmUrl, TheGroupIsFourPlainOctets) {
  for (const char* good :
       {"udpm://239.255.76.67:7667", "udpm://224.0.0.0", "udpm://239.255.255.255:1?ttl=1", "udpm://230.0.10.100:7667"})
    EXPECT_EQ(udpm_url_problem(good), "") << good;
  for (const char* bad :
       {"udpm://4294967535.255.76.67:7667", "udpm://239.4294967551.76.67:7667", "udpm://99999999999.1.1.1",
        "udpm:// 239.255.76.67:7667", "udpm://+239.255.76.67:7667", "udpm://239.-0.76.67:7667",
        "udpm://239.255. 76.67:7667", "udpm://239.255.76.067:7667", "udpm://0239.255.76.67:7667",
        "udpm://239.255.76:7667", "udpm://239.255.76.67.1:7667", "udpm://239..76.67:7667", "udpm://239.255.76.67x:7667",
        "udpm://239.256.76.67:7667", "udpm://240.0.0.1:7667", "udpm://223.255.255.255:7667", "udpm://:7667"})
    EXPECT_NE(udpm_url_problem(bad).find("multicast address"), std::string::npos) << bad;
  // A route check never reads such a group: it is blamed on LCM, not the route.
  EXPECT_EQ(lcm_start_failure("udpm://4294967535.255.76.67:7667", kLanOnly).find("route"), std::string::npos);
}

// poll(2) takes int milliseconds: --timeout 1e7 went through
// static_cast<int>(1e10), negative here, and poll waited forever; 0.0001 s
// became 0 and did not wait at all.
TEST(LcmUrl, PollTimeoutsRoundUpAndStayInRange) {
  EXPECT_EQ(poll_timeout_ms(1.0), 1000);
  EXPECT_EQ(poll_timeout_ms(0.0001), 1);
  EXPECT_EQ(poll_timeout_ms(0.0015), 2);
  EXPECT_EQ(poll_timeout_ms(1e7), INT_MAX);
  EXPECT_EQ(poll_timeout_ms(1e300), INT_MAX);
  EXPECT_EQ(poll_timeout_ms(2147483.647), INT_MAX);
  EXPECT_EQ(poll_timeout_ms(2147483.0), 2147483000);
  EXPECT_EQ(poll_timeout_ms(0.0), 0);
  EXPECT_EQ(poll_timeout_ms(-1.0), 0);
  EXPECT_EQ(poll_timeout_ms(std::nan("")), 0);
}

// LCM's tcpq client connects to 127.0.0.1:7700 for "tcpq://" and to port 7700
// of a host given without one (lcm_tcpq.c): the probe skipped such URLs, so
// `tissue x3d --lcm tcpq://127.0.0.1` against a silent port 7700 hung.
TEST(LcmUrl, ATcpqUrlWithoutAPortIsProbedOnLcmsDefaultPort) {
  TcpqServer server;
  ASSERT_TRUE(tcpq_server("tcpq://127.0.0.1", &server));
  EXPECT_EQ(server.host, "127.0.0.1");
  EXPECT_EQ(server.port, "7700");
  ASSERT_TRUE(tcpq_server("tcpq://", &server));
  EXPECT_EQ(server.host, "");  // the probe connects to 127.0.0.1, as LCM does
  EXPECT_EQ(server.port, "7700");
  ASSERT_TRUE(tcpq_server("tcpq://10.0.0.7:7800?x=1", &server));
  EXPECT_EQ(server.host, "10.0.0.7");
  EXPECT_EQ(server.port, "7800");
  EXPECT_FALSE(tcpq_server("udpm://239.255.76.67:7667", &server));
}

using tissue::testing::LoopbackListener;

std::string server_greeting() {
  const std::uint32_t words[2] = {htonl(0x287617fau), htonl(0x0100u)};
  return std::string(reinterpret_cast<const char*>(words), sizeof words);
}

// LCM's tcpq client waits for the server's greeting without a time limit:
// a port that accepts and stays silent hung `tissue render --lcm tcpq://…`
// past its --timeout. The probe gives up after the timeout and says why.
TEST(LcmUrl, ATcpqServerThatNeverGreetsIsFoundWithinTheTimeout) {
  LoopbackListener silent("");
  ASSERT_TRUE(silent.ok());
  const auto start = std::chrono::steady_clock::now();
  const std::string why = tcpq_server_problem(silent.url(), 0.2);
  const double waited_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  EXPECT_NE(why.find("did not answer LCM's greeting"), std::string::npos) << why;
  EXPECT_NE(why.find(silent.url()), std::string::npos) << why;
  EXPECT_LT(waited_s, 5.0);  // bounded (0.2 s asked; generous for a loaded machine)

  LoopbackListener web("HTTP/1.1 400 Bad Request\r\n\r\n");
  ASSERT_TRUE(web.ok());
  EXPECT_NE(tcpq_server_problem(web.url(), 2.0).find("not LCM's"), std::string::npos);

  LoopbackListener lcm(server_greeting());
  ASSERT_TRUE(lcm.ok());
  EXPECT_EQ(tcpq_server_problem(lcm.url(), 2.0), "");

  EXPECT_EQ(tcpq_server_problem("udpm://239.255.76.67:7667", 0.1), "");  // not tcpq: not probed
  EXPECT_NE(tcpq_server_problem("tcpq://127.0.0.1:99999", 0.1).find("port"), std::string::npos);
}

// A stop request (Ctrl-C: util::StopOnSignals's flag) during the probe ends
// it: `tissue x3d --timeout 600` against a silent listener waited out
// connection and greeting (up to 20 minutes) before it saw the request.
TEST(LcmUrl, ATcpqProbeGivesUpWhenItsStopFlagIsRaised) {
  LoopbackListener silent("");
  ASSERT_TRUE(silent.ok());
  std::atomic<bool> stop{false};
  auto probe = std::async(std::launch::async, [&] { return probe_tcpq_server(silent.url(), 600.0, &stop); });
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  stop.store(true);
  // The watchdog: a probe that ignores the flag would hold the test for
  // 600 s; well before that, fail and leave (the future would block the
  // destructor until the probe ended).
  if (probe.wait_for(std::chrono::seconds(20)) != std::future_status::ready) {
    ADD_FAILURE() << "the probe did not return within 20 s of its stop flag (timeout 600 s)";
    std::fflush(nullptr);
    std::_Exit(1);
  }
  const TcpqProbe got = probe.get();
  EXPECT_TRUE(got.stopped);
  EXPECT_EQ(got.problem, "");

  // Raised before it starts: no connection is waited for at all.
  EXPECT_TRUE(probe_tcpq_server(silent.url(), 600.0, &stop).stopped);
  // Not tcpq: nothing to probe, nothing stopped.
  EXPECT_FALSE(probe_tcpq_server("udpm://239.255.76.67:7667", 600.0, &stop).stopped);
  // A flag never raised changes nothing: the answer as without one.
  std::atomic<bool> never{false};
  LoopbackListener lcm(server_greeting());
  ASSERT_TRUE(lcm.ok());
  const TcpqProbe answered = probe_tcpq_server(lcm.url(), 2.0, &never);
  EXPECT_FALSE(answered.stopped);
  EXPECT_EQ(answered.problem, "");
}

}  // namespace
}  // namespace tissue::util
