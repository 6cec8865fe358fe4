// `tissue`: the command-line client of tissued. One executable, one
// subcommand per file (tissue/ctl_command.cpp, ...); see subcommand.hpp.
#include <CLI/CLI.hpp>

#include <exception>
#include <iostream>
#include <vector>

#include "tissue/ctl_command.hpp"
#include "tissue/render_command.hpp"
#include "tissue/session_command.hpp"
#include "tissue/subcommand.hpp"
#include "tissue/trade_command.hpp"
#include "tissue/x3d_command.hpp"

int main(int argc, char** argv) {
  using namespace tissue::cli;
  CLI::App app{"tissue: command-line client of the tissued haptic server"};
  app.require_subcommand(1);
  std::vector<Subcommand> subcommands;
  subcommands.push_back(add_ctl_command(app));
  subcommands.push_back(add_session_command(app));
  subcommands.push_back(add_x3d_command(app));
  subcommands.push_back(add_render_command(app));
  subcommands.push_back(add_trade_command(app));
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // --help prints and succeeds; every other parse problem is a usage error.
    const int code = app.exit(e);
    return code == 0 ? kExitOk : kExitBadArguments;
  }
  try {
    for (const Subcommand& s : subcommands)
      if (s.app->parsed()) return s.run();
  } catch (const std::exception& e) {
    std::cerr << "tissue: " << e.what() << "\n";
    return kExitDaemonError;
  }
  return kExitBadArguments;
}
