// --table1: the seed paper's Table 1 for this implementation (cantilever
// §4.1): low / high / adaptive node and tet counts at t2 and at peak, plus
// what the paper leaves out: tip and node error of low and adaptive against
// high, and cost.
#pragma once

#include "app/trade_options.hpp"

namespace tissue::app {

// Runs the three meshes and prints the table and its diagnostics to stdout
// (progress to stderr). --quick shortens the run (release at 0.25 s, end 0.5 s).
void run_table1(const TradeOptions& o);

}  // namespace tissue::app
