#include "record/recording_lock.hpp"

#include <gtest/gtest.h>

#include <fstream>

#include "record_test_support.hpp"

namespace tissue::record {
namespace {

using testing::TempDir;

// The mark is seen from another descriptor (of this process too: open file
// description locks conflict between descriptions, not processes) and goes
// with release() or the lock's end.
TEST(RecordingLock, MarksAFileUntilReleased) {
  TempDir dir;
  const std::string path = dir / "s.h5";
  std::ofstream(path) << "x";
  EXPECT_FALSE(being_recorded(path));
  {
    RecordingLock lock;
    ASSERT_TRUE(lock.take(path));
    EXPECT_TRUE(lock.held());
    EXPECT_TRUE(being_recorded(path));
    lock.release();
    EXPECT_FALSE(lock.held());
    EXPECT_FALSE(being_recorded(path));
    ASSERT_TRUE(lock.take(path));
  }
  EXPECT_FALSE(being_recorded(path));
}

TEST(RecordingLock, AMissingFileIsNeitherTakenNorRecorded) {
  TempDir dir;
  RecordingLock lock;
  EXPECT_FALSE(lock.take(dir / "missing.h5"));
  EXPECT_FALSE(lock.held());
  EXPECT_FALSE(being_recorded(dir / "missing.h5"));
}

}  // namespace
}  // namespace tissue::record
