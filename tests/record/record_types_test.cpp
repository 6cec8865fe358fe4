// The plain records of a session (daemon/record/record_types): Event::make,
// which the real-time threads call, and the event kinds as the file and
// docs/session-format.md name them.
#include "record/record_types.hpp"

#include <gtest/gtest.h>

#include <cstring>
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

}  // namespace
}  // namespace tissue::record
