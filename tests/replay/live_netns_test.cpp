// Live sources end to end, inside a private network namespace with a private
// /dev/shm (the ReplayNetns ctest entry): `tissue session replay` publishes a
// recorded session over LCM or DDS, and `tissue x3d --lcm`, `tissue render
// --dds` (and the in-process DdsMeshSubscriber) consume it; --dds-max-mesh-bytes
// keeps larger meshes off DDS. Skipped outside that entry
// (TISSUE_TEST_LCM_URL / TISSUE_TEST_DDS_DOMAIN unset).
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "config/daemon_config.hpp"
#include "export/export_test_support.hpp"
#include "record/session_writer.hpp"
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

// The session of the --dds-max-mesh-bytes cases: frames k = 0 .. 14 at k / 30
// s, alternately small and large (the last one small, so a subscriber knows
// when it has seen everything); haptic and sim rows as write_session's.
constexpr std::uint64_t kLimitFrames = 15;
constexpr std::uint64_t kLimitLargeFrames = kLimitFrames / 2;  // the odd ones
bool is_large_frame(std::uint64_t k) { return k % 2 == 1; }

// Even k: test_frame(k) (at most 16 vertices, under 1 KB serialized). Odd k:
// a strip of 2000 + k quads, 4002 + 2k vertices and 4000 + 2k triangles with
// strain, about 116 KB serialized: over the 64 KiB minimum limit, under 256
// KiB. The vertex count tells the two kinds apart.
record::testing::TestFrame limit_frame(std::uint64_t k) {
  record::testing::TestFrame f = record::testing::test_frame(k);
  if (!is_large_frame(k)) return f;
  f.vertices_m.clear();
  f.vertex_level.clear();
  f.triangles.clear();
  f.triangle_strain_energy_J_per_m3.clear();
  const std::uint32_t quads = 2000 + static_cast<std::uint32_t>(k);
  for (std::uint32_t q = 0; q <= quads; ++q)
    for (std::uint32_t row = 0; row < 2; ++row) {
      f.vertices_m.push_back({0.001 * q, 0.25 * row, 0.0625 * static_cast<double>(k)});
      f.vertex_level.push_back(static_cast<std::uint8_t>(q % 7));
    }
  for (std::uint32_t q = 0; q < quads; ++q) {
    const std::uint32_t a = 2 * q, b = 2 * q + 1, c = 2 * q + 2, d = 2 * q + 3;
    f.triangles.push_back({a, c, b});
    f.triangles.push_back({b, c, d});
  }
  f.triangle_strain_energy_J_per_m3.assign(f.triangles.size(), 1.5f);
  return f;
}

std::string write_limit_session(const std::string& path) {
  record::SessionMetadata m;
  m.scene_name = "mesh limit test";
  m.software_version = "test";
  auto w = record::SessionWriter::create(path, m);
  std::vector<record::HapticRow> haptic;
  for (std::uint64_t i = 0; i < kLimitFrames * 1000 / 30; ++i) haptic.push_back(record::testing::haptic_row(i));
  w->append_haptic(haptic);
  std::vector<record::SimRow> sim;
  for (std::uint64_t i = 0; i < kLimitFrames * 50 / 30; ++i) sim.push_back(record::testing::sim_row(i));
  w->append_sim(sim);
  for (std::uint64_t k = 0; k < kLimitFrames; ++k) w->append_mesh_frame(limit_frame(k).view());
  w->close();
  return path;
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

// What a subscriber (the project's DdsMeshSubscriber, expecting meshes up to
// its default 8 MiB: only the publisher's limit applies) gets from `tissue
// session replay` of write_limit_session with --dds-max-mesh-bytes.
struct LimitedReplay {
  RunResult result;
  std::vector<std::uint64_t> frames;  // k of each frame received, in arrival order
  std::vector<std::size_t> vertices;  // its vertex count
  std::optional<std::int64_t> last_sequence;
  std::uint64_t rejected = 0;
};

TEST_F(LiveNetns, DdsMaxMeshBytesKeepsLargerFramesOffTheWireAndTheSummarySaysWhy) {
  const std::string session = write_limit_session(dir_ / "limit.h5");
  const double last_time_s = limit_frame(kLimitFrames - 1).time_s;
  const auto replay_with_limit = [&](std::size_t limit_bytes) {
    transport::DdsOptions o;
    o.domain_id = std::atoi(domain_.c_str());
    transport::DdsMeshSubscriber sub(o);
    LimitedReplay got;
    std::atomic<bool> done{false};
    std::thread replay([&] {
      got.result = cli("session replay " + quote(session) + " " + dds() + " --dds-wait 5 --dds-max-mesh-bytes " +
                       std::to_string(limit_bytes));
      done = true;
    });
    // Until the replay has ended and its last (small) frame has arrived, or
    // nothing more came within 1 s of the end.
    for (bool last = false; !done || !last;) {
      if (auto f = sub.next_frame(done ? 1.0 : 0.1)) {
        got.frames.push_back(static_cast<std::uint64_t>(std::llround(f->time_s * 30.0)));
        got.vertices.push_back(f->vertices_m.size());
        last = f->time_s == last_time_s;
      } else if (done) {
        break;
      }
    }
    replay.join();
    got.last_sequence = sub.counts().last_sequence;
    got.rejected = sub.counts().rejected;
    return got;
  };
  const auto dds_line = [&](std::uint64_t meshes, std::uint64_t failures) {
    // 500 haptic rows at 1 kHz -> 50 at 100 Hz; 25 sim rows at 50 Hz -> 3 at 5 Hz.
    return "  DDS domain " + domain_ + " topics tissue/*: " + std::to_string(meshes) + " meshes, 50 haptic states, " +
           "3 stats sent, " + std::to_string(failures) + " failures";
  };
  const std::string why = " (" + std::to_string(kLimitLargeFrames) +
                          " of them meshes over --dds-max-mesh-bytes 65536 serialized, not sent)";
  {
    SCOPED_TRACE("--dds-max-mesh-bytes 65536: the large frames are over it");
    const LimitedReplay got = replay_with_limit(std::size_t{64} << 10);
    ASSERT_EQ(got.result.exit_code, 0) << got.result.err;
    EXPECT_NE(got.result.out.find(dds_line(kLimitFrames - kLimitLargeFrames, kLimitLargeFrames) + why + "\n"),
              std::string::npos)
        << got.result.out;
    for (std::size_t i = 0; i < got.frames.size(); ++i) {
      ASSERT_LT(got.frames[i], kLimitFrames);
      EXPECT_FALSE(is_large_frame(got.frames[i]))
          << "frame " << got.frames[i] << " (" << got.vertices[i] << " vertices) is over the limit and was delivered";
      EXPECT_EQ(got.vertices[i], limit_frame(got.frames[i]).vertices_m.size()) << "frame " << got.frames[i];
    }
    // The small frames do go out (reliable, keep-last 8): the last one, and
    // the sequence numbers count only what was sent.
    ASSERT_FALSE(got.frames.empty()) << got.result.out;
    EXPECT_EQ(got.frames.back(), kLimitFrames - 1) << got.result.out;
    EXPECT_EQ(got.last_sequence, static_cast<std::int64_t>(kLimitFrames - kLimitLargeFrames));
    EXPECT_EQ(got.rejected, 0u);
  }
  {
    SCOPED_TRACE("--dds-max-mesh-bytes 262144: every frame is under it");
    const LimitedReplay got = replay_with_limit(std::size_t{256} << 10);
    ASSERT_EQ(got.result.exit_code, 0) << got.result.err;
    EXPECT_NE(got.result.out.find(dds_line(kLimitFrames, 0) + "\n"), std::string::npos) << got.result.out;
    EXPECT_EQ(got.result.out.find("(a mesh over"), std::string::npos) << got.result.out;
    std::size_t large = 0;
    for (std::size_t i = 0; i < got.frames.size(); ++i) {
      ASSERT_LT(got.frames[i], kLimitFrames);
      EXPECT_EQ(got.vertices[i], limit_frame(got.frames[i]).vertices_m.size()) << "frame " << got.frames[i];
      if (is_large_frame(got.frames[i])) ++large;
    }
    EXPECT_GE(large, 1u) << "no frame over 64 KiB delivered under a 256 KiB limit";
    ASSERT_FALSE(got.frames.empty()) << got.result.out;
    EXPECT_EQ(got.frames.back(), kLimitFrames - 1) << got.result.out;
    EXPECT_EQ(got.last_sequence, static_cast<std::int64_t>(kLimitFrames));
    EXPECT_EQ(got.rejected, 0u);
  }
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

// An output that cannot be written is refused before the collection, not
// after it: `-o` in a missing directory was found only once --timeout (or
// --seconds, up to an hour) had passed, and the take was lost. Nothing is
// published here, so a check made after collecting waits the whole --timeout
// and exits 4.
TEST_F(LiveNetns, AnOutputThatCannotBeWrittenIsRefusedBeforeCollecting) {
  const std::string missing = dir_ / "no/such/dir";
  const auto refused_at_once = [&](const std::string& args, int exit_code, const std::string& said) {
    const auto t0 = std::chrono::steady_clock::now();
    const RunResult r = cli(args + " --timeout 20");
    const double took_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    EXPECT_EQ(r.exit_code, exit_code) << args << "\n" << r.err;
    EXPECT_NE(r.err.find(said), std::string::npos) << args << "\n" << r.err;
    EXPECT_LT(took_s, 10.0) << args << ": waited for frames before checking -o";
  };
  const std::string lcm = "--lcm " + quote(url_);
  refused_at_once("x3d " + lcm + " --animate --seconds 5 -o " + quote(missing + "/a.x3d"), 1,
                  "tissue x3d: cannot write '" + missing + "/a.x3d': ");
  refused_at_once("x3d " + lcm + " -o " + quote(missing + "/a.x3d"), 1,
                  "tissue x3d: cannot write '" + missing + "/a.x3d': ");
  refused_at_once("x3d " + lcm + " --animate -o ''", 2, "tissue x3d: -o: the output path is empty");
  // A sequence's first numbered file is what is checked, and named.
  refused_at_once("render " + lcm + " --sequence --seconds 5 -o " + quote(missing + "/f.png"), 1,
                  "tissue render: cannot write " + missing + "/f-0000.png: ");
  refused_at_once("render " + lcm + " -o " + quote(missing + "/f.png"), 1,
                  "tissue render: cannot write " + missing + "/f.png: ");
  refused_at_once("render " + lcm + " --sequence -o ''", 2, "tissue render: -o: the output path is empty");
  EXPECT_FALSE(std::filesystem::exists(dir_ / "no"));
}

// Ctrl-C (SIGINT) or SIGTERM during a live --animate / --sequence ends the
// collection and exports what came so far, saying on stderr that it was cut
// short; the exit code is a normal finish's. The signal killed the client
// and every frame collected was lost.
TEST_F(LiveNetns, AStopSignalDuringACollectionExportsTheFramesSoFar) {
  // Not BackgroundReplay: its std::system() ignores SIGINT in this process
  // while the replay runs (the clients started meanwhile restore SIGINT's
  // default since process_support's child does, but this test should not
  // depend on that).
  tissue::testing::BackgroundProcess replay({TISSUE_CLI_BINARY, "session", "replay", session_, "--lcm", url_, "--loop"},
                                            dir_ / "replay.out", dir_ / "replay.err");
  ASSERT_TRUE(replay.started());
  struct Case {
    std::vector<std::string> args;
    int signo;
    std::string first_output;
  };
  const std::string anim = dir_ / "anim.x3d", seq = dir_ / "seq.png";
  const std::vector<Case> cases = {
      {{"x3d", "--lcm", url_, "--animate", "--seconds", "600", "-o", anim}, SIGINT, anim},
      {{"render", "--lcm", url_, "--sequence", "--seconds", "600", "--width", "64", "--height", "48", "-o", seq},
       SIGTERM,
       dir_ / "seq-0000.png"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.args[0] + " stopped by signal " + std::to_string(c.signo));
    std::vector<std::string> argv = {TISSUE_CLI_BINARY};
    argv.insert(argv.end(), c.args.begin(), c.args.end());
    tissue::testing::BackgroundProcess p(argv, dir_ / "out", dir_ / "err");
    ASSERT_TRUE(p.started());
    // 2 s of a 30 Hz replay: dozens of frames collected.
    std::this_thread::sleep_for(std::chrono::seconds(2));
    ASSERT_TRUE(p.signal(c.signo));
    const std::optional<int> status = p.wait_for_exit(60.0);
    ASSERT_TRUE(status.has_value()) << "still collecting 60 s after the signal";
    ASSERT_TRUE(WIFEXITED(*status)) << "ended by signal " << (WIFSIGNALED(*status) ? WTERMSIG(*status) : 0)
                                    << ": the frames collected were lost";
    EXPECT_EQ(WEXITSTATUS(*status), 0) << p.err();
    EXPECT_NE(p.err().find("tissue " + c.args[0] + ": the collection was cut short by " +
                           (c.signo == SIGINT ? std::string("SIGINT") : std::string("SIGTERM")) + " after "),
              std::string::npos)
        << p.err();
    EXPECT_TRUE(std::filesystem::exists(c.first_output)) << p.out() << p.err();
  }
  EXPECT_GE(x3d::testing::count_elements(record::testing::slurp(anim), "Shape"), 2u) << "several topologies in 2 s";
  EXPECT_TRUE(is_png(dir_ / "seq-0000.png"));
  EXPECT_TRUE(is_png(dir_ / "seq-0010.png")) << "30 Hz for 2 s: many frames";
  ASSERT_TRUE(replay.signal(SIGTERM));
  const std::optional<int> replayed = replay.wait_for_exit(30.0);
  ASSERT_TRUE(replayed.has_value());
  EXPECT_TRUE(WIFEXITED(*replayed) && WEXITSTATUS(*replayed) == 0) << replay.err();
}

// A stop after one frame leaves an --animate nothing to animate: said as a
// stop (exit 4, as a stop before the first frame), not as "its 1 frames are
// all at t=... (a paused simulation sends the same time)", exit 1.
TEST_F(LiveNetns, AStopSignalAfterOneFrameIsNotAnAnimation) {
  const std::string anim = dir_ / "one.x3d";
  tissue::testing::BackgroundProcess p(
      {TISSUE_CLI_BINARY, "x3d", "--lcm", url_, "--animate", "--seconds", "600", "--timeout", "600", "-o", anim},
      dir_ / "out", dir_ / "err");
  ASSERT_TRUE(p.started());
  std::this_thread::sleep_for(std::chrono::seconds(1));  // subscribed
  // 100x slower than recorded: the frames 3.3 s apart, the first at once.
  tissue::testing::BackgroundProcess replay(
      {TISSUE_CLI_BINARY, "session", "replay", session_, "--lcm", url_, "--speed", "0.01"}, dir_ / "replay.out",
      dir_ / "replay.err");
  ASSERT_TRUE(replay.started());
  std::this_thread::sleep_for(std::chrono::milliseconds(1500));
  ASSERT_TRUE(p.signal(SIGINT));
  const std::optional<int> status = p.wait_for_exit(60.0);
  ASSERT_TRUE(status.has_value()) << "still collecting 60 s after the signal";
  ASSERT_TRUE(WIFEXITED(*status)) << WTERMSIG(*status);
  EXPECT_EQ(WEXITSTATUS(*status), 4) << p.err();
  EXPECT_EQ(p.err(), "tissue x3d: stopped by SIGINT after 1 frame on LCM channel TISSUE_SURFACE_MESH on " + url_ +
                         ": an animation needs 2\n");
  EXPECT_FALSE(std::filesystem::exists(anim));
  ASSERT_TRUE(replay.signal(SIGTERM));
  EXPECT_TRUE(replay.wait_for_exit(30.0).has_value());
}

// A stop before the first frame has nothing to export: exit 4 (no
// surface_mesh), said as a stop, not as a --timeout that never ran out.
TEST_F(LiveNetns, AStopSignalBeforeTheFirstFrameIsNoLiveData) {
  tissue::testing::BackgroundProcess p(
      {TISSUE_CLI_BINARY, "x3d", "--lcm", url_, "--timeout", "600", "-o", dir_ / "none.x3d"}, dir_ / "out",
      dir_ / "err");
  ASSERT_TRUE(p.started());
  std::this_thread::sleep_for(std::chrono::seconds(1));
  ASSERT_TRUE(p.signal(SIGINT));
  const std::optional<int> status = p.wait_for_exit(60.0);
  ASSERT_TRUE(status.has_value());
  ASSERT_TRUE(WIFEXITED(*status)) << WTERMSIG(*status);
  EXPECT_EQ(WEXITSTATUS(*status), 4) << p.err();
  EXPECT_EQ(p.err(),
            "tissue x3d: stopped by SIGINT before any surface_mesh arrived on LCM channel "
            "TISSUE_SURFACE_MESH on " +
                url_ + "\n");
  EXPECT_FALSE(std::filesystem::exists(dir_ / "none.x3d"));
}

// While a live collection waits, OUT is only checked, not held open: the
// temporary file the export is written through (.NAME.tmp-PID-N) was made
// before collecting, so a signal that killed the client (SIGHUP from a
// closed terminal, during an hour's --animate) left it behind. And a FIFO
// is not opened before collecting: the open waited for the FIFO's reader,
// so `tissue x3d --lcm --animate -o FIFO & ...; cat FIFO` collected only
// from when cat opened it. Nothing is published: each run waits for its
// first frame until SIGINT stops it (exit 4).
TEST_F(LiveNetns, WhileCollectingNoTemporaryFileExistsAndAFifoIsNotOpened) {
  const std::filesystem::path out_dir = dir_ / "take";
  std::filesystem::create_directory(out_dir);
  const std::string fifo = out_dir / "take.fifo";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  const auto listing = [&] {
    std::string names;
    for (const auto& e : std::filesystem::directory_iterator(out_dir)) names += e.path().filename().string() + " ";
    return names;
  };
  for (const std::vector<std::string>& args :
       {std::vector<std::string>{"--animate", "--seconds", "600", "-o", out_dir / "take.x3d"},
        std::vector<std::string>{"-o", out_dir / "snap.x3d"}, std::vector<std::string>{"--animate", "-o", fifo}}) {
    std::vector<std::string> argv = {TISSUE_CLI_BINARY, "x3d", "--lcm", url_, "--timeout", "600"};
    argv.insert(argv.end(), args.begin(), args.end());
    SCOPED_TRACE("x3d ... -o " + args.back());
    tissue::testing::BackgroundProcess p(argv, dir_ / "out", dir_ / "err");
    ASSERT_TRUE(p.started());
    std::this_thread::sleep_for(std::chrono::seconds(1));
    EXPECT_EQ(listing(), "take.fifo ") << "while collecting";
    ASSERT_TRUE(p.signal(SIGINT));
    const std::optional<int> status = p.wait_for_exit(10.0);
    ASSERT_TRUE(status.has_value()) << "still running 10 s after SIGINT (waiting for the FIFO's reader?)";
    ASSERT_TRUE(WIFEXITED(*status)) << "ended by signal " << WTERMSIG(*status) << " (waiting for the FIFO's reader?)";
    EXPECT_EQ(WEXITSTATUS(*status), 4) << p.err();
    EXPECT_NE(p.err().find("tissue x3d: stopped by SIGINT before any surface_mesh arrived"), std::string::npos)
        << p.err();
    EXPECT_EQ(listing(), "take.fifo ") << "after the stop";
  }
}

// `--lcm ''` is --lcm without a URL: the documented default (as `tissue
// x3d --lcm ''`), not LCM's own default or $LCM_DEFAULT_URL, which an empty
// URL means to LCM.
TEST_F(LiveNetns, ReplayWithAnEmptyLcmUrlPublishesOnTheDefaultUrl) {
  const std::string other = "udpm://239.255.76.68:7668?ttl=0";
  const RunResult r = record::testing::run("LCM_DEFAULT_URL=" + quote(other) + " " + tissue() + " session replay " +
                                               quote(session_) + " --lcm '' --speed 100",
                                           dir_);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("\n  LCM " + config::LcmPublishSpec{}.url + ": " + std::to_string(kFrames) + " meshes"),
            std::string::npos)
      << r.out;
}

// An --lcm value that is not PROVIDER://... is a bad argument (exit 2), not
// an LCM that cannot start (exit 3).
TEST_F(LiveNetns, AnLcmValueThatIsNotAUrlIsABadArgument) {
  for (const char* command : {"x3d", "render"}) {
    const RunResult r = cli(std::string(command) + " --lcm foo --timeout 0.5 -o " + quote(dir_ / "x"));
    EXPECT_EQ(r.exit_code, 2) << command << ": " << r.err;
    EXPECT_NE(r.err.find("--lcm: 'foo' is not an LCM URL (PROVIDER://...)"), std::string::npos) << r.err;
  }
}

}  // namespace
}  // namespace tissue::replay
