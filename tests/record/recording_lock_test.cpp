#include "record/recording_lock.hpp"

#include <gtest/gtest.h>

#include <fcntl.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <vector>

#include "record/session_writer.hpp"

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
    ASSERT_EQ(lock.take(path), "");
    EXPECT_TRUE(lock.held());
    EXPECT_TRUE(being_recorded(path));
    lock.release();
    EXPECT_FALSE(lock.held());
    EXPECT_FALSE(being_recorded(path));
    ASSERT_EQ(lock.take(path), "");
  }
  EXPECT_FALSE(being_recorded(path));
}

TEST(RecordingLock, AMissingFileIsNeitherTakenNorRecorded) {
  TempDir dir;
  RecordingLock lock;
  EXPECT_EQ(lock.take(dir / "missing.h5"), std::string("cannot open it for the lock: ") + std::strerror(ENOENT));
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

// Refused, the mark says why: here another description's write lock (what
// F_OFD_SETLK cannot take a read lock beside).
TEST(RecordingLock, AConflictingLockIsRefusedWithTheReason) {
  TempDir dir;
  const std::string path = dir / "s.h5";
  std::ofstream(path) << "x";
  const int other = ::open(path.c_str(), O_RDWR | O_CLOEXEC);
  ASSERT_GE(other, 0) << std::strerror(errno);
  struct flock write_lock {};
  write_lock.l_type = F_WRLCK;
  write_lock.l_whence = SEEK_SET;
  ASSERT_EQ(::fcntl(other, F_OFD_SETLK, &write_lock), 0) << std::strerror(errno);
  RecordingLock lock;
  const std::string why = lock.take(path);
  EXPECT_EQ(why.rfind("another lock on it conflicts (fcntl F_OFD_SETLK: ", 0), 0u) << why;
  EXPECT_FALSE(lock.held());
  ::close(other);
  EXPECT_EQ(lock.take(path), "");
}

// Runs in a child (the descriptor limit must not reach the rest of the
// suite). With 1, 2, ... descriptors free, SessionWriter::create either gives
// a recording marked as being recorded or fails naming the file, with
// nothing left in `dir`; and with some number free (one, while HDF5 needs
// one for the file) it is the lock's own open that is refused, with the
// reason. Counting up rather than assuming HDF5's needs keeps the test true
// to the writer, whatever the library opens. Exit 0 then; otherwise says
// what went wrong on stderr.
[[noreturn]] void create_short_of_descriptors(const std::string& dir) {
  const auto fail = [](const std::string& what) {
    std::fprintf(stderr, "%s\n", what.c_str());
    std::_Exit(1);
  };
  rlimit limit{};
  if (::getrlimit(RLIMIT_NOFILE, &limit) != 0) fail(std::string("getrlimit: ") + std::strerror(errno));
  limit.rlim_cur = std::min<rlim_t>(limit.rlim_cur, 512);  // quick to fill
  if (::setrlimit(RLIMIT_NOFILE, &limit) != 0) fail(std::string("setrlimit: ") + std::strerror(errno));
  std::vector<int> spare;
  const auto fill = [&] {
    for (int fd; (fd = ::open("/dev/null", O_RDONLY | O_CLOEXEC)) >= 0;) spare.push_back(fd);
    if (errno != EMFILE) fail(std::string("filling the descriptor table: ") + std::strerror(errno));
  };
  const auto free_some = [&](std::size_t n) {
    if (spare.size() < n) fail("fewer than " + std::to_string(n) + " spare descriptors to free");
    for (; n > 0; --n) {
      ::close(spare.back());
      spare.pop_back();
    }
  };
  bool lock_refused = false;
  for (std::size_t free = 1; free <= 8; ++free) {
    fill();
    free_some(free);
    const std::string path = dir + "/s" + std::to_string(free) + ".h5";
    const std::string with = "with " + std::to_string(free) + " descriptor(s) free, ";
    std::unique_ptr<SessionWriter> writer;
    std::string error;
    try {
      writer = SessionWriter::create(path, SessionMetadata{});
    } catch (const RecordError& e) {
      // The table back first: UBSan checks the object of a virtual call
      // (what()) by reading memory through a pipe of its own, and with no
      // descriptor free it found "an invalid vptr". The next round refills it.
      for (const int fd : spare) ::close(fd);
      spare.clear();
      error = e.what();
    }
    if (writer) {
      free_some(1);  // being_recorded opens the file too
      if (!being_recorded(path))
        fail(with + "create made '" + path +
             "' but it is not marked as being recorded (`tissue session repair` would take it for a crashed one)");
      writer->close();
      break;  // more descriptors change nothing
    }
    if (error.rfind("cannot create session file '" + path + "': ", 0) != 0)
      fail(with + "the error does not name the file: " + error);
    std::error_code ec;
    if (!std::filesystem::is_empty(dir, ec) || ec)
      fail(with + "the failed create left something in " + dir + (ec ? ": " + ec.message() : std::string()));
    if (error.find("cannot mark it as being recorded: cannot open it for the lock: " +
                   std::string(std::strerror(EMFILE))) != std::string::npos)
      lock_refused = true;
  }
  if (!lock_refused) fail("the lock's open was never the one refused: nothing checked");
  std::_Exit(0);
}

// A recording that cannot be marked (here: the process is out of file
// descriptors when the lock opens the file; a file system without these
// locks is the other way) is not created: unmarked it would read as left
// by a crash, and `tissue session repair` would trim and re-flag it under
// the writer.
TEST(RecordingLock, ASessionThatCannotBeMarkedIsNotCreated) {
  TempDir dir;
  EXPECT_EXIT(create_short_of_descriptors(dir.path()), ::testing::ExitedWithCode(0), "");
  // Only the session made once enough descriptors were free: no hidden file
  // of a refused one.
  std::vector<std::string> left;
  for (const auto& entry : std::filesystem::directory_iterator(dir.path()))
    left.push_back(entry.path().filename().string());
  ASSERT_EQ(left.size(), 1u);
  EXPECT_NE(left[0][0], '.') << left[0];
}

}  // namespace
}  // namespace tissue::record
