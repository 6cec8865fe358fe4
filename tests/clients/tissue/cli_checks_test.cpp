#include "tissue/cli_checks.hpp"

#include <gtest/gtest.h>

#include <string>

namespace tissue::cli {
namespace {

// The validator's message for `value`: empty when accepted.
std::string verdict(const CLI::Validator& v, std::string value) { return v(value); }

TEST(CliChecks, FiniteNumberRefusesNanInfinityAndText) {
  EXPECT_EQ(verdict(finite_number(), "0.5"), "");
  EXPECT_EQ(verdict(finite_number(), "-2"), "");
  EXPECT_NE(verdict(finite_number(), "nan").find("not a finite number"), std::string::npos);
  EXPECT_NE(verdict(finite_number(), "inf").find("not a finite number"), std::string::npos);
  EXPECT_NE(verdict(finite_number(), "1e999").find("not a finite number"), std::string::npos);
  EXPECT_NE(verdict(finite_number(), "20abc").find("not a number"), std::string::npos);
}

TEST(CliChecks, FinitePositiveRefusesZeroNegativeAndNan) {
  EXPECT_EQ(verdict(finite_positive(), "2"), "");
  for (const char* bad : {"0", "-1", "nan", "inf", "x"}) EXPECT_NE(verdict(finite_positive(), bad), "") << bad;
}

// The clients check --lcm as the daemon's config checks publish.lcm.url: a
// ttl of 999 was accepted and the client waited on it.
TEST(CliChecks, LcmUrlsAreCheckedAsTheDaemonChecksThem) {
  EXPECT_EQ(verdict(lcm_url(), "udpm://239.255.76.67:7667?ttl=0&recv_buf_size=8388608"), "");
  EXPECT_EQ(verdict(lcm_url(), "memq://"), "");
  EXPECT_NE(verdict(lcm_url(), "udpm://239.255.76.67:7667?ttl=999").find("ttl"), std::string::npos);
  EXPECT_NE(verdict(lcm_url(), "udpm://8.8.8.8:7667").find("multicast"), std::string::npos);
  EXPECT_NE(verdict(lcm_url(), "udpm://239.255.76.67:99999").find("port"), std::string::npos);
}

TEST(CliChecks, FrameIndexRefusesNegatives) {
  EXPECT_EQ(verdict(frame_index(), "3"), "");
  EXPECT_NE(verdict(frame_index(), "-1").find("negative"), std::string::npos);
}

}  // namespace
}  // namespace tissue::cli
