// The plain records of a session (daemon/record/record_types): Event::make,
// which the real-time threads call, and the event kinds as the file and
// docs/session-format.md name them.
#include "record/record_types.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <limits>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "record_test_support.hpp"

namespace tissue::record {
namespace {

// Copied through lock-free rings by the producers: plain bytes, no
// allocation, no exception.
static_assert(std::is_trivially_copyable_v<Event>);
static_assert(std::is_trivially_copyable_v<HapticRow>);
static_assert(std::is_trivially_copyable_v<SimRow>);
static_assert(noexcept(Event::make(0.0, EventKind::kInfo, std::string_view{})));
static_assert(sizeof(Event::message) == kEventMessageBytes);
static_assert(kEventMessageBytes == 256, "docs/session-format.md: /events/message is a 256-byte fixed string");

TEST(RecordTypes, EventKeepsTimeKindAndShortTextWithNothingAfterIt) {
  const Event e = Event::make(12.5, EventKind::kParameterChanged, "material.youngs_modulus_Pa = 8e4");
  EXPECT_EQ(e.time_s, 12.5);
  EXPECT_EQ(e.kind, EventKind::kParameterChanged);
  EXPECT_STREQ(e.message, "material.youngs_modulus_Pa = 8e4");
  // The whole 256-byte field goes into the file: no stale bytes after the text.
  for (std::size_t i = std::strlen(e.message); i < kEventMessageBytes; ++i)
    ASSERT_EQ(e.message[i], '\0') << "byte " << i;
  const Event empty = Event::make(-1.0, EventKind::kRecordingError, "");
  EXPECT_EQ(empty.time_s, -1.0);
  EXPECT_EQ(empty.kind, EventKind::kRecordingError);
  EXPECT_STREQ(empty.message, "");
}

TEST(RecordTypes, EventKeeps255BytesAndCutsLongerText) {
  const std::string fits(kEventMessageBytes - 1, 'a');
  EXPECT_EQ(std::string(Event::make(0, EventKind::kInfo, fits).message), fits);
  for (const std::size_t n : {kEventMessageBytes, kEventMessageBytes + 1, std::size_t{4096}}) {
    SCOPED_TRACE(n);
    std::string text(n, 'b');
    text[kEventMessageBytes - 2] = 'y';  // the last byte kept
    text[kEventMessageBytes - 1] = 'z';  // the first byte cut
    const Event e = Event::make(0, EventKind::kWarning, text);
    EXPECT_EQ(e.message[kEventMessageBytes - 1], '\0');
    EXPECT_EQ(std::string(e.message), text.substr(0, kEventMessageBytes - 1));
  }
}

// A character straddling the 255-byte limit goes whole, for 2-, 3- and
// 4-byte characters at every split point; one that ends at byte 255 stays.
TEST(RecordTypes, EventNeverSplitsAUtf8CharacterAtTheLimit) {
  const std::size_t kept = kEventMessageBytes - 1;
  for (const std::string& ch :
       {std::string("\xc3\xa9"), std::string("\xe2\x82\xac"), std::string("\xf0\x9f\x98\x80")}) {
    for (std::size_t straddle = 1; straddle < ch.size(); ++straddle) {
      // `straddle` bytes of the character fit, the rest would not.
      const std::string prefix(kept - straddle, 'a');
      const Event e = Event::make(0, EventKind::kInfo, prefix + ch + "tail");
      EXPECT_EQ(std::string(e.message), prefix) << ch.size() << "-byte character, " << straddle << " byte(s) fit";
    }
    const std::string prefix(kept - ch.size(), 'a');
    EXPECT_EQ(std::string(Event::make(0, EventKind::kInfo, prefix + ch + "tail").message), prefix + ch)
        << ch.size() << "-byte character ending at byte 255";
  }
}

// Not UTF-8 at all (a run of continuation bytes, e.g. from a corrupt scene
// name): the cut backs off to nothing rather than running below the start.
TEST(RecordTypes, EventOfOnlyContinuationBytesIsCutToNothing) {
  const Event e = Event::make(1.0, EventKind::kError, std::string(300, '\x80'));
  EXPECT_STREQ(e.message, "");
  EXPECT_EQ(e.kind, EventKind::kError);
  // Short invalid text is not the cut's business: it is kept as it is.
  EXPECT_EQ(std::string(Event::make(1.0, EventKind::kError, "\x80\x80").message), "\x80\x80");
}

TEST(RecordTypes, EventKindNamesListEveryKindInOrderAsTheFormatDocumentSays) {
  // "0=info,1=warning,...": parsed, numbered 0.. in order.
  std::vector<std::pair<int, std::string>> kinds;
  const std::string names(kEventKindNames);
  std::size_t at = 0;
  while (at < names.size()) {
    const std::size_t comma = std::min(names.find(',', at), names.size());
    const std::string item = names.substr(at, comma - at);
    const std::size_t eq = item.find('=');
    ASSERT_NE(eq, std::string::npos) << "'" << item << "' in " << names;
    kinds.emplace_back(std::stoi(item.substr(0, eq)), item.substr(eq + 1));
    at = comma + 1;
  }
  const std::vector<std::pair<EventKind, std::string>> expected = {
      {EventKind::kInfo, "info"},
      {EventKind::kWarning, "warning"},
      {EventKind::kError, "error"},
      {EventKind::kSceneLoaded, "scene_loaded"},
      {EventKind::kParameterChanged, "parameter_changed"},
      {EventKind::kRecordingError, "recording_error"},
  };
  ASSERT_EQ(kinds.size(), expected.size()) << names;
  std::string documented;  // "0 info, 1 warning, ..." as the /events/kind row has it
  for (std::size_t k = 0; k < kinds.size(); ++k) {
    EXPECT_EQ(kinds[k].first, static_cast<int>(expected[k].first)) << names;
    EXPECT_EQ(kinds[k].first, static_cast<int>(k)) << "kinds are numbered 0.. in order: " << names;
    EXPECT_EQ(kinds[k].second, expected[k].second) << names;
    documented += (k ? ", " : "") + std::to_string(kinds[k].first) + " " + kinds[k].second;
  }
  const std::string doc = testing::slurp(std::string(TISSUE_SOURCE_DIR) + "/docs/session-format.md");
  ASSERT_FALSE(doc.empty());
  EXPECT_NE(doc.find("| `/events/kind` | E | int32 | enum | " + documented), std::string::npos)
      << "docs/session-format.md does not list the kinds as '" << documented << "'";
}

// A hole the recorder left in /haptic is a warning event whose text names
// the rows around it; readers take it back from that text alone. Each form
// (rows on both sides, none after it, none before it, no row at all) reads
// back as written, and what is not exactly such a text is no hole.
TEST(RecordTypes, AHapticHoleMessageReadsBackAsWritten) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const HapticHole forms[] = {
      {50, 8192, 8.191, 8.242}, {7, 16384, 16.433, nan},  {3, 0, nan, 0.004},
      {12, 0, nan, nan},        {1, 1, 1e9 - 0.001, 1e9},
  };
  for (const HapticHole& hole : forms) {
    const std::string text = haptic_hole_message(hole);
    SCOPED_TRACE(text);
    EXPECT_LT(text.size(), kEventMessageBytes);
    EXPECT_EQ(text.rfind(kHapticHolePrefix, 0), 0u);
    HapticHole back;
    ASSERT_TRUE(parse_haptic_hole(text, &back));
    EXPECT_EQ(back.ticks_lost, hole.ticks_lost);
    EXPECT_EQ(back.row_after, hole.row_after);
    EXPECT_EQ(back.has_row_before(), hole.has_row_before());
    EXPECT_EQ(back.has_row_after(), hole.has_row_after());
    // To the nanosecond printed (and the double's own rounding near 1e9 s).
    if (hole.has_row_before()) {
      EXPECT_NEAR(back.time_before_s, hole.time_before_s, 1e-9 + 1e-15 * hole.time_before_s);
    }
    if (hole.has_row_after()) {
      EXPECT_NEAR(back.time_after_s, hole.time_after_s, 1e-9 + 1e-15 * hole.time_after_s);
    }
  }
  EXPECT_EQ(haptic_hole_message(forms[0]),
            "haptic rows dropped by the recorder (ring full): 50 ticks between /haptic rows 8191 (8.191000000 s) and "
            "8192 (8.242000000 s)");
  const std::string good = haptic_hole_message(forms[0]);
  HapticHole h;
  for (const std::string& not_a_hole :
       {good + " ", good.substr(0, good.size() - 1), std::string("x") + good, std::string("recording started"),
        std::string(kHapticHolePrefix) + "0 ticks between /haptic rows 1 (0.001000000 s) and 2 (0.003000000 s)",
        std::string(kHapticHolePrefix) + "-5 ticks between /haptic rows 1 (0.001000000 s) and 2 (0.003000000 s)",
        std::string(kHapticHolePrefix) + "5 ticks between /haptic rows 1 (0.001000000 s) and 3 (0.003000000 s)",
        std::string(kHapticHolePrefix) + "5 ticks between /haptic rows 1 (nan s) and 2 (0.003000000 s)",
        std::string(kHapticHolePrefix) + "5 ticks before /haptic row 4 (0.004000000 s), the first recorded",
        std::string(kHapticHolePrefix) + "5 ticks after /haptic row 18446744073709551615 (1.000000000 s), the last "
                                         "recorded",
        // No row follows the largest row number: row_after would wrap to 0.
        std::string(kHapticHolePrefix) + "5 ticks between /haptic rows 18446744073709551615 (1.000000000 s) and 0 "
                                         "(1.006000000 s)"})
    EXPECT_FALSE(parse_haptic_hole(not_a_hole, &h)) << not_a_hole;
}

}  // namespace
}  // namespace tissue::record
