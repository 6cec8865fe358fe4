// util/timestamped_name.hpp: the names the daemon makes up for files, and
// reading them back (the recording budget orders automatic files by them).
#include "util/timestamped_name.hpp"

#include <gtest/gtest.h>

#include <string>

#include "support/process_support.hpp"

namespace tissue::util {
namespace {

using tissue::testing::TempDir;
using tissue::testing::write_text;

// 2026-11-27 02:24:05 UTC as seconds since the epoch.
constexpr std::time_t kNow = 1795746245;

TEST(TimestampedName, IsThePrefixTheUtcTimeAndTheExtension) {
  TempDir dir;
  EXPECT_EQ(free_timestamped_name(dir.path(), "auto-", ".h5", kNow), "auto-20261127-022405.h5");
  EXPECT_EQ(free_timestamped_name(dir.path(), "surface-", ".x3d", 0), "surface-19700101-000000.x3d");
}

TEST(TimestampedName, TakesTheNextFreeSuffixWithinOneSecond) {
  TempDir dir;
  write_text(dir / "session-20261127-022405.h5", "");
  EXPECT_EQ(free_timestamped_name(dir.path(), "session-", ".h5", kNow), "session-20261127-022405-2.h5");
  write_text(dir / "session-20261127-022405-2.h5", "");
  write_text(dir / "session-20261127-022405-3.h5", "");
  EXPECT_EQ(free_timestamped_name(dir.path(), "session-", ".h5", kNow), "session-20261127-022405-4.h5");
  // Another prefix or extension is another name.
  EXPECT_EQ(free_timestamped_name(dir.path(), "session-", ".x3d", kNow), "session-20261127-022405.x3d");
}

TEST(TimestampedName, ReadsBackWhatItMade) {
  TempDir dir;
  const std::string prefix = "auto-", extension = ".h5";
  for (int k = 1; k <= 12; ++k) {
    const std::string name = free_timestamped_name(dir.path(), prefix, extension, kNow);
    const std::string stem = name.substr(prefix.size(), name.size() - prefix.size() - extension.size());
    const std::optional<NameStamp> stamp = read_name_stamp(stem);
    ASSERT_TRUE(stamp) << name;
    EXPECT_EQ(stamp->time, "20261127-022405") << name;
    EXPECT_EQ(stamp->k, k) << name;
    write_text(dir / name, "");
  }
}

TEST(TimestampedName, ReadsNothingElse) {
  for (const char* stem :
       {"", "notes", "20261127", "20261127-02240", "2026112x-022405", "20261127_022405", "20261127-022405-",
        "20261127-022405x2", "20261127-022405-2a", "20261127-022405-99999", "20261127-022405--2", "20261127-022405-0",
        "20261127-022405-1", "20261127-022405-02", "20261127-022405-1000"})
    EXPECT_FALSE(read_name_stamp(stem)) << '"' << stem << '"';
  const std::optional<NameStamp> two = read_name_stamp("20261127-022405-2");
  ASSERT_TRUE(two);
  EXPECT_EQ(two->k, 2);
  const std::optional<NameStamp> last = read_name_stamp("20261127-022405-999");
  ASSERT_TRUE(last);
  EXPECT_EQ(last->k, 999);
}

}  // namespace
}  // namespace tissue::util
