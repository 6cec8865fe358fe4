// --sweep: cost vs error. Th x max depth x integrator x dt, each adaptive run
// against the uniform reference at the same max depth and integrator
// settings; uniform levels base..max depth are the baseline curve. Prints
// its tables and writes --csv and --svg.
//
// A run that exceeds the per-run cap (--run-cap; quick 3 s, full 30 s)
// stops: its cost is still valid, its error is not; finer uniform levels are
// then not run, nor adaptive runs whose reference did not finish.
#pragma once

#include <stdexcept>

#include "app/output_file.hpp"
#include "app/trade_options.hpp"
#include "app/trade_sweep_setup.hpp"

namespace tissue::app {

// A --csv or --svg file that could not be written (the message names it).
struct OutputError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// How a sweep ended: the signal that stopped it (0: none), and whether any
// run gave figures (ok, or capped by --run-cap with what it reached).
struct SweepEnd {
  int signal = 0;
  bool any_figures = false;
};

// Runs the sweep `s` (make_sweep_setup, made before any mode runs so that a
// setup that cannot run fails at once), prints its tables and writes `csv` /
// `svg` (those opened). A signal in s.stop ends it early; the tables and
// files then hold the runs done. Throws OutputError for a file that cannot
// be written.
SweepEnd run_sweep(const TradeOptions& o, const SweepSetup& s, OutputFile& csv, OutputFile& svg);

}  // namespace tissue::app
