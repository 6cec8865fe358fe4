// util/text.hpp: what counts as clean text for names that reach JSON, HDF5
// and terminals.
#include "util/text.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include <string>

namespace tissue::util {
namespace {

TEST(CleanText, PlainAndInternationalNamesPass) {
  for (const std::string ok : {"cantilever", "Liver poke #3", "Leber-Stoß", "肝臓", "emoji 🙂", ""})
    EXPECT_EQ(why_not_clean_text(ok), "") << ok;
}

TEST(CleanText, BrokenUtf8IsNamedByItsByte) {
  EXPECT_EQ(why_not_clean_text("ab\xff"), "byte 3 (0xff) is not UTF-8");
  EXPECT_EQ(why_not_clean_text("\xc3"), "byte 1 (0xc3) is not UTF-8");  // cut short
  EXPECT_EQ(why_not_clean_text("a\xc3"
                               "b"),
            "byte 3 (0x62) is not UTF-8");                                          // bad continuation
  EXPECT_EQ(why_not_clean_text("\xc0\xaf"), "byte 1 (0xc0) is not UTF-8");          // overlong '/'
  EXPECT_EQ(why_not_clean_text("\xe0\x80\xaf"), "byte 1 (0xe0) is not UTF-8");      // overlong, 3 bytes
  EXPECT_EQ(why_not_clean_text("\xed\xa0\x80"), "byte 1 (0xed) is not UTF-8");      // a surrogate
  EXPECT_EQ(why_not_clean_text("\xf4\x90\x80\x80"), "byte 1 (0xf4) is not UTF-8");  // beyond U+10FFFF
}

TEST(CleanText, ControlCharactersAndLineSeparatorsAreRefused) {
  EXPECT_EQ(why_not_clean_text("a\x1b[31m"), "character 2 is a control character (U+001B)");
  EXPECT_EQ(why_not_clean_text("two\nlines"), "character 4 is a control character (U+000A)");
  EXPECT_EQ(why_not_clean_text("del\x7f"), "character 4 is a control character (U+007F)");
  EXPECT_EQ(why_not_clean_text("c1 \xc2\x85"), "character 4 is a control character (U+0085)");
  EXPECT_EQ(why_not_clean_text("\xe2\x80\xa8"), "character 1 is a control character (U+2028)");
  EXPECT_EQ(why_not_clean_text(std::string("nul\0", 4)), "character 4 is a control character (U+0000)");
}

// The command lines' one number reader: the whole text or nothing (std::stod
// took "20abc" as 20; strtod took " 1" and followed the locale).
TEST(WholeNumber, TheWholeTextOrNothing) {
  EXPECT_EQ(whole_number("20"), 20.0);
  EXPECT_EQ(whole_number("+0.5"), 0.5);
  EXPECT_EQ(whole_number("-1e-3"), -1e-3);
  EXPECT_EQ(whole_number("1E3"), 1000.0);
  for (const char* bad : {"", "20abc", " 1", "1 ", "+", "+-5", "--1", "1,5", "0x10", "abc"})
    EXPECT_FALSE(whole_number(bad).has_value()) << "'" << bad << "'";
  ASSERT_TRUE(whole_number("nan").has_value());  // read; the caller refuses it in its own words
  EXPECT_TRUE(std::isnan(*whole_number("nan")));
  EXPECT_TRUE(std::isinf(*whole_number("-inf")));
  EXPECT_EQ(whole_number("1e999"), HUGE_VAL);  // out of range: read as strtod reads it
  EXPECT_EQ(whole_number("-1e999"), -HUGE_VAL);
  EXPECT_EQ(whole_number("1e-999"), 0.0);
}

// Messages quote numbers in the shortest text that reads back the same.
TEST(NumberText, TheShortestTextThatReadsBackTheSame) {
  EXPECT_EQ(number_text(0.1), "0.1");
  EXPECT_EQ(number_text(0.1 + 0.2), "0.30000000000000004");
  EXPECT_EQ(number_text(1e-7), "1e-07");
  EXPECT_EQ(number_text(1e300), "1e+300");
  EXPECT_EQ(number_text(-2.0), "-2");
  EXPECT_EQ(number_text(std::numeric_limits<double>::infinity()), "inf");
  EXPECT_EQ(number_text(-std::numeric_limits<double>::infinity()), "-inf");
  EXPECT_EQ(number_text(-std::numeric_limits<double>::quiet_NaN()), "nan");
  for (const double v : {0.1, 1.0 / 3.0, 5e-324, 1.7976931348623157e308, -123.456e-78})
    EXPECT_EQ(whole_number(number_text(v)), v) << number_text(v);
}

}  // namespace
}  // namespace tissue::util
