// trade_bench: the trade study (app/trade_study.hpp) in the build tree, as the
// README's figures were produced; installed labs run the same as `tissue trade`.
#include <string>
#include <vector>

#include "app/trade_study.hpp"

int main(int argc, char** argv) {
  return tissue::app::run_trade_study("trade_bench", std::vector<std::string>(argv + 1, argv + argc));
}
