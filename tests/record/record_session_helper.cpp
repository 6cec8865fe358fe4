// A separate process that records, for the tests that need one: killed with
// SIGKILL mid-session (crash), watched by a SWMR reader, run under a small
// RLIMIT_FSIZE (disk full) or without write permission.
//
//   record_session_helper record   DIR NAME SECONDS       1 kHz haptic, 50 Hz sim, 10 Hz mesh, 2 Hz events
//   record_session_helper fsize    DIR NAME LIMIT_BYTES   same, under RLIMIT_FSIZE, until the recorder fails
//   record_session_helper readonly DIR NAME               start a recording in DIR as an unprivileged user
//   record_session_helper watch    DIR NAME SECONDS       a reader polling for DIR/NAME without pause
//
// Rows follow record_test_support's generators, so the test checks every
// row. Progress lines on stdout: "progress PUSHED_HAPTIC WRITTEN_HAPTIC
// WRITTEN_FRAMES" after each recorder flush (written = flushed to the file).
// `watch` prints "ready", then tries SWMR opens of the path back to back (as
// a viewer polling for a session would); each open that works checks that
// the file is a whole session and holds it open 200 ms. At the end:
// "watched OPENS INCOMPLETE".
#include <signal.h>
#include <sys/resource.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <thread>

#include "record/recorder.hpp"
#include "record/session_layout.hpp"
#include "record_test_support.hpp"

using namespace tissue::record;
using Clock = std::chrono::steady_clock;

namespace {

// Pushes like the daemon's threads would, in one loop: a haptic row per
// millisecond, a sim row every 20, a mesh frame every 100, an event every 500.
// Returns the number of haptic rows pushed; *frames_offered (when given):
// how many mesh frames were offered to push_mesh_frame, accepted or not.
std::uint64_t produce(Recorder& r, double seconds, bool stop_on_failure, std::uint64_t* pushed_after_failure,
                      std::uint64_t* frames_offered = nullptr) {
  // Indices advance only on accepted pushes, so the file holds rows 0..n-1
  // of each generator with no gaps.
  std::uint64_t i = 0, sim = 0, frame = 0, event = 0, last_flushes = 0, after = 0, offered = 0;
  const auto start = Clock::now();
  auto next = start;
  for (std::uint64_t tick = 0; std::chrono::duration<double>(Clock::now() - start).count() < seconds; ++tick) {
    if (r.push_haptic(testing::haptic_row(i))) ++i;
    if (tick % 20 == 0 && r.push_sim(testing::sim_row(sim))) ++sim;
    if (tick % 100 == 0) {
      const testing::TestFrame f = testing::test_frame(frame);  // allocation here is the test's, not the recorder's
      ++offered;
      if (r.push_mesh_frame(f.view())) ++frame;
    }
    if (tick % 500 == 0 && r.push_event(EventSource::kControl, testing::event_row(event))) ++event;
    if (r.state() == RecorderState::kFailed) {
      ++after;
      if (stop_on_failure && after > 300) break;  // producers kept going for 300 ticks: enough
    }
    const RecorderStats s = r.stats();
    if (s.flushes != last_flushes) {
      last_flushes = s.flushes;
      std::printf("progress %llu %llu %llu\n", static_cast<unsigned long long>(i),
                  static_cast<unsigned long long>(s.haptic_rows_written),
                  static_cast<unsigned long long>(s.mesh_frames_written));
      std::fflush(stdout);
    }
    next += std::chrono::milliseconds(1);
    std::this_thread::sleep_until(next);
  }
  if (pushed_after_failure) *pushed_after_failure = after;
  if (frames_offered) *frames_offered = offered;
  return i;
}

RecorderOptions options() {
  RecorderOptions o;
  o.flush_interval_s = 0.2;
  o.mesh_max_vertices = 1000;
  o.mesh_max_triangles = 1000;
  o.min_free_bytes = 0;  // the fsize test wants the hard failure path
  return o;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 4) {
    std::fprintf(stderr, "usage: %s record|fsize|readonly|watch DIR NAME [ARG]\n", argv[0]);
    return 2;
  }
  const std::string mode = argv[1], dir = argv[2], name = argv[3];
  SessionMetadata meta;
  meta.scene_name = "helper";
  meta.software_version = "test";

  if (mode == "readonly") {
    // Root ignores permission bits: become nobody so the directory's mode counts.
    if (::geteuid() == 0 && (::setresgid(65534, 65534, 65534) != 0 || ::setresuid(65534, 65534, 65534) != 0)) {
      std::perror("dropping privileges");
      return 4;
    }
    try {
      auto r = Recorder::start(dir, name, meta, options());
      std::printf("started (unexpected)\n");
      return 3;
    } catch (const RecordError& e) {
      std::printf("error: %s\n", e.what());
      return 0;
    }
  }

  if (mode == "fsize") {
    if (argc < 5) return 2;
    // Writes past the limit fail with EFBIG instead of killing the process.
    ::signal(SIGXFSZ, SIG_IGN);
    const rlim_t limit = std::strtoull(argv[4], nullptr, 10);
    const struct rlimit rl = {limit, limit};
    if (::setrlimit(RLIMIT_FSIZE, &rl) != 0) {
      std::perror("setrlimit");
      return 4;
    }
    std::string callback_message;
    RecorderOptions o = options();
    o.on_error = [&](const std::string& m) { callback_message = m; };
    auto r = Recorder::start(dir, name, meta, o);
    std::uint64_t after = 0, frames_offered = 0;
    produce(*r, 20.0, true, &after, &frames_offered);
    const RecorderState state = r->state();
    r->stop();                           // must not crash or hang on a broken file
    const RecorderStats s = r->stats();  // after the stop: the last word
    std::printf("state %d\nerror %s\ncallback %s\npushes_after_failure %llu\nhaptic_drops %llu\n",
                static_cast<int>(state), r->error().c_str(), callback_message.c_str(),
                static_cast<unsigned long long>(after), static_cast<unsigned long long>(s.haptic_drops));
    std::printf("frames offered %llu written %llu dropped %llu invalid %llu\n",
                static_cast<unsigned long long>(frames_offered), static_cast<unsigned long long>(s.mesh_frames_written),
                static_cast<unsigned long long>(s.mesh_frame_drops),
                static_cast<unsigned long long>(s.mesh_frames_invalid));
    return state == RecorderState::kFailed ? 0 : 3;
  }

  if (mode == "watch") {
    if (argc < 5) return 2;
    H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
    const std::string path = dir + "/" + name;
    const auto end = Clock::now() + std::chrono::duration<double>(std::strtod(argv[4], nullptr));
    std::printf("ready\n");
    std::fflush(stdout);
    unsigned opens = 0, incomplete = 0;
    while (Clock::now() < end) {
      const hid_t file = H5Fopen(path.c_str(), H5F_ACC_RDONLY | H5F_ACC_SWMR_READ, H5P_DEFAULT);
      if (file < 0) continue;
      ++opens;
      const hid_t ds = H5Dopen2(file, kDatasets[kHapticTime].path, H5P_DEFAULT);
      if (H5Aexists(file, kAttrFormatVersion) <= 0 || H5Aexists(file, kAttrClosedCleanly) <= 0 || ds < 0) ++incomplete;
      if (ds >= 0) H5Dclose(ds);
      std::this_thread::sleep_for(std::chrono::milliseconds(200));
      H5Fclose(file);
    }
    std::printf("watched %u %u\n", opens, incomplete);
    return 0;
  }

  if (mode == "record") {
    const double seconds = std::strtod(argv[4 < argc ? 4 : 3], nullptr);
    auto r = Recorder::start(dir, name, meta, options());
    const std::uint64_t pushed = produce(*r, seconds, false, nullptr);
    r->stop();
    const RecorderStats s = r->stats();
    std::printf("done %llu %llu %d\n", static_cast<unsigned long long>(pushed),
                static_cast<unsigned long long>(s.haptic_rows_written), static_cast<int>(r->state()));
    return r->state() == RecorderState::kStopped ? 0 : 3;
  }
  return 2;
}
