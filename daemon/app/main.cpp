// tissued — the daemon's entry point: parses the command line and dispatches
// to a mode. Modes live in their own files (batch_run.cpp); this file stays
// thin. Exit codes: as the --help footer below says (batch_run.hpp has the
// batch mode's, service/service.hpp the service's).
#include <CLI/CLI.hpp>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <exception>
#include <string>

#include "app/batch_run.hpp"
#include "record/session_tools.hpp"
#include "service/service.hpp"
#include "util/text.hpp"

namespace {

std::string seconds_text(double s) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.15g", s);
  return buf;
}

// A finite number of seconds >= 0 (CLI::NonNegativeNumber lets "inf" through
// and prints DBL_MAX in full when it fails), at most kMaxSessionTime_s (31
// years; a session holds no later time): the service's --duration timer
// converts it to nanoseconds, which 1e10 s overflowed (UB; it stopped at once).
const CLI::Validator kDurationSeconds(
    [](std::string& text) -> std::string {
      const std::optional<double> value = tissue::util::whole_number(text);
      if (!value || !std::isfinite(*value) || *value < 0.0 || *value > tissue::record::kMaxSessionTime_s)
        return "must be a finite number of seconds in [0, " + seconds_text(tissue::record::kMaxSessionTime_s) +
               "] (got " + text + ")";
      return {};
    },
    "SECONDS>=0");

// 0 (quiet) or an interval of at least kMinProgress_s (up to
// kMaxSessionTime_s): the run counts its lines as sim time / interval in a
// long long, which --progress 1e-20 overflowed (UB), and a line per step
// is not progress.
constexpr double kMinProgress_s = 1e-3;
const CLI::Validator kProgressSeconds(
    [](std::string& text) -> std::string {
      const std::optional<double> value = tissue::util::whole_number(text);
      if (!value || !std::isfinite(*value) || (*value != 0.0 && *value < kMinProgress_s) ||
          *value > tissue::record::kMaxSessionTime_s || *value < 0.0)
        return "must be 0 (quiet) or a number of seconds in [" + seconds_text(kMinProgress_s) + ", " +
               seconds_text(tissue::record::kMaxSessionTime_s) + "] (got " + text + ")";
      return {};
    },
    "SECONDS");

// A finite number of seconds > 0 (an interval: 0 would record every step
// at once, and is refused).
const CLI::Validator kPositiveSeconds(
    [](std::string& text) -> std::string {
      const std::optional<double> value = tissue::util::whole_number(text);
      if (!value || !std::isfinite(*value) || *value <= 0.0)
        return "must be a finite number of seconds > 0 (got " + text + ")";
      return {};
    },
    "SECONDS>0");

}  // namespace

int main(int argc, char** argv) {
  // Under a file-size limit (ulimit -f, systemd's LimitFSIZE=) a write past
  // it must fail with EFBIG, which the session writers report and survive,
  // not kill the daemon (SIGXFSZ's default action) and lose the session.
  std::signal(SIGXFSZ, SIG_IGN);
  // Output to a pipe whose reader went away (`tissued ... | tee log` and tee
  // ended) must fail that write with EPIPE, not kill the daemon or the batch
  // run (SIGPIPE's default action) before its session is closed. systemd
  // ignores SIGPIPE for its services anyway (IgnoreSIGPIPE=yes).
  std::signal(SIGPIPE, SIG_IGN);
  try {
    CLI::App app{"tissued: real-time haptic server for adaptive soft-tissue simulation"};
    app.footer(
        "Exit codes: 0 success, 1 internal error, 2 bad command line, scene or config, 3 --batch: a step failed; "
        "--config: the service could not start (device, control socket, threads, --record), 4 report not writable, "
        "5 session file (--batch --record) not writable, 128 + N --batch stopped by signal N "
        "(SIGINT, SIGTERM; the report and session cover the run so far).");
    bool batch = false;
    tissue::app::BatchOptions batch_options;
    std::string config_path;
    app.add_option("--config", config_path,
                   "run the service (threads, device, control socket) with this daemon config "
                   "(YAML, see docs/daemon-config.md)");
    app.add_flag("--batch", batch, "run a scene for --duration simulated seconds as fast as possible, then exit");
    CLI::Option* scene = app.add_option("--scene", batch_options.scene_path,
                                        "--batch: scene file (YAML, see docs/scene-format.md); the service serves "
                                        "its config's `scene:` (--set scene=FILE)");
    CLI::Option* duration =
        app.add_option("--duration", batch_options.duration_s,
                       "--batch: simulated seconds to run; --config: stop the service after this many wall seconds")
            ->check(kDurationSeconds);
    app.add_option("--set", batch_options.overrides,
                   "override a scene value (or, with --config, a daemon value): key.path=value (repeatable)");
    CLI::Option* report =
        app.add_option("--report", batch_options.report_path, "--batch: write the JSON report to this file");
    std::string record_name;
    CLI::Option* record = app.add_option(
        "--record", record_name,
        "--config: record the session from the start to this file name in the config's state_dir; "
        "--batch: record the run to this file (path); never overwrites (HDF5, see docs/session-format.md)");
    CLI::Option* record_interval =
        app.add_option("--record-interval", batch_options.record_frame_interval_s,
                       "--batch --record: simulated seconds between recorded surface frames (default 1/30)")
            ->check(kPositiveSeconds);
    bool no_timing = false;
    CLI::Option* timing = app.add_flag("--no-timing", no_timing,
                                       "--batch: leave wall-clock timing out of the report (bit-identical reruns)");
    CLI::Option* progress = app.add_option("--progress", batch_options.progress_every_s,
                                           "--batch: simulated seconds between live lines on stdout (0: quiet)")
                                ->check(kProgressSeconds)
                                ->capture_default_str();

    try {
      app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
      if (e.get_exit_code() == 0) return app.exit(e);  // --help
      std::fprintf(stderr, "tissued: %s (see --help)\n", e.what());
      return tissue::app::kExitUsage;
    }

    // An empty name (an unset shell variable) would record or report
    // nothing and say nothing.
    for (const CLI::Option* named : {report, record})
      if (named->count() > 0 && named->as<std::string>().empty()) {
        std::fprintf(stderr, "tissued: %s needs a file name (got an empty one; see --help)\n",
                     named->get_name().c_str());
        return tissue::app::kExitUsage;
      }
    if (batch && !config_path.empty()) {
      std::fprintf(stderr, "tissued: --batch and --config are two different modes; give one (see --help)\n");
      return tissue::app::kExitUsage;
    }
    if (!config_path.empty()) {
      // Batch-only options are refused, not ignored: `--config ... --scene B`
      // served the config's scene and said nothing. (The service records its
      // frames at the recorder's own rate, 30 Hz of wall time.)
      for (const CLI::Option* only_batch : {scene, report, timing, progress, record_interval})
        if (only_batch->count() > 0) {
          std::fprintf(stderr, "tissued: %s is for --batch%s (see --help)\n", only_batch->get_name().c_str(),
                       only_batch == scene             ? "; the service serves its config's scene: --set scene=FILE"
                       : only_batch == record_interval ? " --record"
                                                       : "");
          return tissue::app::kExitUsage;
        }
      if (duration->count() > 0 && !(batch_options.duration_s > 0.0)) {
        // 0 would mean "no limit" to the service: a user who typed it meant "stop at once" or a typo.
        std::fprintf(stderr,
                     "tissued: --duration with --config must be > 0 wall seconds (omit it to serve until "
                     "stopped)\n");
        return tissue::app::kExitUsage;
      }
      tissue::service::ServiceOptions options;
      options.config_path = config_path;
      options.overrides = batch_options.overrides;
      options.duration_s = batch_options.duration_s;
      options.record_name = record_name;
      tissue::service::Service service(options);
      return service.run();
    }
    if (!batch) {
      std::fprintf(stderr,
                   "usage: tissued --config FILE [--duration SECONDS] [--set key=value ...]   (the service)\n"
                   "       tissued --batch --scene FILE --duration SECONDS [options]          (a batch run)\n"
                   "see --help\n");
      return tissue::app::kExitUsage;
    }
    if (batch_options.scene_path.empty() || duration->count() == 0) {
      std::fprintf(stderr, "tissued: --batch needs --scene FILE and --duration SECONDS (see --help)\n");
      return tissue::app::kExitUsage;
    }
    batch_options.timing = !no_timing;
    batch_options.record_path = record_name;
    if (record_interval->count() > 0 && (record_name.empty() || !(batch_options.record_frame_interval_s > 0.0))) {
      std::fprintf(stderr, "tissued: --record-interval needs --record FILE and a number of seconds > 0 (see --help)\n");
      return tissue::app::kExitUsage;
    }
    return tissue::app::batch_command(batch_options);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "tissued: internal error: %s\n", e.what());
    return tissue::app::kExitInternal;
  } catch (...) {
    std::fprintf(stderr, "tissued: internal error: unknown exception\n");
    return tissue::app::kExitInternal;
  }
}
