#include "tissue/live_source_options.hpp"

#include <CLI/CLI.hpp>

#include "config/daemon_config.hpp"
#include "export/live_source.hpp"
#include "transport/dds_subscriber.hpp"
#include "transport/lcm_subscriber.hpp"

namespace tissue::cli {

void add_live_source_options(CLI::App* cmd, LiveSourceOptions& o, CLI::Option* session, CLI::Option* many) {
  const config::DdsPublishSpec dds_defaults;
  o.dds_domain = dds_defaults.domain_id;
  o.dds_prefix = dds_defaults.topic_prefix;
  o.lcm_option = cmd->add_option("--lcm", o.lcm_url,
                                 "Live frames from LCM (channel TISSUE_SURFACE_MESH) at URL instead of a session")
                     ->expected(0, 1)
                     ->default_str(transport::kLcmSubscribeUrl);
  o.dds_option = cmd->add_flag("--dds", o.dds, "Live frames from Fast DDS (topic <prefix>surface_mesh)");
  cmd->add_option("--dds-domain", o.dds_domain, "DDS domain (as publish.dds.domain_id)")
      ->check(CLI::Range(0, 232))
      ->capture_default_str()
      ->needs(o.dds_option);
  cmd->add_option("--dds-prefix", o.dds_prefix, "DDS topic prefix (as publish.dds.topic_prefix)")
      ->capture_default_str()
      ->needs(o.dds_option);
  cmd->add_flag("--dds-remote", o.dds_remote, "DDS on every interface (a publisher on another host)")
      ->needs(o.dds_option);
  CLI::Option* seconds =
      cmd->add_option("--seconds", o.seconds, "Live: collect frames for S seconds (wall) after the first one")
          ->check(CLI::PositiveNumber)
          ->capture_default_str();
  if (many) seconds->needs(many);
  CLI::Option* timeout = cmd->add_option("--timeout", o.timeout_s, "Live: wait at most S seconds for the first frame")
                             ->check(CLI::PositiveNumber)
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
      sub = std::make_unique<transport::LcmMeshSubscriber>(*o.lcm_url);
    } else {
      transport::DdsSubscribeOptions d;
      d.domain_id = o.dds_domain;
      d.topic_prefix = o.dds_prefix;
      d.loopback_only = !o.dds_remote;
      sub = std::make_unique<transport::DdsMeshSubscriber>(d);
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
