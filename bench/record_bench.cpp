// record_bench: sustained session recording at daemon rates.
//
//   record_bench [--seconds N] [--triangles T] [--dir DIR] [--keep]
//
// A "haptic" thread pushes one row per millisecond (1 kHz, paced with
// clock_nanosleep), a "sim" thread pushes 50 Hz sim rows and 30 Hz frames of
// a deforming grid surface of about T triangles (default 100k). Prints write
// throughput (file bytes / s), file growth per minute, what was written and
// every drop. The file goes to DIR (default $TMPDIR or /tmp) and is removed
// unless --keep. --seconds is 0.1 to 86400, --triangles 2 to 10,000,000.
#include <sys/stat.h>
#include <time.h>

#include <atomic>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <string>
#include <thread>
#include <type_traits>
#include <vector>

#include "record/recorder.hpp"

using namespace tissue::record;

namespace {

void sleep_until_ns(std::int64_t t_ns) {
  timespec ts{static_cast<time_t>(t_ns / 1'000'000'000), static_cast<long>(t_ns % 1'000'000'000)};
  while (::clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
  }
}

std::int64_t now_ns() {
  timespec ts{};
  ::clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

// `text` as a T within [min, max], the whole of it (from_chars: no sign on an
// unsigned, no leading space, no trailing characters). Otherwise prints why,
// naming `option`, and returns false: atof/strtoull read "1e6" as 1, wrapped
// "-1" to 2^64 - 1 and let "inf" through to a double -> int64 conversion.
template <typename T>
bool parse_option(const char* option, const char* text, T min, T max, T* out) {
  T value{};
  const char* end = text + std::strlen(text);
  const auto [stop, error] = std::from_chars(text, end, value);
  if (error != std::errc{} || stop != end || !std::isfinite(static_cast<double>(value)) || value < min || value > max) {
    std::fprintf(stderr, "record_bench: %s must be a %s from %.10g to %.10g (got '%s')\n", option,
                 std::is_integral_v<T> ? "whole number" : "number", static_cast<double>(min), static_cast<double>(max),
                 text);
    return false;
  }
  *out = value;
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  double seconds = 10.0;
  std::size_t triangles_wanted = 100'000;
  const char* tmp = std::getenv("TMPDIR");
  std::string dir = tmp && *tmp ? tmp : "/tmp";
  bool keep = false;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--seconds" && i + 1 < argc) {
      // At most a day: seconds x 1e9 stays a small int64 of nanoseconds.
      if (!parse_option("--seconds", argv[++i], 0.1, 86400.0, &seconds)) return 2;
    } else if (a == "--triangles" && i + 1 < argc) {
      // The transport bench's bound: a few hundred MB per frame buffer.
      if (!parse_option<std::size_t>("--triangles", argv[++i], 2, 10'000'000, &triangles_wanted)) return 2;
    } else if (a == "--dir" && i + 1 < argc)
      dir = argv[++i];
    else if (a == "--keep")
      keep = true;
    else {
      std::fprintf(stderr, "usage: %s [--seconds N] [--triangles T] [--dir DIR] [--keep]\n", argv[0]);
      return 2;
    }
  }

  // An n x n grid of quads, two triangles each.
  const std::size_t n = std::max<std::size_t>(1, static_cast<std::size_t>(std::sqrt(triangles_wanted / 2.0)));
  std::vector<std::array<double, 3>> vertices((n + 1) * (n + 1));
  std::vector<std::array<std::uint32_t, 3>> triangles;
  std::vector<std::uint8_t> levels(vertices.size());
  for (std::size_t j = 0; j < n; ++j)
    for (std::size_t i = 0; i < n; ++i) {
      const auto v = [&](std::size_t a, std::size_t b) { return static_cast<std::uint32_t>(b * (n + 1) + a); };
      triangles.push_back({v(i, j), v(i + 1, j), v(i + 1, j + 1)});
      triangles.push_back({v(i, j), v(i + 1, j + 1), v(i, j + 1)});
    }
  for (std::size_t k = 0; k < levels.size(); ++k) levels[k] = static_cast<std::uint8_t>(k % 9);

  const std::string name = "record_bench_" + std::to_string(::getpid()) + ".h5";
  const std::string path = (std::filesystem::path(dir) / name).string();
  SessionMetadata meta;
  meta.scene_name = "record_bench";
  meta.software_version = "bench";
  RecorderOptions options;
  options.mesh_max_vertices = vertices.size();
  options.mesh_max_triangles = triangles.size();
  options.mesh_frame_interval_s = 1.0 / 30.0;
  std::unique_ptr<Recorder> rec;
  try {
    rec = Recorder::start(dir, name, meta, options);
  } catch (const RecordError& e) {
    std::fprintf(stderr, "record_bench: %s\n", e.what());
    return 1;
  }

  std::atomic<bool> running{true};
  const std::int64_t t0 = now_ns();
  std::thread haptic([&] {
    std::int64_t next = t0;
    for (std::uint64_t i = 0; running.load(std::memory_order_relaxed); ++i) {
      HapticRow r;
      r.time_s = rec->session_time_s(now_ns());
      r.device_position_m = {0.01 * std::sin(1e-3 * i), 0.0, -0.001};
      r.proxy_position_m = {r.device_position_m[0], 0.0, 0.0};
      r.force_N = {0.0, 0.0, 0.3};
      r.contact = 1;
      r.model_version = i / 10;
      rec->push_haptic(r);
      next += 1'000'000;
      sleep_until_ns(next);
    }
  });
  std::thread sim([&] {
    std::int64_t next = t0;
    for (std::uint64_t tick = 0; running.load(std::memory_order_relaxed); ++tick) {  // 150 Hz ticks
      const double t = rec->session_time_s(now_ns());
      if (tick % 3 == 0) {
        SimRow s;
        s.time_s = s.sim_time_s = t;
        s.real_time_factor = 1.0;
        s.nodes = vertices.size();
        rec->push_sim(s);
      }
      if (rec->mesh_frame_due(t)) {
        for (std::size_t k = 0; k < vertices.size(); ++k) {
          const double x = static_cast<double>(k % (n + 1)) / n, y = static_cast<double>(k / (n + 1)) / n;
          vertices[k] = {0.1 * x, 0.1 * y, 0.005 * std::sin(6.0 * x + t) * std::cos(4.0 * y)};
        }
        rec->push_mesh_frame({t, vertices, triangles, levels, {}});  // no strain: stored as NaN, same bytes
      }
      next += 1'000'000'000 / 150;
      sleep_until_ns(next);
    }
  });

  sleep_until_ns(t0 + static_cast<std::int64_t>(seconds * 1e9));
  running = false;
  haptic.join();
  sim.join();
  const std::int64_t t_stop = now_ns();
  rec->stop();
  const double elapsed_s = (now_ns() - t0) * 1e-9;
  const double stop_s = (now_ns() - t_stop) * 1e-9;

  struct stat st {};
  const double file_bytes = ::stat(path.c_str(), &st) == 0 ? static_cast<double>(st.st_size) : 0.0;
  const RecorderStats s = rec->stats();
  std::printf("record_bench: %.1f s, surface %zu vertices / %zu triangles, file %s\n", seconds, vertices.size(),
              triangles.size(), path.c_str());
  std::printf("  state:                %s%s\n",
              rec->state() == RecorderState::kStopped ? "stopped cleanly" : "FAILED: ", rec->error().c_str());
  std::printf(
      "  written:              %llu haptic rows, %llu sim rows, %llu mesh frames, %llu events\n",
      static_cast<unsigned long long>(s.haptic_rows_written), static_cast<unsigned long long>(s.sim_rows_written),
      static_cast<unsigned long long>(s.mesh_frames_written), static_cast<unsigned long long>(s.events_written));
  std::printf("  mesh frame rate:      %.1f Hz\n", s.mesh_frames_written / seconds);
  std::printf("  file size:            %.1f MB (payload %.1f MB)\n", file_bytes / 1e6, s.bytes_written / 1e6);
  std::printf("  write throughput:     %.1f MB/s (file bytes / recording time)\n", file_bytes / 1e6 / seconds);
  std::printf("  file growth:          %.0f MB/min\n", file_bytes / 1e6 / seconds * 60.0);
  std::printf("  flushes:              %llu\n", static_cast<unsigned long long>(s.flushes));
  std::printf("  stop (drain+close):   %.3f s (total %.2f s)\n", stop_s, elapsed_s);
  std::printf("  drops:                haptic %llu, sim %llu, mesh frames %llu (too big %llu), events %llu\n",
              static_cast<unsigned long long>(s.haptic_drops), static_cast<unsigned long long>(s.sim_drops),
              static_cast<unsigned long long>(s.mesh_frame_drops),
              static_cast<unsigned long long>(s.mesh_frames_too_big), static_cast<unsigned long long>(s.event_drops));
  if (!keep) std::filesystem::remove(path);
  return rec->state() == RecorderState::kStopped ? 0 : 1;
}
