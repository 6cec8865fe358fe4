#include "tissue/cli_checks.hpp"

#include <fcntl.h>
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <future>
#include <string>

namespace tissue::cli {
namespace {

// The validator's message for `value`: empty when accepted.
std::string verdict(const CLI::Validator& v, std::string value) { return v(value); }

TEST(CliChecks, FiniteNumberRefusesNanInfinityAndText) {
  EXPECT_EQ(verdict(finite_number(), "0.5"), "");
  EXPECT_EQ(verdict(finite_number(), "-2"), "");
  EXPECT_NE(verdict(finite_number(), "nan").find("not a finite number"), std::string::npos);
  EXPECT_NE(verdict(finite_number(), "inf").find("not a finite number"), std::string::npos);
  EXPECT_NE(verdict(finite_number(), "1e999").find("not a finite number"), std::string::npos);
  EXPECT_NE(verdict(finite_number(), "20abc").find("not a number"), std::string::npos);
}

TEST(CliChecks, FinitePositiveRefusesZeroNegativeAndNan) {
  EXPECT_EQ(verdict(finite_positive(), "2"), "");
  for (const char* bad : {"0", "-1", "nan", "inf", "x"}) EXPECT_NE(verdict(finite_positive(), bad), "") << bad;
}

// The clients check --lcm as the daemon's config checks publish.lcm.url: a
// ttl of 999 was accepted and the client waited on it.
TEST(CliChecks, LcmUrlsAreCheckedAsTheDaemonChecksThem) {
  EXPECT_EQ(verdict(lcm_url(), "udpm://239.255.76.67:7667?ttl=0&recv_buf_size=8388608"), "");
  EXPECT_EQ(verdict(lcm_url(), "memq://"), "");
  EXPECT_NE(verdict(lcm_url(), "udpm://239.255.76.67:7667?ttl=999").find("ttl"), std::string::npos);
  EXPECT_NE(verdict(lcm_url(), "udpm://8.8.8.8:7667").find("multicast"), std::string::npos);
  EXPECT_NE(verdict(lcm_url(), "udpm://239.255.76.67:99999").find("port"), std::string::npos);
}

// A value without PROVIDER:// is no LCM URL: refused as a bad argument (it
// reached LCM, which could not start, and `tissue x3d --lcm foo` exited 3).
TEST(CliChecks, AnLcmUrlNeedsAProvider) {
  for (const char* bad : {"foo", "239.255.76.67:7667", "udpm:/239.255.76.67:7667", "s.h5"})
    EXPECT_EQ(verdict(lcm_url(), bad), "'" + std::string(bad) + "' is not an LCM URL (PROVIDER://...)") << bad;
  EXPECT_EQ(verdict(lcm_url(), "tcpq://127.0.0.1:7700"), "");
}

TEST(CliChecks, FrameIndexRefusesNegatives) {
  EXPECT_EQ(verdict(frame_index(), "3"), "");
  EXPECT_NE(verdict(frame_index(), "-1").find("negative"), std::string::npos);
}

// Integer options read decimal digits only: CLI11 parses with base 0, so
// `--frame 010` showed frame 8, `--tcp 01750` talked to port 1000, and a
// frame number past 64 bits became 18446744073709551615.
TEST(CliChecks, IntegerOptionsAreDecimalAndFitIn64Bits) {
  CLI::App app;
  std::size_t frame = 0;
  int port = 0;
  app.add_option("--frame", frame)->transform(frame_index());
  app.add_option("--tcp", port)->transform(decimal_integer())->check(CLI::Range(1, 65535));
  app.parse(std::vector<std::string>{"01750", "--tcp", "010", "--frame"});  // CLI11 takes them reversed
  EXPECT_EQ(frame, 10u);
  EXPECT_EQ(port, 1750);
  app.parse(std::vector<std::string>{"0", "--frame"});
  EXPECT_EQ(frame, 0u);  // a lone zero stays a zero
  for (const char* bad : {"0x10", "+3", " 3", "3 ", "1e3", "", "-0"})
    EXPECT_NE(verdict(decimal_integer(), bad).find("decimal digits"), std::string::npos) << bad;
  EXPECT_NE(verdict(frame_index(), "0x10").find("decimal digits"), std::string::npos);
  EXPECT_NE(verdict(frame_index(), "99999999999999999999").find("too large"), std::string::npos);
  EXPECT_EQ(verdict(frame_index(), "18446744073709551615"), "");
}

// A fresh directory under $TMPDIR, removed with what is in it.
struct ScratchDir {
  ScratchDir() {
    std::string name = (std::filesystem::temp_directory_path() / "cli_checks-XXXXXX").string();
    if (::mkdtemp(name.data()) != nullptr) path = name;
  }
  ~ScratchDir() {
    std::error_code ec;
    if (!path.empty()) std::filesystem::remove_all(path, ec);
  }
  std::string names() const {
    std::string all;
    for (const auto& e : std::filesystem::directory_iterator(path)) all += e.path().filename().string() + " ";
    return all;
  }
  std::filesystem::path path;
};

// The early check of `tissue x3d|render -o` leaves nothing behind (a
// temporary file held through a live collection was left by a signal that
// killed the client), touches no existing OUT, and says why a path in a
// missing directory cannot be written.
TEST(OutputProblem, ChecksWithoutLeavingOrChangingAFile) {
  const ScratchDir dir;
  ASSERT_FALSE(dir.path.empty());
  EXPECT_EQ(output_problem(dir.path / "new.x3d"), "");
  EXPECT_EQ(dir.names(), "") << "the check left a file";
  std::ofstream(dir.path / "old.x3d") << "earlier";
  EXPECT_EQ(output_problem(dir.path / "old.x3d"), "");
  EXPECT_EQ(dir.names(), "old.x3d ");
  std::ifstream in(dir.path / "old.x3d");
  const std::string kept((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_EQ(kept, "earlier");
  EXPECT_NE(output_problem(dir.path / "no" / "a.x3d").find("No such file or directory"), std::string::npos)
      << output_problem(dir.path / "no" / "a.x3d");
  EXPECT_EQ(dir.names(), "old.x3d ");
}

// A FIFO is not opened by the check: the open waited for a reader, so
// `tissue x3d --lcm --animate -o FIFO & ...; cat FIFO` collected only from
// when cat opened it.
TEST(OutputProblem, AFifoIsNotOpenedSoTheCheckReturnsAtOnce) {
  const ScratchDir dir;
  ASSERT_FALSE(dir.path.empty());
  const std::string fifo = dir.path / "out.fifo";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  std::future<std::string> checked = std::async(std::launch::async, [&] { return output_problem(fifo); });
  const bool returned = checked.wait_for(std::chrono::seconds(5)) == std::future_status::ready;
  if (!returned) {
    // A reader releases the blocked open, so the test ends.
    const int reader = ::open(fifo.c_str(), O_RDONLY | O_NONBLOCK);
    checked.wait();
    if (reader >= 0) ::close(reader);
  }
  EXPECT_TRUE(returned) << "the check waited for the FIFO's reader";
  EXPECT_EQ(checked.get(), "");
  EXPECT_EQ(dir.names(), "out.fifo ");
}

// The files of a sequence: the first one that cannot be written is named
// with why, wherever it is in the list (its own directory missing, its name
// taken by a directory); a directory is probed once for all the new names in
// it, but a name taken by a directory is found even after that probe.
TEST(OutputProblem, TheFirstOfManyThatCannotBeWrittenIsNamed) {
  const ScratchDir dir;
  ASSERT_FALSE(dir.path.empty());
  std::filesystem::create_directory(dir.path / "a");
  const std::string in_a = dir.path / "a" / "f.png", in_missing = dir.path / "b" / "f.png";
  EXPECT_FALSE(first_output_problem({in_a, dir.path / "g-0000.png", dir.path / "g-0001.png"}));
  std::optional<OutputProblem> bad = first_output_problem({in_a, in_missing, dir.path / "c" / "f.png"});
  ASSERT_TRUE(bad);
  EXPECT_EQ(bad->path, in_missing);
  EXPECT_NE(bad->why.find("'" + (dir.path / "b").string() + "': No such file or directory"), std::string::npos)
      << bad->why;
  std::filesystem::create_directory(dir.path / "g-0001.png");
  bad = first_output_problem({dir.path / "g-0000.png", dir.path / "g-0001.png"});
  ASSERT_TRUE(bad);
  EXPECT_EQ(bad->path, (dir.path / "g-0001.png").string());
  EXPECT_EQ(bad->why, "is a directory");
  EXPECT_EQ(dir.names().find(".tmp"), std::string::npos) << "a probe left its file: " << dir.names();
}

}  // namespace
}  // namespace tissue::cli
