// What every `tissue` subcommand file provides: it registers its CLI11
// subcommand (options bound to its own state) and returns how to run it.
// main.cpp runs the one the user chose. A new subcommand is a new file with
// one add_*_command function, added to main.cpp and clients/CMakeLists.txt.
#pragma once

#include <functional>

namespace CLI {
class App;
}

namespace tissue::cli {

// Exit codes shared by all subcommands (documented in docs/control-protocol.md).
enum ExitCode : int {
  kExitOk = 0,
  kExitDaemonError = 1,    // the daemon answered, with an error
  kExitBadArguments = 2,   // the command line is wrong; nothing was sent
  kExitCannotConnect = 3,  // no daemon reachable, or the connection broke
};

struct Subcommand {
  CLI::App* app = nullptr;   // parsed() tells whether the user chose it
  std::function<int()> run;  // returns an ExitCode
};

}  // namespace tissue::cli
