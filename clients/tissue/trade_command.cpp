#include "tissue/trade_command.hpp"

#include <CLI/CLI.hpp>

#include "app/trade_study.hpp"

namespace tissue::cli {

Subcommand add_trade_command(CLI::App& parent) {
  CLI::App* cmd = parent.add_subcommand(
      "trade", "Measure the speed/accuracy trade: Table 1, a cost-vs-error sweep (CSV, SVG), beam theory");
  // The study parses its own options (one parser for `tissue trade` and
  // trade_bench), so every word after `trade`, --help included, goes to it.
  cmd->prefix_command();
  cmd->set_help_flag();
  return Subcommand{cmd, [cmd] { return app::run_trade_study("tissue trade", cmd->remaining()); }};
}

}  // namespace tissue::cli
