// The `tissue` executable as a user runs it, against a test server: output
// and exit codes (0 ok, 1 daemon error, 2 bad arguments, 3 cannot connect).
#include <gtest/gtest.h>

#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "control/server_harness.hpp"

namespace tissue::control {
namespace {

using nlohmann::json;
using testing::FakeHandler;
using testing::ServerHarness;

struct Result {
  int exit_code = -1;
  std::string out;  // stdout
  std::string err;  // stderr
};

std::string slurp(const std::string& path) {
  std::string s;
  if (FILE* f = std::fopen(path.c_str(), "rb")) {
    char buf[4096];
    std::size_t n;
    while ((n = std::fread(buf, 1, sizeof buf, f)) > 0) s.append(buf, n);
    std::fclose(f);
  }
  return s;
}

// Runs `tissue <args>` (args already shell-quoted where needed) in `cwd`.
Result tissue(const std::string& args, const testing::TempDir& scratch, const std::string& cwd = "") {
  const std::string out = scratch / "stdout", err = scratch / "stderr";
  std::string command;
  if (!cwd.empty()) command = "cd '" + cwd + "' && ";
  command += std::string("'") + TISSUE_CLI_BINARY + "' " + args + " >'" + out + "' 2>'" + err + "'";
  const int status = std::system(command.c_str());
  Result r;
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  r.out = slurp(out);
  r.err = slurp(err);
  return r;
}

class TissueCli : public ::testing::Test {
 protected:
  ServerHarness server_{ServerHarness::default_settings(nullptr)};
  testing::TempDir scratch_;
  std::string sock() const { return "--socket '" + server_.socket_path() + "' "; }
};

TEST_F(TissueCli, StatusPrintsTheResultAndExitsZero) {
  const Result r = tissue("ctl " + sock() + "status", scratch_);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(json::parse(r.out), json({{"state", "running"}, {"scene", "cantilever"}, {"calls_before", 0}}));
  EXPECT_EQ(r.err, "");
}

TEST_F(TissueCli, SetAndLoadSceneSendTheirArguments) {
  EXPECT_EQ(tissue("ctl " + sock() + "set material.youngs_modulus_Pa 8e4", scratch_).exit_code, 0);
  EXPECT_EQ(tissue("ctl " + sock() + "set 'gravity_m_per_s2[2]' -9.81", scratch_).exit_code, 0);
  EXPECT_EQ(tissue("ctl " + sock() + "set integrator.kind=implicit", scratch_).exit_code, 0);
  EXPECT_EQ(tissue("ctl " + sock() + "set gravity_m_per_s2 '[0,0,-1]'", scratch_).exit_code, 0);
  EXPECT_EQ(tissue("ctl " + sock() + "load_scene scenes/beam.yaml", scratch_, scratch_.path()).exit_code, 0);
  const auto calls = server_.handler().calls();
  ASSERT_EQ(calls.size(), 5u);
  EXPECT_EQ(calls[0].args, json({{"key", "material.youngs_modulus_Pa"}, {"value", 8e4}}));
  EXPECT_EQ(calls[1].args, json({{"key", "gravity_m_per_s2[2]"}, {"value", -9.81}}));
  EXPECT_EQ(calls[2].args, json({{"key", "integrator.kind"}, {"value", "implicit"}}));
  EXPECT_EQ(calls[3].args.at("value"), json::array({0, 0, -1}));
  EXPECT_EQ(calls[4].cmd, "load_scene");
  // Relative to where the user ran it, not to the daemon's directory.
  EXPECT_EQ(calls[4].args.at("path"), (std::filesystem::path(scratch_.path()) / "scenes/beam.yaml").string());
}

TEST_F(TissueCli, DaemonErrorsExitOne) {
  Result r = tissue("ctl " + sock() + "bogus", scratch_);
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("unknown command 'bogus'"), std::string::npos) << r.err;
  EXPECT_EQ(r.out, "");
  server_.handler().fail_with(FakeHandler::Failure::kControlError, "no scene loaded");
  r = tissue("ctl " + sock() + "reset", scratch_);
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("reset: no scene loaded"), std::string::npos) << r.err;
}

TEST_F(TissueCli, BadArgumentsExitTwoAndSendNothing) {
  const std::vector<std::string> cases = {"",
                                          "ctl",
                                          "ctl " + sock(),
                                          "ctl --tcp 0 status",
                                          "ctl --tcp 70000 status",
                                          "ctl " + sock() + "--tcp 5000 status",
                                          "ctl " + sock() + "set",
                                          "ctl " + sock() + "set 'a..b' 1",
                                          "ctl " + sock() + "load_scene",
                                          "ctl " + sock() + "status verbose",
                                          "ctl " + sock() + "--timeout 0 status",
                                          "nosuchcommand"};
  for (const std::string& args : cases) {
    const Result r = tissue(args, scratch_);
    EXPECT_EQ(r.exit_code, 2) << "tissue " << args << "\n" << r.err;
    EXPECT_NE(r.err, "") << "tissue " << args;
  }
  EXPECT_EQ(server_.handler().call_count(), 0u);
  EXPECT_EQ(tissue("--help", scratch_).exit_code, 0);
  EXPECT_EQ(tissue("ctl --help", scratch_).exit_code, 0);
}

TEST_F(TissueCli, NoDaemonExitsThreeNamingTheSocket) {
  const std::string absent = scratch_ / "absent.sock";
  const Result r = tissue("ctl --socket '" + absent + "' status", scratch_);
  EXPECT_EQ(r.exit_code, 3);
  EXPECT_NE(r.err.find("cannot connect to control socket " + absent), std::string::npos) << r.err;
  EXPECT_EQ(r.out, "");
}

// A socket path that no Unix socket can have (empty, or longer than the 107
// bytes of sun_path) is a bad argument naming --socket and the limit: it
// was a connection failure, exit 3, "(is tissued running?)".
TEST_F(TissueCli, AnImpossibleSocketPathIsABadArgument) {
  const std::string long_path = "/tmp/" + std::string(103, 's');  // 108 bytes
  ASSERT_EQ(long_path.size(), 108u);
  const std::string longest = "/tmp/" + std::string(102, 's');  // 107: may exist, so it is a connect failure
  struct Case {
    std::string path, said;
  };
  for (const Case& c : {Case{"", "tissue ctl: --socket: the path is empty\n"},
                        Case{long_path, "tissue ctl: --socket '" + long_path +
                                            "': 108 bytes, longer than a Unix socket path can be (107 bytes)\n"}}) {
    const Result r = tissue("ctl --socket '" + c.path + "' status", scratch_);
    EXPECT_EQ(r.exit_code, 2) << "--socket '" << c.path << "'\n" << r.err;
    EXPECT_EQ(r.err, c.said);
  }
  const Result r = tissue("ctl --socket '" + longest + "' status", scratch_);
  EXPECT_EQ(r.exit_code, 3) << r.err;
  EXPECT_NE(r.err.find("cannot connect to control socket " + longest + ": "), std::string::npos) << r.err;
  EXPECT_EQ(server_.handler().call_count(), 0u);
}

TEST(TissueCliTcp, TalksToTheLoopbackPort) {
  ServerSettings s;
  s.tcp_port = 0;
  ServerHarness server(s);
  testing::TempDir scratch;
  const Result r = tissue("ctl --tcp " + std::to_string(server.server().tcp_endpoint()->port()) + " pause", scratch);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(json::parse(r.out), json({{"paused", true}}));
}

}  // namespace
}  // namespace tissue::control
