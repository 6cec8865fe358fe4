// `tissue ctl`: send one control command to a running tissued and print the
// result (docs/control-protocol.md).
#pragma once

#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "tissue/subcommand.hpp"

namespace tissue::cli {

Subcommand add_ctl_command(CLI::App& parent);

// The request for `tissue ctl <cmd> [words...]`, or throws
// std::invalid_argument saying what is wrong. Words: `load_scene PATH`
// (PATH made absolute against the current directory), `set KEY VALUE` or
// `set KEY=VALUE`, otherwise key=value pairs. Values are JSON when they
// parse as JSON (8e4, true, [0,0,-1], "text"), plain strings otherwise.
nlohmann::json build_ctl_request(const std::string& cmd, const std::vector<std::string>& words);

}  // namespace tissue::cli
