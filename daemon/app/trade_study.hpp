// The speed/accuracy trade study (NUMERICS.md §4): the seed paper's Table 1
// for this implementation, a cost-vs-error sweep against the uniform
// reference (CSV + SVG) on the shipped scenes or a user's scene file, and the
// beam's model error against beam theory. `tissue trade` and the build tree's
// `trade_bench` are this one function; the option list is its usage text
// (`--help`) and the README's "The speed/accuracy trade".
#pragma once

#include <string>
#include <vector>

namespace tissue::app {

// Exit codes of run_trade_study.
enum TradeExitCode : int {
  kTradeExitOk = 0,
  kTradeExitUsage = 2,   // a bad option, a scene file that does not load, a run that cannot start
  kTradeExitNoRun = 3,   // every run of the sweep failed or was refused: no figure came out
  kTradeExitOutput = 4,  // --csv or --svg cannot be written (checked before any run)
  // 128 + N: the sweep was stopped by signal N (SIGINT 130, SIGTERM 143;
  // util/stop_signals.hpp); its tables and files hold the runs done.
};

// Runs the study `args` ask for (argv without the program name), printing
// its tables to stdout. `program` names it in the usage and error lines.
// Returns one of the codes above after printing the reason to stderr (with
// the usage, for a bad option).
int run_trade_study(const std::string& program, const std::vector<std::string>& args);

}  // namespace tissue::app
