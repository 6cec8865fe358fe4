// OutputFile: opened before a long run (a bad path fails first), written once
// at the end, removed when the run never got to write it.
#include "app/output_file.hpp"

#include <gtest/gtest.h>

#include <filesystem>
#include <string>

#include "support/process_support.hpp"

namespace tissue::app {
namespace {

using tissue::testing::slurp;
using tissue::testing::TempDir;

TEST(OutputFile, WritesTheTextAtTheEnd) {
  TempDir dir;
  OutputFile file;
  ASSERT_EQ(file.open(dir / "out.txt"), "");
  EXPECT_TRUE(std::filesystem::exists(dir / "out.txt"));  // there before the run
  EXPECT_EQ(file.write("measured\n"), "");
  EXPECT_FALSE(file.is_open());
  EXPECT_EQ(slurp(dir / "out.txt"), "measured\n");
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

TEST(OutputFile, AFileNeverWrittenIsRemoved) {
  TempDir dir;
  {
    OutputFile file;
    ASSERT_EQ(file.open(dir / "a.txt"), "");
  }
  EXPECT_FALSE(std::filesystem::exists(dir / "a.txt"));
  OutputFile file;
  ASSERT_EQ(file.open(dir / "b.txt"), "");
  file.discard();
  EXPECT_FALSE(std::filesystem::exists(dir / "b.txt"));
  EXPECT_NE(file.write("late"), "");  // not open any more: an error, not a crash
}

}  // namespace
}  // namespace tissue::app
