// The sweep's CSV (app/trade_sweep_csv.hpp): fields that hold a user's text
// stay one field, unmeasured numbers are empty.
#include "app/trade_sweep_csv.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <sstream>
#include <string>
#include <vector>

namespace tissue::app {
namespace {

TEST(TradeSweepCsv, QuotingDoublesQuotes) {
  EXPECT_EQ(csv_quote(""), "\"\"");
  EXPECT_EQ(csv_quote("a,b"), "\"a,b\"");
  EXPECT_EQ(csv_quote("say \"hi\""), "\"say \"\"hi\"\"\"");
}

TEST(TradeSweepCsv, NumbersAreSixDigitsOrEmpty) {
  EXPECT_EQ(csv_num(0.1234567), "0.123457");
  EXPECT_EQ(csv_num(-2.5e-7), "-2.5e-07");
  EXPECT_EQ(csv_num(NAN), "");
  EXPECT_EQ(csv_num(INFINITY), "");
}

std::vector<std::string> lines_of(const std::string& text) {
  std::vector<std::string> lines;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  return lines;
}

TEST(TradeSweepCsv, OneRowPerPointWithAsManyFieldsAsTheHeader) {
  SweepPoint uniform;
  uniform.integrator = "implicit";
  uniform.dt_s = 0.001;
  uniform.level = uniform.max_depth = 2;
  SweepPoint capped = uniform;
  capped.adaptive = true;
  capped.th_Pa = 20;
  capped.st.capped = true;
  const std::string text = csv_text("plain", {uniform, capped}, {{2, "explicit at dt 1 ms, uniform L2"}});
  const std::vector<std::string> lines = lines_of(text);
  ASSERT_EQ(lines.size(), 3u);
  const auto fields = [](const std::string& line) {  // commas outside quotes, + 1
    std::size_t n = 1;
    bool quoted = false;
    for (char c : line) {
      if (c == '"') quoted = !quoted;
      n += c == ',' && !quoted;
    }
    return n;
  };
  EXPECT_EQ(fields(lines[1]), fields(lines[0]));
  EXPECT_EQ(fields(lines[2]), fields(lines[0]));
  EXPECT_EQ(lines[1].rfind("\"plain\",implicit,0.001,2,uniform,2,,ok,\"\",", 0), 0u) << lines[1];
  EXPECT_EQ(
      lines[2].rfind("\"plain\",implicit,0.001,2,adaptive,,20,capped,\"stopped by the per-run cap on wall time\",", 0),
      0u)
      << lines[2];
  EXPECT_NE(lines[2].find(",\"explicit at dt 1 ms, uniform L2\""), std::string::npos);
}

// Under --clock cpu the cap is on thread CPU time, and the message says so
// (it said "wall cap" whichever clock the cap read).
TEST(TradeSweepCsv, ACappedRunNamesTheClockItsCapRead) {
  SweepPoint capped;
  capped.integrator = "implicit";
  capped.st.capped = true;
  EXPECT_NE(csv_text("plain", {capped}, {}).find(",capped,\"stopped by the per-run cap on wall time\","),
            std::string::npos);
  capped.st.cost_uses_cpu = true;
  const std::string text = csv_text("plain", {capped}, {});
  EXPECT_NE(text.find(",capped,\"stopped by the per-run cap on thread CPU time\","), std::string::npos) << text;
}

}  // namespace
}  // namespace tissue::app
