// `tissue trade [options]`: the speed/accuracy trade study on the shipped
// scenes or a scene file of your own (app/trade_study.hpp; `tissue trade
// --help` lists the options). Runs the simulation in-process; no daemon.
// Exit codes: 0 ok, 2 bad arguments or a scene that cannot be run.
#pragma once

#include "tissue/subcommand.hpp"

namespace tissue::cli {

Subcommand add_trade_command(CLI::App& parent);

}  // namespace tissue::cli
