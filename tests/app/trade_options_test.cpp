// The trade study's command line (app/trade_options.hpp) read directly: the
// modes it defaults to, the lists it splits, and the errors that name the
// option (the CLI tests in trade_study_test.cpp check the same errors reach
// stderr with exit 2).
#include "app/trade_options.hpp"

#include <gtest/gtest.h>

#include <stdexcept>
#include <string>
#include <vector>

namespace tissue::app {
namespace {

// The message parse_trade_options throws for `args` ("" if it accepts them).
std::string parse_error(const std::vector<std::string>& args) {
  try {
    parse_trade_options(args);
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "";
}

TEST(TradeOptions, NoModeFlagRunsAllThreeButASceneFileOnlyTheSweep) {
  const TradeOptions all = parse_trade_options({});
  EXPECT_TRUE(all.table1 && all.sweep && all.beam_theory);
  EXPECT_EQ(all.metric, "rms");
  EXPECT_EQ(all.sweep_scene, "cantilever");

  const TradeOptions file = parse_trade_options({"--scene-file", "my.yaml"});
  EXPECT_TRUE(file.sweep);
  EXPECT_FALSE(file.table1 || file.beam_theory) << "a scene file is for the sweep";

  const TradeOptions one = parse_trade_options({"--beam-theory"});
  EXPECT_TRUE(one.beam_theory);
  EXPECT_FALSE(one.table1 || one.sweep) << "a mode flag runs that mode only";
}

TEST(TradeOptions, ListsAndNumbersAreReadWhole) {
  const TradeOptions o = parse_trade_options({"--sweep",       "--beam-theory",
                                              "--th",          "2,20.5",
                                              "--depths",      "3,6",
                                              "--dts",         "0.001",
                                              "--integrators", "implicit,explicit",
                                              "--duration",    "0.25",
                                              "--beam-depth",  "0",
                                              "--clock",       "cpu",
                                              "--set",         "a.b=1",
                                              "--set",         "c=2",
                                              "--scene-file",  "s.yaml"});
  EXPECT_EQ(o.th_Pa, (std::vector<double>{2.0, 20.5}));
  EXPECT_EQ(o.max_depths, (std::vector<int>{3, 6}));
  EXPECT_EQ(o.dts_s, (std::vector<double>{0.001}));
  EXPECT_EQ(o.integrators, (std::vector<std::string>{"implicit", "explicit"}));
  EXPECT_EQ(o.sweep_duration_s, 0.25);
  EXPECT_EQ(o.beam_max_depth, 0);  // 0 is a depth, not "unset" (-1)
  EXPECT_TRUE(o.cpu_clock);
  EXPECT_EQ(o.scene_overrides, (std::vector<std::string>{"a.b=1", "c=2"}));  // --set accumulates
}

TEST(TradeOptions, HelpStopsReadingTheRest) {
  EXPECT_TRUE(parse_trade_options({"--help", "--frobnicate"}).help);
  EXPECT_TRUE(parse_trade_options({"-h"}).help);
  // An unknown option before it is still an error.
  EXPECT_EQ(parse_error({"--frobnicate", "--help"}), "unknown argument --frobnicate");
}

TEST(TradeOptions, EachErrorNamesTheOptionOrTheConflict) {
  EXPECT_EQ(parse_error({"--csv"}), "missing value after --csv");
  EXPECT_EQ(parse_error({"--th", "5,-1"}), "--th: -1 must be a finite number > 0");
  EXPECT_EQ(parse_error({"--dts", "1ms"}), "--dts: '1ms' is not a number");
  EXPECT_EQ(parse_error({"--depths", "31"}), "--depths: 31 must be a depth in [0, 30]");
  EXPECT_EQ(parse_error({"--beam-depth", "x"}), "--beam-depth: 'x' is not an integer");
  EXPECT_EQ(parse_error({"--clock", "gpu"}), "--clock must be wall or cpu");
  EXPECT_EQ(parse_error({"--scene", "plate"}), "--scene must be cantilever, beam or beam-r");
  EXPECT_EQ(parse_error({"--metric", "l2"}), "--metric must be rms, max, tip or path");
  EXPECT_EQ(parse_error({"--set", "a=1"}), "--set applies to --scene-file; the built-in scenes take none");
  EXPECT_EQ(parse_error({"--table1", "--svg", "p.svg"}), "--csv and --svg are the sweep's files: add --sweep");
  EXPECT_EQ(parse_error({"--sweep", "--csv", "x", "--svg", "x"}),
            "--csv and --svg name the same file 'x': the plot would replace the table");
  // The beam-theory table runs every uniform depth up to --beam-depth, each
  // checked as a scene first: depth 17 is 192 x 2^17 = 2.5e7 tets, over the
  // mesh budget (it was accepted, and 20 would have asked for ~40 GB).
  EXPECT_EQ(parse_error({"--beam-theory", "--beam-depth", "17"}),
            "--beam-depth 17: the uniform beam at depth 17: the starting mesh would have 25165824 tetrahedra (32 "
            "cubes x 6 x 2^17), more than 20000000 (adaptivity.min_depth)");
  EXPECT_EQ(parse_error({"--beam-theory", "--beam-depth", "16"}), "");
  // With the sweep in the defaulted modes, its files are fine.
  EXPECT_EQ(parse_error({"--csv", "t.csv", "--svg", "p.svg"}), "");
  // Table 1 and beam theory run their built-in scenes with --quick alone: an
  // option of the sweep without --sweep was silently ignored (Table 1 ran on
  // the built-in cantilever, never opening --scene-file).
  EXPECT_EQ(parse_error({"--table1", "--scene-file", "mine.yaml", "--set", "a=1"}),
            "--scene-file is the sweep's option (Table 1 and beam theory do not read it): add --sweep");
  for (const std::vector<std::string>& option : {std::vector<std::string>{"--scene", "beam"},
                                                 {"--th", "20"},
                                                 {"--depths", "3"},
                                                 {"--integrators", "implicit"},
                                                 {"--dts", "0.001"},
                                                 {"--duration", "0.2"},
                                                 {"--run-cap", "5"},
                                                 {"--clock", "wall"},
                                                 {"--metric", "rms"},
                                                 {"--preconditioner", "jacobi"},
                                                 {"--explicit-precision", "float"}}) {
    std::vector<std::string> args = {"--beam-theory", "--quick"};
    args.insert(args.end(), option.begin(), option.end());
    EXPECT_EQ(parse_error(args),
              option[0] + " is the sweep's option (Table 1 and beam theory do not read it): add --sweep");
  }
  EXPECT_EQ(parse_error({"--sweep", "--table1", "--th", "20", "--clock", "cpu"}), "") << "with --sweep they are read";
  // Only the beam-theory table reads --beam-depth.
  EXPECT_EQ(parse_error({"--sweep", "--beam-depth", "3"}),
            "--beam-depth is the beam-theory table's option: add --beam-theory");
  // The sweep runs one scene: a built-in one or a file, not both.
  EXPECT_EQ(parse_error({"--sweep", "--scene", "beam", "--scene-file", "mine.yaml"}),
            "--scene and --scene-file both name the sweep's scene: give one");
  // A value given twice ran its points twice (duplicate CSV rows, points
  // drawn over each other), by value and across repeats of the option.
  EXPECT_EQ(parse_error({"--sweep", "--depths", "3,3"}),
            "--depths: 3 is given twice (each point of the sweep runs once)");
  EXPECT_EQ(parse_error({"--sweep", "--th", "5,20", "--th", "5.0"}),
            "--th: 5 is given twice (each point of the sweep runs once)");
  EXPECT_EQ(parse_error({"--sweep", "--dts", "0.001,1e-3"}),
            "--dts: 0.001 is given twice (each point of the sweep runs once)");
  EXPECT_EQ(parse_error({"--sweep", "--integrators", "implicit,explicit,implicit"}),
            "--integrators: implicit is given twice (each point of the sweep runs once)");
  // Repeating --integrators adds to the list, as the other lists do (a
  // second one replaced the first, silently running only its integrators).
  EXPECT_EQ(parse_error({"--sweep", "--integrators", "implicit", "--integrators", "implicit"}),
            "--integrators: implicit is given twice (each point of the sweep runs once)");
  EXPECT_EQ(parse_trade_options({"--sweep", "--integrators", "implicit", "--integrators", "explicit"}).integrators,
            (std::vector<std::string>{"implicit", "explicit"}));
  EXPECT_EQ(parse_error({"--sweep", "--depths", "3,6", "--th", "5,20", "--dts", "0.001,0.005"}), "");
}

}  // namespace
}  // namespace tissue::app
