#include "tissue/session_command.hpp"

#include <CLI/CLI.hpp>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <iostream>
#include <memory>
#include <optional>
#include <string>
#include <thread>

#include "config/daemon_config.hpp"
#include "record/session_tools.hpp"
#include "replay/session_replay.hpp"
#include "tissue/cli_checks.hpp"
#include "tissue/dds_cli.hpp"
#include "transport/dds_publisher.hpp"
#include "transport/lcm_publisher.hpp"
#include "util/lcm_url.hpp"
#include "util/output_file.hpp"
#include "util/stop_signals.hpp"

namespace tissue::cli {

namespace {

constexpr int kExitBadFile = 1;  // same value as kExitDaemonError: "the thing you asked about is broken"
// How long `replay --lcm tcpq://…` waits for the server's greeting.
constexpr double kLcmServerWait_s = 10.0;

// `replay`: where to publish and how fast.
struct ReplayCommandOptions {
  std::optional<std::string> lcm_url;  // set: publish over LCM there
  DdsCliOptions dds;
  double dds_wait_s = 1.0;
  replay::ReplayOptions replay;
};

struct SessionOptions {
  std::string file;
  std::string dir = config::DaemonConfig{}.state_dir;  // `list`
  std::string xdmf_out;
  ReplayCommandOptions replay;
  CLI::App* list = nullptr;
  CLI::App* info = nullptr;
  CLI::App* repair = nullptr;
  CLI::App* xdmf = nullptr;
  CLI::App* replay_cmd = nullptr;
};

// --speed within replay::kMinSpeed..kMaxSpeed: 1e-300 waited for ever for
// the second item.
CLI::Validator replay_speed() {
  static_assert(replay::kMinSpeed == 1e-3 && replay::kMaxSpeed == 1e6, "the message below names the bounds");
  return CLI::Validator(
      [](std::string& v) -> std::string {
        double x = 0.0;
        if (std::string why = detail::whole_number(v, &x); !why.empty()) return why;
        if (x >= replay::kMinSpeed && x <= replay::kMaxSpeed) return {};
        return v + " is outside 0.001 to 1000000 (session seconds per wall second)";
      },
      "X in [0.001, 1e6]");
}

std::string fixed(double v, int digits) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*f", digits, v);
  return buf;
}

// The publishers, and a line on stdout where the replay reaches a hole the
// recorder left in /haptic: no haptic_state goes out over it, so a viewer
// sees the hand stop there though live it moved on; the person running the
// replay learns why (nothing on the wire can say "no data").
class AnnouncingSink final : public replay::ReplaySink {
 public:
  explicit AnnouncingSink(replay::PublisherSink& publishers) : publishers_(publishers) {}
  void mesh(const service::MeshSnapshot& snapshot) override { publishers_.mesh(snapshot); }
  void haptic(const service::SimStatus& status) override { publishers_.haptic(status); }
  void stats(const service::SimStatus& status) override { publishers_.stats(status); }
  void haptic_hole(const record::HapticHole& hole) override {
    std::cout << "hole: no haptic_state from t=" << fixed(hole.time_before_s, 3)
              << " s to t=" << fixed(hole.time_after_s, 3) << " s (" << fixed(hole.time_after_s - hole.time_before_s, 3)
              << " s of session time): the recorder dropped " << hole.ticks_lost
              << " haptic ticks there (its ring was full); live clients got them" << std::endl;
  }

 private:
  replay::PublisherSink& publishers_;
};

int run_replay(const std::string& file, const ReplayCommandOptions& o) {
  if (!o.lcm_url && !o.dds.enabled) {
    std::cerr << "tissue session replay: choose where to publish: --lcm [URL] and/or --dds\n";
    return kExitBadArguments;
  }
  // SIGINT / SIGTERM: the replay stops at its next wait (within 20 ms) and
  // prints its summary. Before the publishers, whose threads must start with
  // the signals blocked (util/stop_signals.hpp).
  const util::StopOnSignals stops;
  // The file first: a bad file is reported without touching the network.
  std::unique_ptr<x3d::FrameSource> frames;
  replay::SessionRows rows;
  try {
    frames = x3d::open_session_source(file);
    rows = replay::read_session_rows(file);
  } catch (const x3d::SourceError& e) {
    std::cerr << "tissue session replay: " << e.what() << "\n";
    return kExitBadFile;
  } catch (const replay::ReplayError& e) {
    std::cerr << "tissue session replay: " << e.what() << "\n";
    return kExitBadFile;
  }
  // An empty session is a property of the file, not of the options: exit 1
  // as for any other unusable file (an empty --from/--to window stays exit 2).
  if (frames->frame_count() == 0 && rows.haptic.empty() && rows.sim.empty()) {
    std::cerr << "tissue session replay: '" << file
              << "': nothing to replay: the session holds no mesh frame, haptic row or sim row\n";
    return kExitBadFile;
  }
  std::unique_ptr<transport::LcmPublisher> lcm;
  std::unique_ptr<transport::DdsPublisher> dds;
  try {
    if (o.lcm_url) {
      // LCM waits for a tcpq:// server's greeting without a time limit: a
      // port that accepts and says nothing hung the replay for ever. A stop
      // request ends the probe's wait at once (it waited the 10 s out).
      const util::TcpqProbe probe = util::probe_tcpq_server(*o.lcm_url, kLcmServerWait_s, &stops.flag());
      if (!probe.problem.empty()) throw std::runtime_error(probe.problem);
      if (probe.stopped) {
        std::cout << "stopped: " << file << ": by " << util::signal_name(stops.signal())
                  << " while waiting for the tcpq server at '" << *o.lcm_url << "' to answer; nothing was sent\n";
        return 0;  // stopped as asked, as a replay stopped later
      }
      lcm = std::make_unique<transport::LcmPublisher>(*o.lcm_url);
    }
    if (o.dds.enabled) dds = std::make_unique<transport::DdsPublisher>(o.dds.options());
  } catch (const std::runtime_error& e) {
    std::cerr << "tissue session replay: " << e.what() << "\n";
    return kExitCannotConnect;
  }
  if (dds) {
    // DDS readers match only after discovery (~0.1-1 s); frames sent before
    // are lost to them (the mesh topic keeps only the newest for late
    // joiners). Wait a little for a mesh reader; start anyway after that.
    const auto until = std::chrono::steady_clock::now() + std::chrono::duration<double>(o.dds_wait_s);
    while (dds->matched_readers().meshes == 0 && std::chrono::steady_clock::now() < until && !stops.stopped())
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  replay::PublisherSink publishers(lcm.get(), dds.get());
  AnnouncingSink sink(publishers);
  replay::SteadyReplayClock clock;
  replay::ReplaySummary sum;
  try {
    sum = replay::replay_session(*frames, rows, o.replay, sink, clock, stops.flag());
  } catch (const replay::ReplayError& e) {
    std::cerr << "tissue session replay: " << e.what() << "\n";
    return kExitBadArguments;  // only options (window, speed, rates) fail here
  } catch (const x3d::SourceError& e) {
    std::cerr << "tissue session replay: " << e.what() << "\n";
    return kExitBadFile;
  }
  std::cout << (sum.stopped ? "stopped: " : "replayed ") << file << ": " << sum.frames << " mesh frames, "
            << sum.haptic_rows << " haptic states, " << sum.stats << " stats";
  if (o.replay.loop) std::cout << ", " << sum.passes << " complete passes";
  std::cout << "\n  " << fixed(sum.session_span_s, 3) << " s of session time in " << fixed(sum.wall_s, 3)
            << " s wall: pace " << fixed(sum.pace(), 3) << "x (asked " << fixed(o.replay.speed, 3) << "x), "
            << sum.late_items << " items sent > 10 ms late (worst " << fixed(1e3 * sum.max_lag_s, 1) << " ms)\n";
  if (sum.haptic_holes > 0)
    std::cout << "  " << sum.haptic_holes << (sum.haptic_holes == 1 ? " recorder hole" : " recorder holes")
              << " crossed (" << fixed(sum.haptic_hole_time_s, 3)
              << " s without haptic rows): no haptic_state over them, the ticks the recorder dropped\n";
  if (lcm)
    std::cout << "  LCM " << lcm->url() << ": " << lcm->counts().meshes << " meshes, " << lcm->counts().haptic_states
              << " haptic states, " << lcm->counts().stats << " stats sent, " << lcm->counts().failures
              << " failures\n";
  if (dds) {
    std::cout << "  DDS domain " << o.dds.domain_id << " topics " << o.dds.topic_prefix << "*: " << dds->counts().meshes
              << " meshes, " << dds->counts().haptic_states << " haptic states, " << dds->counts().stats
              << " stats sent, " << dds->counts().failures << " failures";
    // The publisher does not send a mesh larger than max_mesh_bytes and
    // counts it as a failure: said when that is what happened.
    if (dds->counts().oversize_meshes > 0)
      std::cout << " (" << dds->counts().oversize_meshes << " of them meshes over --dds-max-mesh-bytes "
                << o.dds.max_mesh_bytes << " serialized, not sent)";
    std::cout << "\n";
  }
  return kExitOk;
}

void print_counts(const char* label, const record::GroupCounts& c) {
  std::cout << label << c.haptic_rows << " haptic ticks, " << c.sim_rows << " sim samples, " << c.mesh_frames
            << " mesh frames, " << c.events << " events\n";
}

int run_session(const SessionOptions& o) {
  try {
    if (o.list->parsed()) {
      std::cout << record::format_session_listing(record::list_sessions(o.dir));
      return kExitOk;
    }
    if (o.info->parsed()) {
      std::cout << record::format_session_info(record::read_session_info(o.file));
      return kExitOk;
    }
    if (o.repair->parsed()) {
      const record::RepairReport r = record::repair_session(o.file);
      for (const std::string& note : r.notes) std::cout << "note: " << note << "\n";
      if (r.repair_needed) {
        std::cout << "repaired " << o.file << ": ordinary HDF5 readers can open it now\n";
        print_counts("recovered: ", r.after.rows);
      } else {
        print_counts("contents: ", r.after.rows);
      }
      return kExitOk;
    }
    if (o.xdmf->parsed()) {
      const record::XdmfReport r = record::write_xdmf(o.file, o.xdmf_out);
      std::ostream& said = util::summary_stream(r.out_path);  // not into the XDMF (-o /dev/stdout)
      said << "wrote " << r.out_path << ": " << r.frames << " mesh frames";
      if (r.skipped_empty > 0) said << " (" << r.skipped_empty << " empty frames skipped)";
      said << "\n";
      return kExitOk;
    }
    if (o.replay_cmd->parsed()) return run_replay(o.file, o.replay);
  } catch (const record::RecordError& e) {
    std::cerr << "tissue session: " << e.what() << "\n";
    return kExitBadFile;
  }
  return kExitBadArguments;
}

void add_replay_command(CLI::App* session, SessionOptions& options) {
  ReplayCommandOptions& r = options.replay;
  const config::PublishSpec defaults;
  r.replay.timeline.haptic_rate_hz = defaults.haptic_rate_hz;
  r.replay.timeline.stats_rate_hz = defaults.stats_rate_hz;
  CLI::App* cmd = options.replay_cmd = session->add_subcommand(
      "replay", "Publish a recorded session over LCM and/or Fast DDS at the recorded pace, as tissued would");
  // Not ->required(): `--lcm FILE` may have taken it (below).
  cmd->add_option("file", options.file, "Session file (.h5)");
  cmd->add_option("--lcm", r.lcm_url, "Publish over LCM at URL (publish.lcm.url)")
      // As the daemon's config checks publish.lcm.url; a word without "://"
      // is FILE (below).
      ->check(lcm_url(false))
      ->expected(0, 1)
      ->default_str(defaults.lcm.url);
  // --lcm's URL is optional, so CLI11 takes whatever word follows it: in
  // `--lcm stroke.h5` the session file, which left no FILE ("file is
  // required"). An LCM URL is PROVIDER://...; anything else there is FILE,
  // published on the default URL (docs/replay-and-live.md). `--lcm ''` is
  // the default URL too, as in x3d and render: to LCM an empty URL is its own
  // default or $LCM_DEFAULT_URL, not the documented publish.lcm.url.
  cmd->parse_complete_callback([&options, url = defaults.lcm.url] {
    std::optional<std::string>& lcm = options.replay.lcm_url;
    if (lcm && lcm->empty()) lcm = url;
    if (lcm && !lcm->empty() && lcm->find("://") == std::string::npos) {
      if (!options.file.empty())
        throw CLI::ValidationError("--lcm", "'" + *lcm + "' is not an LCM URL (PROVIDER://...)");
      options.file = *lcm;
      lcm = url;
    }
    if (options.file.empty()) throw CLI::RequiredError("file");
  });
  CLI::Option* dds = add_dds_options(cmd, r.dds, "Publish over Fast DDS (topics <prefix>surface_mesh, ...)");
  cmd->add_option("--dds-wait", r.dds_wait_s, "Wait up to S seconds for a DDS mesh reader before starting")
      ->check(finite_number())  // CLI::Range lets NaN through (every comparison with it is false)
      ->check(CLI::Range(0.0, 3600.0))
      ->capture_default_str()
      ->needs(dds);
  cmd->add_option("--speed", r.replay.speed, "Session seconds per wall second (2: twice as fast), 0.001 to 1e6")
      ->check(finite_positive())
      ->check(replay_speed())
      ->capture_default_str();
  cmd->add_option("--from", r.replay.timeline.from_s, "Start at this session time (s)")->check(finite_number());
  cmd->add_option("--to", r.replay.timeline.to_s, "End at this session time (s)")->check(finite_number());
  cmd->add_flag("--loop", r.replay.loop, "Start over after the end, until Ctrl-C");
  cmd->add_option("--haptic-rate", r.replay.timeline.haptic_rate_hz,
                  "haptic_state rate in Hz (publish.haptic_rate_hz); 0: every recorded tick")
      ->check(finite_number())
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cmd->add_option("--stats-rate", r.replay.timeline.stats_rate_hz,
                  "sim_stats rate in Hz (publish.stats_rate_hz); 0: every recorded sample")
      ->check(finite_number())
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cmd->footer(
      "Same channels / topics and encoders as tissued (proto/README.md); message time_s is session time.\n"
      "Ctrl-C or SIGTERM stops cleanly and prints the summary.\n"
      "Exit codes: 0 ok (also when stopped), 1 the file is unreadable / corrupt / not a session,\n"
      "2 bad arguments, 3 LCM or DDS cannot start.");
}

}  // namespace

Subcommand add_session_command(CLI::App& parent) {
  auto options = std::make_shared<SessionOptions>();
  CLI::App* session =
      parent.add_subcommand("session", "Inspect, repair, export and replay recorded session files (HDF5)");
  session->require_subcommand(1);
  options->list = session->add_subcommand(
      "list",
      "The sessions in a state directory: state (closed cleanly, OPEN: recording or crashed, repaired, NOT closed "
      "cleanly, NOT closed (crash tail): `tissue session repair` trims it), start, duration, rows, recorder holes in "
      "/haptic (count, session time spanned), scene");
  options->list->add_option("dir", options->dir, "Directory (default: tissued's default state_dir)")
      ->capture_default_str();
  options->list->footer(
      "Unreadable session files and unfinished creations are listed after the sessions, with the reason.\n"
      "Exit codes: 0 listed, 1 the directory cannot be read, 2 bad arguments.");
  options->info = session->add_subcommand(
      "info", "Duration, row counts, scene, host, version, clean close or crash, recorder holes in /haptic");
  options->info->add_option("file", options->file, "Session file (.h5)")->required();
  options->repair = session->add_subcommand(
      "repair",
      "Make a session left by a crash readable by ordinary HDF5 readers (h5clear -s --increment, in-library)");
  options->repair->add_option("file", options->file, "Session file (.h5)")->required();
  options->xdmf =
      session->add_subcommand("xdmf", "Write an XDMF sidecar so ParaView opens the mesh frames as a time series");
  options->xdmf->add_option("file", options->file, "Session file (.h5)")->required();
  options->xdmf->add_option("-o,--output", options->xdmf_out, "Sidecar path (default: FILE with .xdmf)");
  add_replay_command(session, *options);
  return Subcommand{session, [options] { return run_session(*options); }};
}

}  // namespace tissue::cli
