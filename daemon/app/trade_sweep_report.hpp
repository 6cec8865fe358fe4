// The sweep's tables on stdout: the header, the per-run table, refusals,
// and where each adaptive point lies relative to the uniform curve.
#pragma once

#include <map>
#include <string>
#include <utility>
#include <vector>

#include "app/trade_options.hpp"
#include "app/trade_sweep_point.hpp"
#include "app/trade_sweep_setup.hpp"

namespace tissue::app {

// What the sweep runs: scene, duration, Th list, max depths and the run cap.
void print_sweep_header(const TradeOptions& o, const SweepSetup& s);

// Each max depth's path truth, then one table row per point.
void print_sweep_table(const std::vector<SweepPoint>& points, const std::map<int, std::string>& truth);

// One line per distinct refusal or failure message, with the runs it ended.
void print_refusals(const std::vector<SweepPoint>& points);

// A uniform curve in (log10 cost, log10 error), sorted by cost.
using LogCurve = std::vector<std::pair<double, double>>;

// The uniform levels of p's (integrator, dt, max depth) that have a finite
// positive `metric` error and a finite cost, as a LogCurve: the levels below
// the max depth (the reference has no error against itself), and with the
// path metric the reference too (its path error is against the truth run).
LogCurve uniform_curve(const std::vector<SweepPoint>& points, const SweepPoint& p, const std::string& metric);

// The level of the cheapest point on p's uniform curve: the lowest uniform
// level, adaptivity.min_depth, unless that one has no error; -1 without a curve.
int cheapest_uniform_level(const std::vector<SweepPoint>& points, const SweepPoint& p, const std::string& metric);

// The cost of p's reference run (the uniform level at its max depth); NaN if
// that run failed or is not there.
double reference_cost(const std::vector<SweepPoint>& points, const SweepPoint& p);

// An adaptive point of cost `cost` and error `error` against the uniform
// curve interpolated (log-log) at that cost: the uniform error there
// ("n/a" without a curve of 2 points, "—" outside it) and the verdict
// (naming `cheapest_level`, the curve's cheapest point, when it costs less).
struct CurveVerdict {
  std::string uniform_error, verdict;
};
CurveVerdict compare_with_uniform_curve(double cost, double error, const LogCurve& curve, double ref_cost,
                                        int cheapest_level);

// The adaptive points' verdicts against their uniform curves, `metric` errors.
void print_verdicts(const std::vector<SweepPoint>& points, const std::string& metric);

}  // namespace tissue::app
