// The sweep's --svg plot, hand-written SVG: one log-log panel per
// (integrator, dt) row and max-depth column, shared axes. Uniform levels:
// squares joined by a line; the reference (error 0 by definition) as a dashed
// vertical line at its cost; adaptive points: circles coloured by Th.
#pragma once

#include <string>
#include <vector>

#include "app/trade_sweep_point.hpp"
#include "app/trade_sweep_setup.hpp"

namespace tissue::app {

// The axes every panel shares, as whole decades of log10: cost from lc0 to
// lc1, error from le0 to le1, covering every finite positive cost and
// `metric` error of `points` (1e-3..1 for an axis with none).
struct PlotDecades {
  double lc0, lc1, le0, le1;
};
PlotDecades plot_decades(const std::vector<SweepPoint>& points, const std::string& metric);

// What one panel shows: the uniform levels and adaptive points that have a
// cost and an error (the uniform ones sorted by level), the reference run
// (nullptr if none), and a note for each run that stopped short and for runs
// not made. Pointers into `points`.
struct PanelPoints {
  std::vector<const SweepPoint*> uniform, adaptive;
  const SweepPoint* reference = nullptr;
  std::vector<std::string> notes;
};
PanelPoints panel_points(const std::vector<SweepPoint>& points, scene::IntegratorKind kind, double dt_s, int max_depth,
                         const std::string& metric);

// The whole plot of the sweep `s` (its grid, Th list, clock and scene name)
// with `points`' `metric` errors.
std::string svg_text(const SweepSetup& s, const std::vector<SweepPoint>& points, const std::string& metric);

}  // namespace tissue::app
