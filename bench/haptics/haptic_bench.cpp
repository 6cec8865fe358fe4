// haptic_bench: what the 1 kHz haptic thread achieves on this machine.
//
// For each background load (idle, and the adaptive cantilever simulation
// stepping continuously on another thread) it measures, in the same run and
// with the same thread settings (SCHED_FIFO when permitted, 1 ns timer slack):
//   - a bare clock_nanosleep(TIMER_ABSTIME) loop: lateness p50/p99/p99.9, and
//     the time a fixed ~3 us arithmetic workload takes in each period (the
//     machine's own tail, read beside the tick's);
//   - the HapticThread driving a HapticLoop with a SimDevice hand pressing a
//     deformable patch while a publisher thread feeds a new LocalModel every
//     millisecond: period lateness and tick compute time p50/p99/p99.9.
// and prints the lateness ratio haptic p99 / bare p99.
// A third configuration is the daemon's own pipeline: the sim thread stepping
// the scene (with its tool) and publishing the LocalModel it builds after
// every step, the haptic thread pressing the real surface patch with the
// simulated hand, beside a bare loop measured while the same sim thread runs;
// then the same recording the session to HDF5, and the haptic lateness p99
// with the recording / without it (two runs in turn, not interleaved).
// Targets: tick compute p99.9 <= 20 us; lateness p99 within 1.5x the bare loop's.
//
//   haptic_bench [--seconds 10] [--scene config/scenes/cantilever.yaml] [--no-fifo]
//
// --seconds is per configuration, 0.1 to 86400. The recorded session goes to
// the temporary directory as haptic_bench_<pid>.h5 and is removed afterwards.
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <stdexcept>
#include <string>
#include <system_error>
#include <thread>

#include "haptics/haptic_thread.hpp"
#include "haptics/sim_device.hpp"
#include "physics/simulation.hpp"
#include "record/recorder.hpp"
#include "scene/scene_yaml.hpp"
#include "service/sim_thread.hpp"

namespace {

using namespace tissue;
using haptics::LatencyHistogram;
using haptics::Vec3;

struct BackgroundSim {
  std::atomic<bool> stop{false};
  std::atomic<std::uint64_t> steps{0};
  std::string error;
  std::thread thread;

  void start(const scene::Scene& scene) {
    thread = std::thread([this, scene] {
      try {
        auto sim = std::make_unique<physics::Simulation>(scene);
        while (!stop.load(std::memory_order_relaxed)) {
          const physics::StepResult r = sim->step();
          if (!r.ok) {  // restart the scene rather than stop loading the machine
            if (error.empty()) error = r.error;
            sim = std::make_unique<physics::Simulation>(scene);
          }
          steps.fetch_add(1, std::memory_order_relaxed);
        }
      } catch (const std::exception& e) {
        error = e.what();
      }
    });
  }
  void join() {
    stop.store(true);
    if (thread.joinable()) thread.join();
  }
  // A measurement that throws leaves through here: a joinable std::thread
  // would terminate the process instead of reaching main's catch.
  ~BackgroundSim() { join(); }
};

// Removes the session file however measure_pipeline() is left (declared
// before the recorder, so the file is closed first).
struct RemoveFileOnExit {
  std::string path;
  ~RemoveFileOnExit() {
    std::error_code ignored;
    if (!path.empty()) std::filesystem::remove(path, ignored);
  }
};

haptics::LocalModel make_patch() {
  haptics::LocalModel m;
  m.vertex_m.fill(Vec3::Zero());
  m.vertex_velocity_m_per_s.fill(Vec3::Zero());
  // A 9x9-vertex grid (128 triangles, close to the contract's maximum) at z = 0.
  const int n = 9;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      m.vertex_m[j * n + i] = Vec3(-0.04 + 0.01 * i, -0.04 + 0.01 * j, 0.0);
      m.vertex_node[j * n + i] = static_cast<std::uint32_t>(j * n + i);
    }
  m.vertex_count = n * n;
  int t = 0;
  for (int j = 0; j + 1 < n; ++j)
    for (int i = 0; i + 1 < n; ++i) {
      const int a = j * n + i;
      m.triangle[t++] = {a, a + 1, a + n + 1};
      m.triangle[t++] = {a, a + n + 1, a + n};
    }
  m.triangle_count = t;
  m.in_contact = true;
  m.contact_stiffness_N_per_m = 800.0 * haptics::Mat3::Identity();
  return m;
}

void print_row(const char* name, const haptics::TimingSummary& t, bool with_compute) {
  std::printf("  %-22s %8llu  %7.1f %7.1f %8.1f %8.1f", name, static_cast<unsigned long long>(t.periods),
              t.lateness_p50_ns / 1e3, t.lateness_p99_ns / 1e3, t.lateness_p999_ns / 1e3, t.lateness_max_ns / 1e3);
  if (with_compute)
    std::printf("   %6.2f %6.2f %7.2f %7.2f", t.compute_p50_ns / 1e3, t.compute_p99_ns / 1e3, t.compute_p999_ns / 1e3,
                t.compute_max_ns / 1e3);
  std::printf("\n");
}

struct Figures {
  haptics::TimingSummary bare, haptic;  // bare: its compute columns are the fixed work's
  haptics::TimingSummary control;       // the fixed work after each tick, in the haptic thread
  // Stalls (>= kStallNs) in ticks and in the fixed work after them, and the
  // computing time each was exposed over (count x median).
  std::uint64_t tick_stalls = 0, control_stalls = 0;
  double tick_exposure_s = 0.0, control_exposure_s = 0.0;
  std::string scheduling;
};

// A tick or fixed-work sample this long is a stall: an order of magnitude
// above either's median.
constexpr std::int64_t kStallNs = 40000;

void count_stalls(const haptics::HapticThread& thread, Figures& f) {
  f.tick_stalls = thread.compute().count_at_least(kStallNs);
  f.control_stalls = thread.control().count_at_least(kStallNs);
  f.tick_exposure_s = 1e-9 * static_cast<double>(thread.compute().count() * thread.compute().percentile_ns(0.5));
  f.control_exposure_s = 1e-9 * static_cast<double>(thread.control().count() * thread.control().percentile_ns(0.5));
}

// Iterations of the bare loop's fixed work that take about `target_ns` here
// (median of a short calibration run), so its tail can be read beside a
// tick's: what the machine alone adds to a few microseconds of computing.
int g_work_iterations = 0;
int calibrate_work_iterations(double target_ns) {
  int iterations = 1000;
  for (int round = 0; round < 3; ++round) {
    LatencyHistogram lateness(1000, 50000), work(50, 40000);
    haptics::run_bare_timer_loop(5000.0, 300, lateness, &work, iterations);
    const double median_ns = static_cast<double>(std::max<std::int64_t>(work.percentile_ns(0.5), 50));
    iterations = std::max(1, static_cast<int>(iterations * target_ns / median_ns));
  }
  return iterations;
}

Figures measure(double seconds, const config::RealtimeSpec& realtime) {
  Figures f;
  const config::HapticSpec haptic_spec;  // 1 kHz, defaults
  const auto periods = static_cast<std::uint64_t>(seconds * haptic_spec.rate_hz);

  // Bare timer loop on a thread with the same settings as the haptic thread.
  LatencyHistogram bare(1000, 50000), work(50, 40000);
  std::thread bare_thread([&] {
    haptics::configure_current_thread(realtime, realtime.haptic_priority);
    haptics::run_bare_timer_loop(haptic_spec.rate_hz, periods, bare, &work, g_work_iterations);
  });
  bare_thread.join();
  f.bare = haptics::summarize(bare, work, 0);

  // The haptic thread, fed by a 1 kHz model publisher and drained like the sim would.
  config::DeviceSpec device_spec;
  device_spec.sim.mode = config::SimDeviceSpec::Mode::kHand;
  device_spec.sim.waypoints = {{0.0, {0, 0, 0.005}},         {0.5, {0, 0, 0.005}}, {1.0, {0.01, 0, -0.004}},
                               {2.0, {-0.01, 0.01, -0.004}}, {2.5, {0, 0, 0.01}},  {3.0, {0, 0, 0.005}}};
  device_spec.sim.loop = true;
  haptics::SimDevice device(device_spec.sim);
  std::string error;
  if (!device.start(&error)) throw std::runtime_error(error);
  auto models = std::make_unique<haptics::LocalModelBuffer>();
  auto samples = std::make_unique<haptics::ToolSampleRing>();
  haptics::HapticLoop loop(device, device_spec, haptic_spec, *models, *samples);
  haptics::HapticThread thread(loop, haptic_spec, realtime);
  if (!thread.set_control_work(g_work_iterations)) throw std::logic_error("control work set after start");
  const haptics::LocalModel patch = make_patch();
  std::uint64_t contact_samples = 0;
  // A jthread: if thread.start() below throws, its destructor stops and
  // joins it (a joinable std::thread would terminate the process).
  std::jthread publisher([&](std::stop_token stop) {
    std::uint64_t version = 0;
    while (!stop.stop_requested()) {
      haptics::LocalModel& m = models->write_buffer();
      m = patch;
      m.version = ++version;
      m.built_ns = haptics::monotonic_now_ns();
      models->publish();
      samples->drain([&](const haptics::ToolSample& s) { contact_samples += s.contact; });
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
  });
  if (!thread.start(&error)) throw std::runtime_error(error);
  f.scheduling = thread.scheduling().summary();
  while (loop.heartbeat().load() < periods) std::this_thread::sleep_for(std::chrono::milliseconds(20));
  thread.request_stop();
  thread.join();
  publisher.request_stop();
  publisher.join();
  f.haptic = thread.timing();
  f.control = haptics::summarize(thread.lateness(), thread.control(), 0);
  count_stalls(thread, f);
  const haptics::HapticStats st = loop.stats();
  std::printf("  (haptic loop: %llu ticks, %llu model updates, %llu contact samples, ring drops %llu)\n",
              static_cast<unsigned long long>(st.ticks), static_cast<unsigned long long>(st.model_updates),
              static_cast<unsigned long long>(contact_samples), static_cast<unsigned long long>(st.ring_drops));
  return f;
}

// The daemon pipeline (service::SimThread + HapticLoop), as tissued --config runs it.
// With `record_dir` set, the session is recorded there (HDF5, 30 Hz mesh
// frames), as `tissued --record` does: the recording's cost to the haptic loop.
Figures measure_pipeline(double seconds, const config::RealtimeSpec& realtime, scene::Scene scene,
                         const std::string& record_dir = "") {
  Figures f;
  if (!scene.tool) scene.tool = scene::ToolSpec{};
  const config::HapticSpec haptic_spec;
  const auto periods = static_cast<std::uint64_t>(seconds * haptic_spec.rate_hz);
  service::SimThreadOptions sim_options;
  sim_options.priority = realtime.sched_fifo ? realtime.sim_priority : 0;

  {  // Bare loop with the sim thread stepping the same scene (no tool input).
    service::SimThread sim(std::make_unique<service::SimRunner>(scene), nullptr, nullptr, sim_options);
    sim.start();
    LatencyHistogram bare(1000, 50000), work(50, 40000);
    std::thread bare_thread([&] {
      haptics::configure_current_thread(realtime, realtime.haptic_priority);
      haptics::run_bare_timer_loop(haptic_spec.rate_hz, periods, bare, &work, g_work_iterations);
    });
    bare_thread.join();
    sim.stop();
    f.bare = haptics::summarize(bare, work, 0);
  }

  // The hand of config/tissued.yaml: down onto the top face near the free
  // end, 7 mm in, hold, release, up; looping.
  config::DeviceSpec device_spec;
  device_spec.sim.mode = config::SimDeviceSpec::Mode::kHand;
  device_spec.sim.loop = true;
  device_spec.sim.waypoints = {{0.0, {0.075, 0.05, 0.13}},  {1.0, {0.075, 0.05, 0.10}}, {2.0, {0.075, 0.05, 0.093}},
                               {4.0, {0.075, 0.05, 0.093}}, {4.5, {0.075, 0.05, 0.10}}, {5.5, {0.075, 0.05, 0.13}}};
  haptics::SimDevice device(device_spec.sim);
  std::string error;
  if (!device.start(&error)) throw std::runtime_error(error);
  auto models = std::make_unique<haptics::LocalModelBuffer>();
  auto samples = std::make_unique<haptics::ToolSampleRing>();
  // Before the sim thread: on a throw the sim thread stops before the
  // recorder it writes to goes, and the file is removed after it is closed.
  RemoveFileOnExit session_file;
  std::unique_ptr<record::Recorder> recorder;
  service::SimThread sim(std::make_unique<service::SimRunner>(scene), samples.get(), models.get(), sim_options);
  haptics::HapticLoop loop(device, device_spec, haptic_spec, *models, *samples);
  haptics::HapticThread thread(loop, haptic_spec, realtime);
  if (!thread.set_control_work(g_work_iterations)) throw std::logic_error("control work set after start");
  if (!record_dir.empty()) {
    record::SessionMetadata meta;
    meta.scene_name = scene.name;
    // One name per process: the recorder never overwrites, so a fixed name
    // left by an interrupted run, or taken by a concurrent one, failed here
    // after every earlier configuration had run.
    const std::string name = "haptic_bench_" + std::to_string(::getpid()) + ".h5";
    recorder = record::Recorder::start(record_dir, name, meta);
    session_file.path = recorder->path();
    sim.set_recorder(recorder.get());
  }
  sim.start();
  if (!thread.start(&error)) throw std::runtime_error(error);
  f.scheduling = thread.scheduling().summary();
  while (loop.heartbeat().load() < periods) std::this_thread::sleep_for(std::chrono::milliseconds(20));
  thread.request_stop();
  thread.join();
  const service::SimStatus status = sim.status();
  sim.set_recorder(nullptr);
  sim.stop();
  if (recorder) {
    recorder->stop();
    const record::RecorderStats r = recorder->stats();
    std::printf("  (recorded %llu haptic rows, %llu mesh frames, %.1f MB, drops %llu%s%s)\n",
                static_cast<unsigned long long>(r.haptic_rows_written),
                static_cast<unsigned long long>(r.mesh_frames_written), r.bytes_written / 1e6,
                static_cast<unsigned long long>(r.haptic_drops + r.sim_drops + r.mesh_frame_drops),
                recorder->error().empty() ? "" : "; error: ", recorder->error().c_str());
  }
  f.haptic = thread.timing();
  f.control = haptics::summarize(thread.lateness(), thread.control(), 0);
  count_stalls(thread, f);
  const haptics::HapticStats st = loop.stats();
  // The sim thread measures its real-time factor over whole seconds: a
  // shorter run has none ("-", not the unmeasured NaN).
  char rtf[32] = "-";
  if (status.real_time_factor_measured) std::snprintf(rtf, sizeof rtf, "%.2f", status.real_time_factor);
  std::printf("  (pipeline: %llu ticks, %llu model updates, %llu sim steps, rtf %s, %zu tets, ring drops %llu)\n",
              static_cast<unsigned long long>(st.ticks), static_cast<unsigned long long>(st.model_updates),
              static_cast<unsigned long long>(status.steps), rtf, status.tets,
              static_cast<unsigned long long>(st.ring_drops));
  return f;
}

}  // namespace

// Lateness p99 of `over` / of `under`, or n/a when `under` has none (no
// period, or a p99 of 0): a ratio of 0.00 read as well within the target.
std::string lateness_p99_ratio(const haptics::TimingSummary& over, const haptics::TimingSummary& under) {
  if (under.periods == 0 || under.lateness_p99_ns <= 0) return "n/a";
  char text[32];
  std::snprintf(text, sizeof text, "%.2f",
                static_cast<double>(over.lateness_p99_ns) / static_cast<double>(under.lateness_p99_ns));
  return text;
}

// A tick's tail beside the fixed work's, timed right after every tick in the
// same thread and period: p99.9 - p50 of each, and stalls (>= 40 us) per
// second of computing. Stalls at the same rate in both (the fixed work runs
// the same instructions every time) come from the machine, not the tick.
void print_tails(const Figures& f) {
  auto tail_us = [](const haptics::TimingSummary& t) { return (t.compute_p999_ns - t.compute_p50_ns) / 1e3; };
  auto rate = [](std::uint64_t n, double s) { return s > 0.0 ? static_cast<double>(n) / s : 0.0; };
  std::printf("  tail p99.9 - p50: tick %.2f us, fixed work after each tick %.2f us (bare loop %.2f us)\n",
              tail_us(f.haptic), tail_us(f.control), tail_us(f.bare));
  std::printf("  stalls >= 40 us: ticks %llu in %.3f s of computing (%.0f/s), fixed work %llu in %.3f s (%.0f/s)\n",
              static_cast<unsigned long long>(f.tick_stalls), f.tick_exposure_s, rate(f.tick_stalls, f.tick_exposure_s),
              static_cast<unsigned long long>(f.control_stalls), f.control_exposure_s,
              rate(f.control_stalls, f.control_exposure_s));
}

int run(double seconds, const std::string& scene_path, bool fifo) {
  config::RealtimeSpec realtime;
  realtime.sched_fifo = fifo;
  const scene::Scene scene = scene::load_scene_file(scene_path);

  g_work_iterations = calibrate_work_iterations(3000.0);
  std::printf("haptic_bench: %.1f s per configuration, 1 kHz; background scene %s\n", seconds, scene_path.c_str());
  std::printf("  bare loop rows: lateness, then the time of a fixed ~3 us workload per period (%d iterations)\n",
              g_work_iterations);
  std::printf("  %-22s %8s  %7s %7s %8s %8s   %6s %6s %7s %7s\n", "", "periods", "late50", "late99", "late99.9",
              "lateMax", "tick50", "tick99", "tick99.9", "tickMax");
  std::printf("  %-22s %8s  %7s %7s %8s %8s   %6s %6s %7s %7s\n", "", "", "us", "us", "us", "us", "us", "us", "us",
              "us");
  for (const bool loaded : {false, true}) {
    BackgroundSim background;
    if (loaded) background.start(scene);
    const auto t0 = std::chrono::steady_clock::now();
    const Figures f = measure(seconds, realtime);
    const double elapsed_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    background.join();
    std::printf("  [%s] %s\n", loaded ? "cantilever sim running" : "idle background", f.scheduling.c_str());
    print_row(loaded ? "bare loop + sim" : "bare loop", f.bare, true);
    print_row(loaded ? "haptic thread + sim" : "haptic thread", f.haptic, true);
    std::printf("  lateness p99 ratio haptic/bare = %s (target <= 1.5); tick p99.9 = %.2f us (target <= 20)\n",
                lateness_p99_ratio(f.haptic, f.bare).c_str(), f.haptic.compute_p999_ns / 1e3);
    print_tails(f);
    if (loaded)
      std::printf("  background sim: %llu steps in %.1f s%s%s\n",
                  static_cast<unsigned long long>(background.steps.load()), elapsed_s,
                  background.error.empty() ? "" : "; first error: ", background.error.c_str());
  }
  const std::string record_dir = std::filesystem::temp_directory_path().string();
  haptics::TimingSummary haptic_not_recording;
  for (const bool recording : {false, true}) {
    const Figures p = measure_pipeline(seconds, realtime, scene, recording ? record_dir : "");
    std::printf("  [daemon pipeline%s: sim thread + haptic thread on the real patch] %s\n",
                recording ? " + HDF5 recording" : "", p.scheduling.c_str());
    print_row("bare loop + sim thread", p.bare, true);
    print_row(recording ? "haptic thread, recording" : "haptic thread", p.haptic, true);
    std::printf("  lateness p99 ratio haptic/bare = %s (target <= 1.5); tick p99.9 = %.2f us (target <= 20)\n",
                lateness_p99_ratio(p.haptic, p.bare).c_str(), p.haptic.compute_p999_ns / 1e3);
    print_tails(p);
    // What the recording itself costs the haptic thread; the ratios above
    // are each against a bare loop, which says nothing of that.
    if (!recording)
      haptic_not_recording = p.haptic;
    else
      std::printf("  lateness p99 ratio haptic recording / not recording = %s (the two runs above, in turn)\n",
                  lateness_p99_ratio(p.haptic, haptic_not_recording).c_str());
  }
  return 0;
}

int main(int argc, char** argv) {
  CLI::App app{"haptic_bench: 1 kHz haptic thread lateness and tick cost vs a bare timer loop"};
  double seconds = 10.0;
  std::string scene_path = std::string(TISSUE_SOURCE_DIR) + "/config/scenes/cantilever.yaml";
  bool fifo = true;
  // At least 100 periods for a p99; at most a day, so that the period count
  // (seconds x 1 kHz) is a small integer.
  app.add_option("--seconds", seconds, "measurement time per configuration (0.1 to 86400)")
      ->check(CLI::Number)
      ->check(CLI::Range(0.1, 86400.0));
  app.add_option("--scene", scene_path, "scene the background simulation runs");
  app.add_flag("!--no-fifo", fifo, "do not try SCHED_FIFO");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // --help prints and succeeds; every other parse problem is a usage error.
    return app.exit(e) == 0 ? 0 : 2;
  }
  try {
    return run(seconds, scene_path, fifo);
  } catch (const std::exception& e) {
    // A bad --scene, a device or thread that did not start, a session file
    // that could not be created.
    std::fprintf(stderr, "haptic_bench: %s\n", e.what());
    return 1;
  }
}
