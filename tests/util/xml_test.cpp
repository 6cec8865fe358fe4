#include "util/xml.hpp"

#include <gtest/gtest.h>

#include <string>

namespace tissue::util {
namespace {

const std::string kFffd = "\xef\xbf\xbd";  // U+FFFD REPLACEMENT CHARACTER

TEST(EscapeXml, ReplacesTheFiveSpecialCharacters) {
  EXPECT_EQ(escape_xml("a<b>&'c\""), "a&lt;b&gt;&amp;&apos;c&quot;");
  EXPECT_EQ(escape_xml("plain text, ümlaut 1.5e-3"), "plain text, ümlaut 1.5e-3");
  EXPECT_EQ(escape_xml(""), "");
  EXPECT_EQ(escape_xml("&amp;"), "&amp;amp;");  // not idempotent: escape once
  // Every valid character beyond them passes: 2, 3 and 4 bytes, the last
  // ones XML allows, C1 and DEL (allowed, if discouraged).
  EXPECT_EQ(escape_xml("\xce\xa9 \xe2\x82\xac \xf0\x9f\x98\x80 \xef\xbf\xbd \xf4\x8f\xbf\xbf \x7f\xc2\x85"),
            "\xce\xa9 \xe2\x82\xac \xf0\x9f\x98\x80 \xef\xbf\xbd \xf4\x8f\xbf\xbf \x7f\xc2\x85");
}

// An attribute value's parser turns a literal tab, newline or CR into a
// space (and a CR is lost in any text): as character references they stay.
TEST(EscapeXml, TabNewlineAndCarriageReturnBecomeCharacterReferences) {
  EXPECT_EQ(escape_xml("a\tb\nc\rd"), "a&#9;b&#10;c&#13;d");
}

// `tissue x3d --session $'a\x01.h5'` took its title from the path and wrote
// the control character as it was: ill-formed XML, which no reader opens.
// What XML 1.0 does not allow, and bytes that are not UTF-8, become U+FFFD.
TEST(EscapeXml, WhatXmlCannotHoldBecomesTheReplacementCharacter) {
  EXPECT_EQ(escape_xml(std::string("a\x01.h5")), "a" + kFffd + ".h5");
  EXPECT_EQ(escape_xml(std::string("\x00\x1b\x1f", 3)), kFffd + kFffd + kFffd);
  EXPECT_EQ(escape_xml("\xef\xbf\xbe|\xef\xbf\xbf"), kFffd + "|" + kFffd);  // U+FFFE, U+FFFF
  EXPECT_EQ(escape_xml("bad\xff.h5"), "bad" + kFffd + ".h5");
  EXPECT_EQ(escape_xml("\xc0\xaf"), kFffd + kFffd);                          // overlong '/'
  EXPECT_EQ(escape_xml("\xed\xa0\x80"), kFffd + kFffd + kFffd);              // a UTF-16 surrogate
  EXPECT_EQ(escape_xml("cut \xe2\x82"), "cut " + kFffd + kFffd);             // a sequence cut short
  EXPECT_EQ(escape_xml("\xe2\x82<"), kFffd + kFffd + "&lt;");                // ... and what follows it
  EXPECT_EQ(escape_xml("\xf4\x90\x80\x80"), kFffd + kFffd + kFffd + kFffd);  // beyond U+10FFFF
}

}  // namespace
}  // namespace tissue::util
