// The DDS options every client that talks DDS takes (`--dds`, `--dds-domain`,
// `--dds-prefix`, `--dds-remote`, `--dds-max-mesh-bytes`), named, defaulted
// and bounded like the daemon's publish.dds.* keys, and their conversion to
// transport options.
#pragma once

#include <cstddef>
#include <string>

#include "config/daemon_config.hpp"
#include "transport/dds_options.hpp"

namespace CLI {
class App;
class Option;
}  // namespace CLI

namespace tissue::cli {

struct DdsCliOptions {
  bool enabled = false;  // --dds given
  int domain_id = config::DdsPublishSpec{}.domain_id;
  std::string topic_prefix = config::DdsPublishSpec{}.topic_prefix;
  bool remote = false;  // --dds-remote: every interface, not this host only
  // --dds-max-mesh-bytes: a publisher does not send larger serialized meshes
  // (counted as failures); a subscriber sizes its receive buffer from it.
  std::size_t max_mesh_bytes = config::DdsPublishSpec{}.max_mesh_bytes;

  // For a publisher (session replay) or a subscriber (live sources) alike.
  transport::DdsOptions options() const;
};

// Adds --dds (described by `dds_help`) and the options that need it; returns
// the --dds option (for excludes/needs).
CLI::Option* add_dds_options(CLI::App* cmd, DdsCliOptions& o, const std::string& dds_help);

}  // namespace tissue::cli
