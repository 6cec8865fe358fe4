// The sweep's setup (app/trade_sweep_setup.hpp): every run it would make is
// checked before the first one.
#include "app/trade_sweep_setup.hpp"

#include <gtest/gtest.h>

#include <stdexcept>
#include <string>
#include <vector>

#include "app/trade_options.hpp"

namespace tissue::app {
namespace {

// The message make_sweep_setup throws for `args` ("" if it accepts them).
std::string setup_error(const std::vector<std::string>& args) {
  try {
    make_sweep_setup(parse_trade_options(args), nullptr);
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "";
}

// --dts 1e-300 (its step count out of range) and 5 (above the scene's 1 s
// bound) ran every point as an "ok" run of zero steps.
TEST(TradeSweepSetup, AStepThatMakesNoRunOrTooManyIsRefused) {
  EXPECT_NE(setup_error({"--sweep", "--quick", "--dts", "1e-300"}).find("--dts 1e-300: a run of 0.2 s would take"),
            std::string::npos)
      << setup_error({"--sweep", "--quick", "--dts", "1e-300"});
  EXPECT_NE(setup_error({"--sweep", "--quick", "--dts", "5"}).find("--dts 5: a run of 0.2 s would take 0 steps"),
            std::string::npos)
      << setup_error({"--sweep", "--quick", "--dts", "5"});
  EXPECT_EQ(setup_error({"--sweep", "--quick", "--dts", "0.001,0.005"}), "");
}

// --depths 30 scheduled uniform levels up to L30 (6e9 tets a cube); the
// scene checks refuse the first level past the mesh budget, before any run.
TEST(TradeSweepSetup, UniformLevelsPastTheMeshBudgetAreRefusedBeforeRunning) {
  const std::string why = setup_error({"--sweep", "--quick", "--depths", "30", "--integrators", "explicit"});
  EXPECT_NE(why.find("the sweep's uniform run at depth"), std::string::npos) << why;
  EXPECT_NE(why.find("the starting mesh would have"), std::string::npos) << why;
  EXPECT_NE(why.find("(adaptivity.min_depth)"), std::string::npos) << why;
  EXPECT_EQ(setup_error({"--sweep", "--quick", "--depths", "4", "--integrators", "explicit"}), "");
}

}  // namespace
}  // namespace tissue::app
