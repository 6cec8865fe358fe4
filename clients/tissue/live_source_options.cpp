#include "tissue/live_source_options.hpp"

#include <CLI/CLI.hpp>

#include "export/live_source.hpp"
#include "tissue/cli_checks.hpp"
#include "transport/dds_subscriber.hpp"
#include "transport/lcm_subscriber.hpp"
#include "util/lcm_url.hpp"
#include "util/stop_signals.hpp"
#include "util/text.hpp"

namespace tissue::cli {

namespace {
// Live frames are held in memory until the window ends (and stop at
// x3d::kLiveFrameBudgetBytes); an hour is more than any export of them
// needs, and longer takes are what recording a session is for.
constexpr double kMaxLiveSeconds = 3600.0;

CLI::Validator at_most_an_hour() {
  return CLI::Validator(
      [](std::string& v) -> std::string {
        double x = 0.0;
        if (std::string why = detail::whole_number(v, &x); !why.empty()) return why;
        if (x <= kMaxLiveSeconds) return {};
        return v + " is more than 3600: live frames are held in memory; record a session for longer takes";
      },
      "S <= 3600");
}
}  // namespace

void add_live_source_options(CLI::App* cmd, LiveSourceOptions& o, CLI::Option* session, CLI::Option* many) {
  o.lcm_option = cmd->add_option("--lcm", o.lcm_url,
                                 "Live frames from LCM (channel TISSUE_SURFACE_MESH) at URL instead of a session")
                     ->expected(0, 1)
                     ->default_str(transport::kLcmSubscribeUrl)
                     ->check(lcm_url());
  o.dds_option = add_dds_options(cmd, o.dds, "Live frames from Fast DDS (topic <prefix>surface_mesh)");
  CLI::Option* seconds =
      cmd->add_option("--seconds", o.seconds,
                      "Live: collect frames for S seconds (wall, at most 3600) after the first one, or until they "
                      "hold 1 GiB")
          ->check(finite_positive())
          ->check(at_most_an_hour())
          ->capture_default_str();
  if (many) seconds->needs(many);
  CLI::Option* timeout = cmd->add_option("--timeout", o.timeout_s, "Live: wait at most S seconds for the first frame")
                             ->check(finite_positive())
                             ->capture_default_str();
  session->excludes(o.lcm_option)->excludes(o.dds_option);
  o.lcm_option->excludes(o.dds_option);
  // Live options without a live source would be silently ignored.
  seconds->excludes(session);
  timeout->excludes(session);
}

std::unique_ptr<x3d::FrameSource> open_live_source(const LiveSourceOptions& o, bool many, std::string* stop_note) {
  // Ctrl-C during a take of up to an hour ends the take, not the process:
  // the frames so far are exported (the signal killed the client and lost
  // them). Made before the subscriber so its transport's threads start with
  // the signals blocked (util/stop_signals.hpp); only while collecting: a signal
  // during the export ends it as usual.
  const util::StopOnSignals stops;
  const auto stopped_by = [&] { return std::string("stopped by ") + util::signal_name(stops.signal()); };
  std::unique_ptr<transport::MeshSubscriber> sub;
  std::string stopped_before_open;  // the source a stop during the tcpq probe left unopened
  try {
    if (o.lcm_url) {
      // `--lcm ''` reaches here unchecked (CLI11 validates no empty value):
      // it means the default, said by name in every message.
      const std::string url = o.lcm_url->empty() ? std::string(transport::kLcmSubscribeUrl) : *o.lcm_url;
      // LCM waits for a tcpq server's greeting without a time limit. The
      // probe waits at most --timeout for each of connection and greeting,
      // and a stop request ends it at once (--timeout 600 waited up to 20
      // minutes before it saw a Ctrl-C).
      const util::TcpqProbe probe = util::probe_tcpq_server(url, o.timeout_s, &stops.flag());
      if (!probe.problem.empty()) throw LiveStartError(probe.problem);
      if (probe.stopped)
        stopped_before_open = transport::LcmMeshSubscriber::name_for(url);
      else
        sub = std::make_unique<transport::LcmMeshSubscriber>(url);
    } else {
      sub = std::make_unique<transport::DdsMeshSubscriber>(o.dds.options());
    }
  } catch (const std::runtime_error& e) {
    throw LiveStartError(e.what());
  }
  // Outside the try: a NoLiveFrameError is a std::runtime_error too.
  if (!stopped_before_open.empty())
    throw x3d::NoLiveFrameError(stopped_by() + " before any surface_mesh arrived on " + stopped_before_open);
  x3d::LiveCollectOptions c;
  c.first_timeout_s = o.timeout_s;
  c.window_s = many ? o.seconds : 0.0;
  c.max_frames = many ? 0 : 1;
  auto source = std::make_unique<x3d::LiveFrameSource>(*sub, c, &stops.flag());
  stop_note->clear();
  // Whether the stop ended the collection, not whether a signal came by now:
  // one that lands after the window ended on its own changes nothing (it
  // said "cut short" of a complete take).
  if (source->stopped_by_request()) {
    if (source->frame_count() == 0)
      throw x3d::NoLiveFrameError(stopped_by() + " before any surface_mesh arrived on " + source->name());
    // One frame is no animation (x3d_command.cpp would blame a paused
    // simulation: "its 1 frames are all at t=..."): a stop before enough
    // frames, exit 4 as a stop before the first.
    if (many && source->frame_count() < o.frames_needed)
      throw x3d::NoLiveFrameError(stopped_by() + " after " + std::to_string(source->frame_count()) + " frame" +
                                  (source->frame_count() == 1 ? "" : "s") + " on " + source->name() +
                                  ": an animation needs " + std::to_string(o.frames_needed));
    if (many)
      *stop_note = std::string("the collection was cut short by ") + util::signal_name(stops.signal()) + " after " +
                   std::to_string(source->frame_count()) + " frames of the " + util::number_text(o.seconds) +
                   " s window";
  }
  return source;
}

}  // namespace tissue::cli
