#include "tissue/live_source_options.hpp"

#include <CLI/CLI.hpp>

#include "export/live_source.hpp"
#include "tissue/cli_checks.hpp"
#include "transport/dds_subscriber.hpp"
#include "transport/lcm_subscriber.hpp"
#include "util/lcm_url.hpp"

namespace tissue::cli {

void add_live_source_options(CLI::App* cmd, LiveSourceOptions& o, CLI::Option* session, CLI::Option* many) {
  o.lcm_option = cmd->add_option("--lcm", o.lcm_url,
                                 "Live frames from LCM (channel TISSUE_SURFACE_MESH) at URL instead of a session")
                     ->expected(0, 1)
                     ->default_str(transport::kLcmSubscribeUrl)
                     ->check(lcm_url());
  o.dds_option = add_dds_options(cmd, o.dds, "Live frames from Fast DDS (topic <prefix>surface_mesh)");
  CLI::Option* seconds =
      cmd->add_option("--seconds", o.seconds, "Live: collect frames for S seconds (wall) after the first one")
          ->check(finite_positive())
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

std::unique_ptr<x3d::FrameSource> open_live_source(const LiveSourceOptions& o, bool many) {
  std::unique_ptr<transport::MeshSubscriber> sub;
  try {
    if (o.lcm_url) {
      // `--lcm ''` reaches here unchecked (CLI11 validates no empty value):
      // it means the default, said by name in every message.
      const std::string url = o.lcm_url->empty() ? std::string(transport::kLcmSubscribeUrl) : *o.lcm_url;
      // LCM waits for a tcpq server's greeting without a time limit.
      if (const std::string why = util::tcpq_server_problem(url, o.timeout_s); !why.empty()) throw LiveStartError(why);
      sub = std::make_unique<transport::LcmMeshSubscriber>(url);
    } else {
      sub = std::make_unique<transport::DdsMeshSubscriber>(o.dds.options());
    }
  } catch (const std::runtime_error& e) {
    throw LiveStartError(e.what());
  }
  x3d::LiveCollectOptions c;
  c.first_timeout_s = o.timeout_s;
  c.window_s = many ? o.seconds : 0.0;
  c.max_frames = many ? 0 : 1;
  return std::make_unique<x3d::LiveFrameSource>(*sub, c);
}

}  // namespace tissue::cli
