#include "util/xml.hpp"

#include <gtest/gtest.h>

namespace tissue::util {
namespace {

TEST(EscapeXml, ReplacesTheFiveSpecialCharactersAndNothingElse) {
  EXPECT_EQ(escape_xml("a<b>&'c\""), "a&lt;b&gt;&amp;&apos;c&quot;");
  EXPECT_EQ(escape_xml("plain text, ümlaut 1.5e-3"), "plain text, ümlaut 1.5e-3");
  EXPECT_EQ(escape_xml(""), "");
  EXPECT_EQ(escape_xml("&amp;"), "&amp;amp;");  // not idempotent: escape once
}

}  // namespace
}  // namespace tissue::util
