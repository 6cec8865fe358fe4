// Beam theory for the --beam-theory table (app/trade_beam_theory.hpp),
// worked by hand for the 0.4 x 0.1 x 0.1 m beam, E = 5e4 Pa, F = 0.05 N.
#include "app/trade_beam_theory.hpp"

#include <gtest/gtest.h>

namespace tissue::app {
namespace {

TEST(TradeBeamTheory, EulerBernoulliAndTimoshenkoTips) {
  const BeamTheory bt = beam_theory_tip();
  // I = b h^3 / 12 = 1e-4 / 12 m^4; F L^3 / (3 E I) = 0.0032 / 1.25 = 2.56 mm.
  EXPECT_NEAR(bt.euler_bernoulli_m, 2.56e-3, 1e-12);
  // Shear adds F L / (kappa G A): G = E / 2.5 = 2e4 Pa, A = 0.01 m^2,
  // kappa = 10 (1.25) / (12 + 2.75) = 12.5 / 14.75, so 0.02 * 14.75 / (12.5 * 200) m.
  EXPECT_NEAR(bt.timoshenko_m - bt.euler_bernoulli_m, 0.02 * 14.75 / (12.5 * 200.0), 1e-12);
}

}  // namespace
}  // namespace tissue::app
