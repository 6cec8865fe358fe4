// Where an adaptive point lies relative to the uniform curve
// (app/trade_sweep_report.hpp): the curve it is compared with and the verdict.
#include "app/trade_sweep_report.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

namespace tissue::app {
namespace {

// Uniform L0 at cost 1 s/s with 10 % error, L1 at 10 s/s with 1 %: a
// straight line in log-log, one decade of error per decade of cost.
const LogCurve kCurve = {{0.0, -1.0}, {1.0, -2.0}};

TEST(TradeSweepReport, InsideTheCurveTheUniformErrorIsInterpolatedLogLog) {
  // At cost 10^0.5 the line gives 10^-1.5 = 3.16 %; 0.1 % is 10^1.5 = 32x less.
  const CurveVerdict below = compare_with_uniform_curve(std::pow(10.0, 0.5), 1e-3, kCurve, 100.0, 0);
  EXPECT_EQ(below.uniform_error, "3.16 %");
  EXPECT_EQ(below.verdict, "below (32x less error)");
  // A quarter of the way along (cost 10^0.25) the line gives 10^-1.25 =
  // 5.62 %, and 10 % is 10^0.25 = 1.8x more.
  const CurveVerdict above = compare_with_uniform_curve(std::pow(10.0, 0.25), 0.1, kCurve, 100.0, 0);
  EXPECT_EQ(above.uniform_error, "5.62 %");
  EXPECT_EQ(above.verdict, "above (1.8x more error)");
}

TEST(TradeSweepReport, OutsideTheCurveTheVerdictSaysWhere) {
  const CurveVerdict cheap = compare_with_uniform_curve(0.1, 0.01, kCurve, 100.0, 0);
  EXPECT_EQ(cheap.uniform_error, "—");
  EXPECT_EQ(cheap.verdict, "cheaper than L0, and more accurate: below");
  EXPECT_EQ(compare_with_uniform_curve(0.1, 0.5, kCurve, 100.0, 0).verdict, "cheaper than L0");
  // Costlier than L1 but cheaper than the reference (100 s/s)...
  EXPECT_EQ(compare_with_uniform_curve(20.0, 1e-3, kCurve, 100.0, 0).verdict,
            "below (between L(max-1) and the reference in cost)");
  EXPECT_EQ(compare_with_uniform_curve(20.0, 0.05, kCurve, 100.0, 0).verdict,
            "above (costlier and less accurate than L(max-1))");
  // ...or not: then accuracy does not redeem it, nor does an unknown reference cost.
  EXPECT_EQ(compare_with_uniform_curve(20.0, 1e-3, kCurve, 15.0, 0).verdict, "costs more than the reference itself");
  EXPECT_EQ(compare_with_uniform_curve(20.0, 1e-3, kCurve, NAN, 0).verdict, "costs more than the reference itself");
}

TEST(TradeSweepReport, OnePointIsNoCurve) {
  const CurveVerdict v = compare_with_uniform_curve(1.0, 0.01, {{0.0, -1.0}}, 100.0, 0);
  EXPECT_EQ(v.uniform_error, "n/a");
  EXPECT_EQ(v.verdict, "no uniform curve");
}

SweepPoint uniform_point(int level, double cost, double rms_err, double dt_s = 1e-3) {
  SweepPoint p;
  p.integrator = "implicit";
  p.dt_s = dt_s;
  p.level = level;
  p.max_depth = 2;
  p.st.sim_s = 1.0;
  p.st.wall_s = cost;
  p.rms_err = rms_err;
  p.path_err = rms_err;
  return p;
}

TEST(TradeSweepReport, TheCurveIsTheSameSettingsLevelsBelowTheReference) {
  SweepPoint adaptive = uniform_point(0, 3.0, 0.02);
  adaptive.adaptive = true;
  const std::vector<SweepPoint> points = {
      uniform_point(1, 10.0, 0.01),     uniform_point(0, 1.0, 0.1),
      uniform_point(2, 100.0, 0.001),              // the reference: its rms error is 0 against itself
      uniform_point(0, 2.0, 0.3, 5e-3),            // another dt
      uniform_point(1, NAN, 0.01),      adaptive,  // no cost; not uniform
  };
  const LogCurve curve = uniform_curve(points, adaptive, "rms");
  ASSERT_EQ(curve.size(), 2u);
  EXPECT_NEAR(curve[0].first, 0.0, 1e-12);  // sorted by cost: L0 first
  EXPECT_NEAR(curve[0].second, -1.0, 1e-12);
  EXPECT_NEAR(curve[1].first, 1.0, 1e-12);
  // The path error is against the truth run: the reference is on that curve.
  EXPECT_EQ(uniform_curve(points, adaptive, "path").size(), 3u);
  EXPECT_EQ(reference_cost(points, adaptive), 100.0);
}

// With adaptivity.min_depth 2 the uniform levels start at L2: a point
// cheaper than all of them is cheaper than L2 (the verdict said L0).
TEST(TradeSweepReport, CheaperThanTheCurveNamesItsCoarsestLevel) {
  SweepPoint adaptive = uniform_point(0, 0.1, 0.5);
  adaptive.adaptive = true;
  adaptive.max_depth = 4;
  std::vector<SweepPoint> points = {uniform_point(2, 1.0, 0.1), uniform_point(3, 10.0, 0.01),
                                    uniform_point(4, 100.0, 0.0), adaptive};
  for (SweepPoint& p : points) p.max_depth = 4;
  ::testing::internal::CaptureStdout();
  print_verdicts(points, "rms");
  const std::string out = ::testing::internal::GetCapturedStdout();
  EXPECT_NE(out.find("| cheaper than L2 |"), std::string::npos) << out;
  EXPECT_EQ(out.find("L0"), std::string::npos) << out;
  EXPECT_EQ(cheapest_uniform_level(points, adaptive, "rms"), 2);
  EXPECT_EQ(compare_with_uniform_curve(0.1, 0.5, kCurve, 100.0, 2).verdict, "cheaper than L2");
}

// The header gives the cap as set (0.4 s printed as 0) and the clock it reads.
TEST(TradeSweepReport, TheHeaderGivesTheRunCapAndItsClock) {
  TradeOptions o;
  SweepSetup s;
  s.scene = "cantilever";
  s.duration_s = 0.2;
  s.run_cap_s = 0.4;
  ::testing::internal::CaptureStdout();
  print_sweep_header(o, s);
  std::string out = ::testing::internal::GetCapturedStdout();
  EXPECT_NE(out.find("; per-run cap 0.4 s of wall time ("), std::string::npos) << out;
  s.cost_uses_cpu = true;
  ::testing::internal::CaptureStdout();
  print_sweep_header(o, s);
  out = ::testing::internal::GetCapturedStdout();
  EXPECT_NE(out.find("; per-run cap 0.4 s of thread CPU time ("), std::string::npos) << out;
}

// Refusals are grouped by cause. The explicit rung's energy refusal embeds
// each run's energy, budget and excess, so grouped by the full message every
// refused point was its own group, and each was cut at 200 characters,
// before its advice. Numbers apart, the same message is one group, shown in
// full once (the first run's), with every run it ended.
TEST(TradeSweepReport, RefusalsDifferingOnlyInTheirNumbersAreOneGroupShownInFull) {
  const auto energy_refusal = [](const char* energy_J, const char* percent, const char* budget_J) {
    return std::string("explicit integrator: energy ") + energy_J + " J is " + percent + " % above its budget " +
           budget_J +
           " J (start + work + mesh changes), more than integrator.explicit_energy_slack = 1 allows; step "
           "refused, previous state kept: lower integrator.substep_safety, add damping (material.rayleigh_beta_s) "
           "or use the implicit integrator";
  };
  const auto refused = [](int level, double at_s, const std::string& error) {
    SweepPoint p = uniform_point(level, 1.0, 0.01);
    p.integrator = "explicit";
    p.st.ok = false;
    p.st.error = error;
    p.st.error_time_s = at_s;
    return p;
  };
  const std::string first = energy_refusal("0.0123", "104", "0.00603");
  const std::vector<SweepPoint> points = {
      refused(0, 0.125, first),
      refused(1, 0.25, energy_refusal("1.5e-05", "inf", "7.25e-06")),
      refused(2, 0.5, energy_refusal("nan", "inf", "0.002")),
      refused(1, 0.75, "explicit integrator: state became non-finite; step rejected, previous state kept"),
      uniform_point(0, 1.0, 0.01),  // ok: not listed
  };
  ASSERT_GT(first.size(), 200u);
  ::testing::internal::CaptureStdout();
  print_refusals(points);
  const std::string out = ::testing::internal::GetCapturedStdout();
  const auto count = [&out](const std::string& what) {
    int n = 0;
    for (auto at = out.find(what); at != std::string::npos; at = out.find(what, at + 1)) ++n;
    return n;
  };
  EXPECT_EQ(count("\n- "), 2) << out;  // two causes
  EXPECT_EQ(count("explicit integrator: energy"), 1) << out;
  EXPECT_NE(out.find("- " + first + "\n"), std::string::npos) << "the first run's message, whole:\n" << out;
  EXPECT_EQ(count("numbers above are the first run's"), 1) << out;  // only where the numbers differ
  EXPECT_NE(out.find(" [explicit dt 1 ms L0 at t=0.125 s] [explicit dt 1 ms L1 at t=0.25 s] [explicit dt 1 ms "
                     "L2 at t=0.5 s]"),
            std::string::npos)
      << out;
  EXPECT_NE(out.find("- explicit integrator: state became non-finite; step rejected, previous state kept\n  runs: "
                     "[explicit dt 1 ms L1 at t=0.75 s]"),
            std::string::npos)
      << out;
}

}  // namespace
}  // namespace tissue::app
