// Live sources end to end, inside a private network namespace with a private
// /dev/shm (the ReplayNetns ctest entry): `tissue session replay` publishes a
// recorded session over LCM or DDS, and `tissue x3d --lcm`, `tissue render
// --dds` (and the in-process DdsMeshSubscriber) consume it. Skipped outside
// that entry (TISSUE_TEST_LCM_URL / TISSUE_TEST_DDS_DOMAIN unset).
#include <gtest/gtest.h>
#include <signal.h>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <thread>

#include "export/export_test_support.hpp"
#include "record_test_support.hpp"
#include "replay_test_support.hpp"
#include "transport/dds_subscriber.hpp"

namespace tissue::replay {
namespace {

using record::testing::quote;
using record::testing::RunResult;
using record::testing::TempDir;

std::string tissue() { return quote(TISSUE_CLI_BINARY); }

constexpr std::uint64_t kFrames = 45;  // 30 Hz: 1.467 s

// `tissue session replay FILE ARGS --loop` in the background until destroyed
// (SIGTERM: the replay stops cleanly).
class BackgroundReplay {
 public:
  BackgroundReplay(const std::string& path, const std::string& args) {
    const std::string pid_file = scratch_ / "pid";
    thread_ = std::thread([this, path, args, pid_file] {
      result_ = record::testing::run(tissue() + " session replay " + quote(path) + " " + args + " --loop & echo $! > " +
                                         quote(pid_file) + "; wait $!",
                                     scratch_);
    });
    for (int i = 0; i < 200 && pid_ <= 0; ++i) {
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
      pid_ = std::atoi(record::testing::slurp(pid_file).c_str());
    }
  }
  ~BackgroundReplay() { stop(); }
  const RunResult& stop() {
    if (pid_ > 0) ::kill(pid_, SIGTERM);
    pid_ = 0;
    if (thread_.joinable()) thread_.join();
    return result_;
  }

 private:
  TempDir scratch_;
  std::thread thread_;
  int pid_ = 0;
  RunResult result_;
};

bool is_png(const std::string& path) { return record::testing::slurp(path).rfind("\x89PNG\r\n\x1a\n", 0) == 0; }

void expect_tovrmlx3d_accepts(const std::string& x3d_path, const TempDir& dir) {
  const std::string tool = x3d::testing::tovrmlx3d_path();
  if (tool.empty()) {
    ADD_FAILURE() << "tovrmlx3d not installed (apt-get install view3dscene): cannot check " << x3d_path;
    return;
  }
  const RunResult v = record::testing::run(quote(tool) + " " + quote(x3d_path) + " --encoding xml", dir);
  EXPECT_EQ(v.exit_code, 0) << x3d_path;
  EXPECT_EQ(v.err, "") << x3d_path;
}

// Vertex counts of the recorded frames (what a snapshot may show).
bool is_recorded_vertex_count(std::size_t n) {
  for (std::uint64_t k = 0; k < kFrames; ++k)
    if (record::testing::test_frame(k).vertices_m.size() == n) return true;
  return false;
}

class LiveNetns : public ::testing::Test {
 protected:
  void SetUp() override {
    const char* url = std::getenv("TISSUE_TEST_LCM_URL");
    const char* domain = std::getenv("TISSUE_TEST_DDS_DOMAIN");
    if (!url || !domain)
      GTEST_SKIP() << "run through the ReplayNetns.InPrivateNamespace ctest entry (private network namespace)";
    url_ = url;
    domain_ = domain;
    session_ = testing::write_session(dir_ / "s.h5", kFrames);
  }
  RunResult cli(const std::string& args) { return record::testing::run(tissue() + " " + args, dir_); }
  std::string dds() const { return "--dds --dds-domain " + domain_; }
  TempDir dir_;
  std::string url_, domain_, session_;
};

TEST_F(LiveNetns, X3dAndRenderFromAnLcmReplay) {
  BackgroundReplay replay(session_, "--lcm " + quote(url_));
  const std::string snap = dir_ / "snap.x3d", anim = dir_ / "anim.x3d", png = dir_ / "one.png";
  RunResult r = cli("x3d --lcm " + quote(url_) + " --timeout 10 -o " + quote(snap));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string xml = record::testing::slurp(snap);
  const std::size_t coords = x3d::testing::numbers(x3d::testing::attribute(xml, "Coordinate", "point")).size();
  EXPECT_TRUE(coords % 3 == 0 && is_recorded_vertex_count(coords / 3)) << coords;
  expect_tovrmlx3d_accepts(snap, dir_);

  r = cli("x3d --lcm " + quote(url_) + " --animate --seconds 1 -o " + quote(anim));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_GE(x3d::testing::count_elements(record::testing::slurp(anim), "Shape"), 2u) << "several topologies in 1 s";
  expect_tovrmlx3d_accepts(anim, dir_);

  r = cli("render --lcm " + quote(url_) + " --width 64 --height 48 -o " + quote(png));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(is_png(png));
  const RunResult& rep = replay.stop();
  EXPECT_EQ(rep.exit_code, 0) << rep.err;
  EXPECT_EQ(rep.out.rfind("stopped: ", 0), 0u) << rep.out;
}

TEST_F(LiveNetns, RenderAndX3dFromADdsReplay) {
  BackgroundReplay replay(session_, dds());
  const std::string png = dir_ / "one.png", seq = dir_ / "seq.png", snap = dir_ / "snap.x3d";
  RunResult r = cli("render " + dds() + " --width 64 --height 48 -o " + quote(png));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(is_png(png));
  r = cli("render " + dds() + " --sequence --seconds 1 --width 64 --height 48 -o " + quote(seq));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(is_png(dir_ / "seq-0000.png"));
  EXPECT_TRUE(is_png(dir_ / "seq-0005.png")) << "30 Hz for 1 s: many frames\n" << r.out;
  r = cli("x3d " + dds() + " -o " + quote(snap));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  expect_tovrmlx3d_accepts(snap, dir_);
}

TEST_F(LiveNetns, DdsReplayDeliversTheFramesInOrderAtThePace) {
  transport::DdsOptions o;
  o.domain_id = std::atoi(domain_.c_str());
  transport::DdsMeshSubscriber sub(o);
  RunResult result;
  std::atomic<bool> done{false};
  std::thread replay([&] {
    result = cli("session replay " + quote(session_) + " " + dds() + " --dds-wait 5");
    done = true;
  });
  struct Got {
    double wall_s, time_s;
    std::size_t vertices;
    bool strain;  // one value per vertex
  };
  std::vector<Got> got;
  const auto now_s = [] {
    return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
  };
  while (!done || got.empty() || got.back().time_s < record::testing::test_frame(kFrames - 1).time_s) {
    if (auto f = sub.next_frame(done ? 1.0 : 0.1))
      got.push_back(
          {now_s(), f->time_s, f->vertices_m.size(), f->vertex_strain_energy_Pa.size() == f->vertices_m.size()});
    else if (done)
      break;
  }
  replay.join();
  ASSERT_EQ(result.exit_code, 0) << result.err;
  ASSERT_GE(got.size(), kFrames - 5) << "reliable, keep-last 8: (almost) every frame\n" << result.out;
  for (std::size_t i = 0; i < got.size(); ++i) {
    const auto k = static_cast<std::uint64_t>(std::llround(got[i].time_s * 30.0));
    ASSERT_LT(k, kFrames);
    EXPECT_EQ(got[i].time_s, record::testing::test_frame(k).time_s);
    EXPECT_EQ(got[i].vertices, record::testing::test_frame(k).vertices_m.size()) << "frame " << k;
    EXPECT_TRUE(got[i].strain) << "the session has strain: so do the replayed frames (frame " << k << ")";
    if (i > 0) {
      EXPECT_GT(got[i].time_s, got[i - 1].time_s) << "in order";
    }
  }
  EXPECT_EQ(sub.counts().rejected, 0u);
  const double recorded_s = got.back().time_s - got.front().time_s;
  const double wall_s = got.back().wall_s - got.front().wall_s;
  EXPECT_GT(wall_s / recorded_s, 0.8) << wall_s;
  EXPECT_LT(wall_s / recorded_s, 1.5) << wall_s;
}

TEST_F(LiveNetns, NothingPublishedIsATimeoutWithItsOwnExitCode) {
  RunResult r = cli("x3d --lcm " + quote(url_) + " --timeout 0.5 -o " + quote(dir_ / "none.x3d"));
  EXPECT_EQ(r.exit_code, 4) << r.err;
  EXPECT_EQ(r.err, "tissue x3d: no surface_mesh on LCM channel TISSUE_SURFACE_MESH on " + url_ + " within 0.5 s\n");
  r = cli("render " + dds() + " --timeout 0.5 -o " + quote(dir_ / "none.png"));
  EXPECT_EQ(r.exit_code, 4) << r.err;
  EXPECT_EQ(r.err,
            "tissue render: no surface_mesh on DDS topic tissue/surface_mesh (domain " + domain_ + ") within 0.5 s\n");
  EXPECT_FALSE(std::filesystem::exists(dir_ / "none.x3d"));
  EXPECT_FALSE(std::filesystem::exists(dir_ / "none.png"));
}

}  // namespace
}  // namespace tissue::replay
