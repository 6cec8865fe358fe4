#include "tissue/dds_cli.hpp"
#include "tissue/cli_checks.hpp"

#include <CLI/CLI.hpp>

namespace tissue::cli {

transport::DdsOptions DdsCliOptions::options() const {
  transport::DdsOptions d;
  d.domain_id = domain_id;
  d.topic_prefix = topic_prefix;
  d.loopback_only = !remote;
  d.max_mesh_bytes = max_mesh_bytes;
  return d;
}

CLI::Option* add_dds_options(CLI::App* cmd, DdsCliOptions& o, const std::string& dds_help) {
  CLI::Option* dds = cmd->add_flag("--dds", o.enabled, dds_help);
  cmd->add_option("--dds-domain", o.domain_id, "DDS domain (publish.dds.domain_id)")
      ->transform(decimal_integer())
      ->check(CLI::Range(0, 232))
      ->capture_default_str()
      ->needs(dds);
  cmd->add_option("--dds-prefix", o.topic_prefix, "DDS topic prefix (publish.dds.topic_prefix)")
      ->capture_default_str()
      ->needs(dds);
  // The range of publish.dds.max_mesh_bytes (docs/daemon-config.md).
  cmd->add_option("--dds-max-mesh-bytes", o.max_mesh_bytes,
                  "Largest serialized mesh sent or expected, bytes, 65536 to 1073741824 (publish.dds.max_mesh_bytes)")
      ->transform(decimal_integer())
      ->check(CLI::Range(std::size_t{64} << 10, std::size_t{1} << 30))
      ->capture_default_str()
      ->needs(dds);
  cmd->add_flag("--dds-remote", o.remote,
                "DDS on every interface (publish.dds.loopback_only: false); default: this host only")
      ->needs(dds);
  return dds;
}

}  // namespace tissue::cli
