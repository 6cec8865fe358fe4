// The daemon's settings file (config/tissued.yaml, documented key by key in
// docs/daemon-config.md): YAML text -> a validated DaemonConfig.
//
// Same rules as scene files (scene/scene_yaml.hpp), same machinery: unknown
// keys, wrong types and out-of-range values are a ConfigError naming the
// file, the key path and the reason,
//
//   /etc/tissued/tissued.yaml: haptics.rate_hz: must be > 0 (got -5)
//
// and `--set key.path=value` overrides are applied to the YAML tree before
// conversion, so they are checked exactly like the file.
#pragma once

#include "scene/yaml_util.hpp"

#include <memory>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "config/daemon_config.hpp"

namespace tissue::config {

class ConfigError : public yaml_util::DocumentError {
 public:
  ConfigError(const std::string& source, const std::string& key_path, const std::string& reason)
      : DocumentError(source, key_path, reason, "<daemon config>") {}
};

// Reads, parses and validates a daemon config file. DaemonConfig::source is
// `path`; a relative `scene` (and `state_dir`) is resolved against the
// directory of `path`.
DaemonConfig load_daemon_config(const std::string& path, const std::vector<std::string>& overrides = {});

// Parses config text. `source` names it in messages and is stored in
// DaemonConfig::source; relative paths resolve against source's directory
// (the current directory when `source` has none).
DaemonConfig parse_daemon_config(const std::string& yaml_text, const std::string& source,
                                 const std::vector<std::string>& overrides = {});

// The checks the loaders run, for a DaemonConfig however it was built (e.g.
// after the service changed a field at run time). Throws ConfigError with
// source = c.source and YAML key paths.
void validate_daemon_config(const DaemonConfig& c);

// True when `key_path` ("haptics.rate_hz", "device.sim.waypoints[0].time_s")
// starts with a top-level key of the daemon config; scene keys
// ("material.youngs_modulus_Pa") never do. Spaces and tabs around it are
// ignored, as in an override ("scene =x.yaml"). Lets a `set` command and the
// service's --set decide which document a key belongs to.
bool is_daemon_config_key(std::string_view key_path);

}  // namespace tissue::config
