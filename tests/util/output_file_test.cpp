// util/output_file.hpp: where a tool's -o output goes and how, in the cases
// where a rename would be wrong (a file held open through /proc, a link).
#include "util/output_file.hpp"

#include <fcntl.h>
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <string>
#include <vector>

#include "support/process_support.hpp"

namespace tissue::util {
namespace {

using tissue::testing::slurp;
using tissue::testing::TempDir;
using tissue::testing::write_text;

ino_t inode_of(const std::string& path) {
  struct stat st {};
  EXPECT_EQ(::stat(path.c_str(), &st), 0) << path;
  return st.st_ino;
}

// The names in `dir`, sorted.
std::vector<std::string> entries(const std::string& dir) {
  std::vector<std::string> names;
  for (const auto& e : std::filesystem::directory_iterator(dir)) names.push_back(e.path().filename().string());
  std::sort(names.begin(), names.end());
  return names;
}

bool is_link(const std::string& path) {
  struct stat st {};
  return ::lstat(path.c_str(), &st) == 0 && S_ISLNK(st.st_mode);
}

// -o /dev/stdout with stdout redirected to a file reaches the file through
// /proc/self/fd/1. Renaming PATH.tmp over that path replaced /dev/stdout
// itself (as root) or failed; the file must be written in place, appended
// to as its holder opened it. /proc/self/fd/N and /dev/fd/N stand in here
// for /dev/stdout, so a regression cannot touch this machine's /dev.
TEST(OutputFile, AFileHeldOpenThroughProcIsWrittenInPlace) {
  TempDir dir;
  const std::string file = dir / "redirected.txt";
  write_text(file, "");
  const int fd = ::open(file.c_str(), O_WRONLY | O_APPEND);
  ASSERT_GE(fd, 0);
  const ino_t before = inode_of(file);
  for (const std::string& spelled : {"/proc/self/fd/" + std::to_string(fd), "/dev/fd/" + std::to_string(fd)}) {
    EXPECT_TRUE(through_proc(spelled)) << spelled;
    EXPECT_EQ(write_output_file(spelled, "<x/>\n"), "") << spelled;
  }
  ::close(fd);
  EXPECT_EQ(slurp(file), "<x/>\n<x/>\n");
  EXPECT_EQ(inode_of(file), before) << "the file the holder has open was replaced";
  EXPECT_FALSE(is_link(file));
}

TEST(OutputFile, PlainPathsAreNotThroughProc) {
  TempDir dir;
  write_text(dir / "a.txt", "a");
  EXPECT_FALSE(through_proc(dir / "a.txt"));
  EXPECT_FALSE(through_proc(dir / "missing.txt"));
  EXPECT_FALSE(through_proc("relative-name-that-does-not-exist.txt"));
  ASSERT_EQ(::symlink((dir / "a.txt").c_str(), (dir / "link.txt").c_str()), 0);
  EXPECT_FALSE(through_proc(dir / "link.txt"));
}

// A regular file is replaced whole (a new inode: a failed write never
// leaves it truncated); a link to one stays a link and its file is replaced.
TEST(OutputFile, ARegularFileIsReplacedAndALinkKeepsPointingAtIt) {
  TempDir dir;
  const std::string file = dir / "out.x3d", link = dir / "latest.x3d";
  write_text(file, "old");
  const ino_t before = inode_of(file);
  EXPECT_EQ(write_output_file(file, "new"), "");
  EXPECT_EQ(slurp(file), "new");
  EXPECT_NE(inode_of(file), before);
  ASSERT_EQ(::symlink("out.x3d", link.c_str()), 0);  // relative, as `ln -s` makes them
  EXPECT_EQ(write_output_file(link, "newer"), "");
  EXPECT_TRUE(is_link(link)) << "the link was replaced by a regular file";
  EXPECT_EQ(slurp(file), "newer");
  EXPECT_FALSE(std::ifstream(dir / "latest.x3d.tmp").good());
  EXPECT_FALSE(std::ifstream(dir / "out.x3d.tmp").good());
  EXPECT_EQ(entries(dir.path()), (std::vector<std::string>{"latest.x3d", "out.x3d"})) << "a temporary file was left";
}

// The temporary file was always PATH.tmp, opened with O_TRUNC and without
// O_EXCL / O_NOFOLLOW: the user's own out.x3d.tmp was clobbered, and a link
// planted there was followed (its target truncated and overwritten). Now
// the temporary file is a new one of its own; whatever is there stays.
TEST(OutputFile, TheTemporaryFileIsNeverOneThatWasThere) {
  TempDir dir;
  const std::string out = dir / "out.x3d", sentinel = dir / "sentinel.txt", mine = dir / "notes.x3d.tmp";
  write_text(sentinel, "precious");
  write_text(mine, "the user's own .tmp");
  ASSERT_EQ(::symlink(sentinel.c_str(), (out + ".tmp").c_str()), 0);
  EXPECT_EQ(write_output_file(out, "<X3D/>"), "");
  EXPECT_EQ(write_output_file(dir / "notes.x3d", "notes"), "");
  EXPECT_EQ(slurp(out), "<X3D/>");
  EXPECT_EQ(slurp(sentinel), "precious") << "the link at out.x3d.tmp was followed";
  EXPECT_TRUE(is_link(out + ".tmp")) << "the link at out.x3d.tmp was replaced";
  EXPECT_FALSE(is_link(out));
  EXPECT_EQ(slurp(mine), "the user's own .tmp");
  EXPECT_EQ(entries(dir.path()),
            (std::vector<std::string>{"notes.x3d", "notes.x3d.tmp", "out.x3d", "out.x3d.tmp", "sentinel.txt"}));
}

// Opened, the path is untouched until commit; abandoned, only the
// temporary file (hidden, beside the path) goes.
TEST(OutputFile, APendingFileTouchesThePathOnlyAtCommit) {
  TempDir dir;
  const std::string out = dir / "report.json";
  write_text(out, "earlier");
  {
    PendingOutputFile file;
    ASSERT_EQ(file.open(out), "");
    const std::string tmp = file.temporary_path();
    EXPECT_EQ(std::filesystem::path(tmp).parent_path(), std::filesystem::path(dir.path()));
    EXPECT_EQ(std::filesystem::path(tmp).filename().string().rfind(".report.json.tmp-", 0), 0u) << tmp;
    EXPECT_EQ(slurp(out), "earlier");
  }
  EXPECT_EQ(slurp(out), "earlier");
  EXPECT_EQ(entries(dir.path()), std::vector<std::string>{"report.json"});
  PendingOutputFile a, b;  // two writers of one path: each its own temporary file
  ASSERT_EQ(a.open(out), "");
  ASSERT_EQ(b.open(out), "");
  EXPECT_NE(a.temporary_path(), b.temporary_path());
  EXPECT_EQ(a.commit("a"), "");
  EXPECT_EQ(b.commit("b"), "");
  EXPECT_EQ(slurp(out), "b");
  EXPECT_EQ(entries(dir.path()), std::vector<std::string>{"report.json"});
  EXPECT_NE(a.commit("again"), "") << "not open any more";
  EXPECT_EQ(PendingOutputFile()
                .open(dir / "missing/x.json")
                .find("cannot create a temporary file in '" + dir.path() + "/missing': No such file or directory"),
            0u);
}

// A replaced file keeps its permissions: the temporary file was made 0666
// minus the umask, so a report the user had made private became readable.
TEST(OutputFile, AReplacedFileKeepsItsPermissions) {
  TempDir dir;
  const std::string out = dir / "report.json";
  write_text(out, "earlier");
  ASSERT_EQ(::chmod(out.c_str(), 0600), 0);
  EXPECT_EQ(write_output_file(out, "later"), "");
  EXPECT_EQ(slurp(out), "later");
  struct stat st {};
  ASSERT_EQ(::stat(out.c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 07777, 0600u);
  ASSERT_EQ(::chmod(out.c_str(), 0751), 0);
  EXPECT_EQ(write_output_file(out, "again"), "");
  ASSERT_EQ(::stat(out.c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 07777, 0751u);
}

// open_new: the daemon's exports are never overwritten, and are written whole
// under a temporary name first (the service used to write into the final
// name, so a kill mid-write left a part file that looked complete).
TEST(OutputFile, ANewFileIsNeverPutOverOneThatAppearedAndNoPartIsLeft) {
  TempDir dir;
  const std::string out = dir / "surface.x3d";
  {
    PendingOutputFile file;
    ASSERT_EQ(file.open_new(out), "");
    EXPECT_FALSE(std::filesystem::exists(out)) << "nothing under the name before the commit";
    EXPECT_EQ(file.commit("<X3D/>"), "");
  }
  EXPECT_EQ(slurp(out), "<X3D/>");
  EXPECT_EQ(PendingOutputFile().open_new(out), PendingOutputFile::kAlreadyExists);
  // A dangling link is a name taken, not a way to write elsewhere.
  ASSERT_EQ(::symlink((dir / "elsewhere.x3d").c_str(), (dir / "link.x3d").c_str()), 0);
  EXPECT_EQ(PendingOutputFile().open_new(dir / "link.x3d"), PendingOutputFile::kAlreadyExists);
  // A file made between the open and the commit stays as it is.
  const std::string raced = dir / "raced.x3d";
  {
    PendingOutputFile file;
    ASSERT_EQ(file.open_new(raced), "");
    write_text(raced, "theirs");
    EXPECT_EQ(file.commit("mine"), PendingOutputFile::kAlreadyExists);
  }
  EXPECT_EQ(slurp(raced), "theirs");
  EXPECT_EQ(entries(dir.path()), (std::vector<std::string>{"link.x3d", "raced.x3d", "surface.x3d"}));
  EXPECT_FALSE(std::filesystem::exists(dir / "elsewhere.x3d"));
}

// The "wrote PATH" line goes to standard error when PATH is where standard
// output goes, so it never lands inside the output.
TEST(OutputFile, TheSummaryAvoidsAnOutputThatIsStandardOutput) {
  TempDir dir;
  const std::string file = dir / "stdout.txt", other = dir / "other.txt";
  write_text(file, "");
  write_text(other, "");
  std::fflush(stdout);
  const int saved = ::dup(STDOUT_FILENO);
  ASSERT_GE(saved, 0);
  const int fd = ::open(file.c_str(), O_WRONLY);
  ASSERT_GE(fd, 0);
  ASSERT_GE(::dup2(fd, STDOUT_FILENO), 0);
  ::close(fd);
  const bool file_is_stdout = is_standard_output(file);
  const bool dev_stdout_is_stdout = is_standard_output("/proc/self/fd/1");
  const bool other_is_stdout = is_standard_output(other);
  const bool summary_to_cerr = &summary_stream(file) == &std::cerr;
  const bool other_summary_to_cout = &summary_stream(other) == &std::cout;
  ::dup2(saved, STDOUT_FILENO);
  ::close(saved);
  EXPECT_TRUE(file_is_stdout);
  EXPECT_TRUE(dev_stdout_is_stdout);
  EXPECT_FALSE(other_is_stdout);
  EXPECT_TRUE(summary_to_cerr);
  EXPECT_TRUE(other_summary_to_cout);
  EXPECT_FALSE(is_standard_output(dir / "missing.txt"));
}

}  // namespace
}  // namespace tissue::util
