// The trade study's command line: what to run and with which settings. The
// usage text is the option reference (`tissue trade --help`).
#pragma once

#include <cstdio>
#include <string>
#include <vector>

namespace tissue::app {

struct TradeOptions {
  bool table1 = false, sweep = false, beam_theory = false, quick = false;
  std::string csv_path, svg_path;
  std::string sweep_scene = "cantilever";    // or "beam", "beam-r"
  std::string scene_file;                    // --scene-file: a user's scene instead
  std::vector<std::string> scene_overrides;  // --set key.path=value, applied to the scene file
  std::string preconditioner;      // implicit CG: jacobi | two_level | auto; empty: jacobi (a scene file: its own)
  std::string explicit_precision;  // explicit rung: double | float; empty: double (a scene file: its own)
  std::string metric = "rms";      // plotted error: rms | max | tip | path
  std::vector<double> th_Pa;       // empty: the scene's default list
  std::vector<int> max_depths;     // empty: {3, 6} (quick: {3})
  std::vector<std::string> integrators;  // empty: all three
  std::vector<double> dts_s;             // empty: {1 ms, 5 ms}
  double sweep_duration_s = 0.0;         // 0: the scene's default
  double run_cap_s = 0.0;                // 0: default (quick 3 s, full 30 s)
  int beam_max_depth = -1;               // -1: 6 (quick: 4)
  bool cpu_clock = false;                // --clock cpu: verdicts and plot use thread CPU time
  bool help = false;                     // -h / --help: print the usage, run nothing
};

// `args` (argv without the program name) as options, with the modes
// defaulted (no mode flag: all three; with --scene-file: the sweep). Throws
// std::invalid_argument naming the option and value that is wrong. -h or
// --help stops reading: the rest is not checked.
TradeOptions parse_trade_options(const std::vector<std::string>& args);

// The usage text, `program` as its first word.
void print_trade_usage(const std::string& program, std::FILE* to);

}  // namespace tissue::app
