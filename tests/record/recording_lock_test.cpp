#include "record/recording_lock.hpp"

#include <gtest/gtest.h>

#include <sys/stat.h>

#include <cerrno>
#include <cstring>
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

// A FIFO is no session: a plain open of one blocks until a writer comes, and
// `tissue session repair` on one hung for good in this check.
TEST(RecordingLock, AFifoIsNotRecordedAndNotOpened) {
  TempDir dir;
  const std::string fifo = dir / "fifo.h5";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0) << std::strerror(errno);
  bool recorded = true;
  EXPECT_FALSE(testing::opens_fifo_for_reading(fifo, [&] { recorded = being_recorded(fifo); }))
      << "being_recorded opened the FIFO (it blocks there until a writer comes)";
  EXPECT_FALSE(recorded);
}

}  // namespace
}  // namespace tissue::record
