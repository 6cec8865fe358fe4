// The trade study's shared formatting (app/trade_format.hpp).
#include "app/trade_format.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <string>

namespace tissue::app {
namespace {

TEST(TradeFormat, PercentOfARelativeErrorOrNotMeasured) {
  EXPECT_EQ(percent_text(0.0123), "1.23 %");
  EXPECT_EQ(percent_text(0.0), "0.00 %");
  EXPECT_EQ(percent_text(NAN), "n/a");
  EXPECT_EQ(percent_text(INFINITY), "n/a");
}

TEST(TradeFormat, ShortenKeepsShortMessagesAndMarksTheCut) {
  EXPECT_EQ(shorten("abc", 3), "abc");
  EXPECT_EQ(shorten("abcdef", 3), "abc...");
  EXPECT_EQ(shorten(std::string(110, 'x')).size(), 110u);  // the default length is kept whole
  EXPECT_EQ(shorten(std::string(111, 'x')).size(), 113u);
}

TEST(TradeFormat, LevelNamesAndNumbers) {
  EXPECT_EQ(level_name(0), "L0");
  EXPECT_EQ(level_name(12), "L12");
  EXPECT_EQ(format_number("%.3g", 1234.5), "1.23e+03");
}

}  // namespace
}  // namespace tissue::app
