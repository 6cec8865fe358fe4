// OutputFile: opened before a long run (a bad path fails first), written once
// at the end; until then, and for good when the run never gets to write it,
// the path holds what it held before.
#include "app/output_file.hpp"

#include <fcntl.h>
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <string>
#include <vector>

#include "support/process_support.hpp"

namespace tissue::app {
namespace {

using tissue::testing::slurp;
using tissue::testing::TempDir;
using tissue::testing::write_text;

// The names in `dir`, sorted.
std::vector<std::string> entries(const std::string& dir) {
  std::vector<std::string> names;
  for (const auto& e : std::filesystem::directory_iterator(dir)) names.push_back(e.path().filename().string());
  std::sort(names.begin(), names.end());
  return names;
}

TEST(OutputFile, WritesTheTextAtTheEnd) {
  TempDir dir;
  OutputFile file;
  ASSERT_EQ(file.open(dir / "out.txt"), "");
  EXPECT_FALSE(std::filesystem::exists(dir / "out.txt")) << "nothing at the path before the text is complete";
  EXPECT_EQ(file.write("measured\n"), "");
  EXPECT_FALSE(file.is_open());
  EXPECT_EQ(slurp(dir / "out.txt"), "measured\n");
  EXPECT_EQ(entries(dir.path()), std::vector<std::string>{"out.txt"}) << "no temporary file left";
}

// `--report old.json` of a run that then fails to start (its --record file
// exists): fopen("w") emptied the user's earlier report at open and the
// destructor removed it. Now it is untouched until the new text replaces it.
TEST(OutputFile, AnEarlierFileStaysAsItWasUntilTheWriteAndForGoodWhenDiscarded) {
  TempDir dir;
  write_text(dir / "old.json", "earlier run");
  {
    OutputFile file;
    ASSERT_EQ(file.open(dir / "old.json", "report"), "");
    EXPECT_EQ(slurp(dir / "old.json"), "earlier run") << "emptied at open";
  }
  EXPECT_EQ(slurp(dir / "old.json"), "earlier run") << "removed or emptied by a run that never wrote it";
  EXPECT_EQ(entries(dir.path()), std::vector<std::string>{"old.json"});
  OutputFile file;
  ASSERT_EQ(file.open(dir / "old.json", "report"), "");
  EXPECT_EQ(slurp(dir / "old.json"), "earlier run");
  EXPECT_EQ(file.write("this run"), "");
  EXPECT_EQ(slurp(dir / "old.json"), "this run");
  EXPECT_EQ(entries(dir.path()), std::vector<std::string>{"old.json"});
}

// A special file is written in place and never removed: a FIFO (a reader
// waiting on it) stays a FIFO when the run ends without writing it. The
// same holds for /dev/null or /dev/stdout, which a discard removed as root.
TEST(OutputFile, ASpecialFileIsNeverRemoved) {
  TempDir dir;
  const std::string fifo = dir / "pipe";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  const int reader = ::open(fifo.c_str(), O_RDONLY | O_NONBLOCK);
  ASSERT_GE(reader, 0);
  {
    OutputFile file;
    ASSERT_EQ(file.open(fifo, "report"), "");
  }
  struct stat st {};
  ASSERT_EQ(::lstat(fifo.c_str(), &st), 0) << "the FIFO was removed";
  EXPECT_TRUE(S_ISFIFO(st.st_mode));
  OutputFile file;
  ASSERT_EQ(file.open(fifo, "report"), "");
  EXPECT_EQ(file.write("through the pipe"), "");
  char buf[64] = {};
  EXPECT_EQ(::read(reader, buf, sizeof buf), 16);
  EXPECT_EQ(std::string(buf), "through the pipe");
  ::close(reader);
  ASSERT_EQ(::lstat(fifo.c_str(), &st), 0);
  EXPECT_TRUE(S_ISFIFO(st.st_mode));
}

TEST(OutputFile, AMissingDirectoryIsRefusedAtOpenNamingThePath) {
  TempDir dir;
  OutputFile file;
  const std::string path = dir / "missing/out.txt";
  const std::string why = file.open(path, "report");
  EXPECT_NE(why.find("cannot write report " + path), std::string::npos) << why;
  EXPECT_NE(why.find("No such file or directory"), std::string::npos) << why;
}

TEST(OutputFile, AFullDiskIsReportedAtTheWrite) {
  OutputFile file;
  ASSERT_EQ(file.open("/dev/full"), "");
  const std::string why = file.write(std::string(1 << 16, 'x'));
  EXPECT_NE(why.find("cannot write /dev/full: No space left on device"), std::string::npos) << why;
}

TEST(OutputFile, AFileNeverWrittenLeavesNothingBehind) {
  TempDir dir;
  {
    OutputFile file;
    ASSERT_EQ(file.open(dir / "a.txt"), "");
  }
  EXPECT_TRUE(std::filesystem::is_empty(dir.path()));
  OutputFile file;
  ASSERT_EQ(file.open(dir / "b.txt"), "");
  file.discard();
  EXPECT_TRUE(std::filesystem::is_empty(dir.path()));
  EXPECT_NE(file.write("late"), "");  // not open any more: an error, not a crash
}

}  // namespace
}  // namespace tissue::app
