// The sweep's plot (app/trade_plot_svg.hpp) on a handful of points: shared
// decade axes, what each panel draws, and where.
#include "app/trade_plot_svg.hpp"

#include <gtest/gtest.h>

#include <string>
#include <vector>

namespace tissue::app {
namespace {

namespace sc = tissue::scene;

std::size_t count(const std::string& text, const std::string& what) {
  std::size_t n = 0;
  for (std::size_t at = text.find(what); at != std::string::npos; at = text.find(what, at + 1)) ++n;
  return n;
}

// A finished implicit dt 1 ms run at max depth 2 costing `cost` s/s.
SweepPoint run(bool adaptive, int level, double th_Pa, double cost, double rms_err) {
  SweepPoint p;
  p.integrator = "implicit";
  p.dt_s = 1e-3;
  p.max_depth = 2;
  p.adaptive = adaptive;
  p.level = level;
  p.th_Pa = th_Pa;
  p.st.sim_s = 0.2;
  p.st.wall_s = 0.2 * cost;
  p.rms_err = rms_err;
  p.captured = true;
  return p;
}

// Uniform L1 and L0 (out of order), the reference L2 (error 0: not drawn),
// adaptive Th 20, a failed Th 80, and a run of another dt.
std::vector<SweepPoint> handful() {
  SweepPoint failed = run(true, 0, 80, 0.5, NAN);
  failed.st.ok = false;
  failed.st.error_time_s = 0.05;
  failed.captured = false;
  SweepPoint other_dt = run(false, 0, NAN, 0.3, 0.2);
  other_dt.dt_s = 5e-3;
  return {run(false, 1, NAN, 1.0, 0.01),
          run(false, 0, NAN, 0.2, 0.05),
          run(false, 2, NAN, 5.0, 0.0),
          run(true, 0, 20, 0.5, 0.002),
          failed,
          other_dt};
}

TEST(TradePlotSvg, AxesAreWholeDecadesAroundEveryCostAndError) {
  // Costs 0.2..5 s/s, errors 0.002..0.2 (the 0 of the reference is not on a log axis).
  const PlotDecades d = plot_decades(handful(), "rms");
  EXPECT_EQ(d.lc0, -1.0);
  EXPECT_EQ(d.lc1, 1.0);
  EXPECT_EQ(d.le0, -3.0);
  EXPECT_EQ(d.le1, 0.0);
  // Nothing measured: 1e-3..1 on both, and an exact decade at the top gets
  // one decade of headroom (the +1e-9 before the ceil).
  const PlotDecades none = plot_decades({}, "tip");
  EXPECT_EQ(none.lc0, -3.0);
  EXPECT_EQ(none.lc1, 1.0);
  EXPECT_EQ(none.le0, -3.0);
  EXPECT_EQ(none.le1, 1.0);
}

TEST(TradePlotSvg, APanelHoldsItsSettingsRunsAndNotes) {
  std::vector<SweepPoint> points = handful();
  SweepPoint not_run = not_run_point(sc::IntegratorKind::kImplicit, 1e-3, "not run: no reference");
  not_run.adaptive = true;
  not_run.max_depth = 2;
  points.push_back(not_run);
  const PanelPoints pp = panel_points(points, sc::IntegratorKind::kImplicit, 1e-3, 2, "rms");
  ASSERT_EQ(pp.uniform.size(), 2u);  // L0, L1: the reference has no error to draw
  EXPECT_EQ(pp.uniform[0]->level, 0);
  EXPECT_EQ(pp.uniform[1]->level, 1);
  ASSERT_EQ(pp.adaptive.size(), 1u);
  EXPECT_EQ(pp.adaptive[0]->th_Pa, 20.0);
  ASSERT_NE(pp.reference, nullptr);
  EXPECT_EQ(pp.reference->level, 2);
  EXPECT_EQ(pp.notes, (std::vector<std::string>{"Th 80 refused/failed at t=0.05 s",
                                                "1 adaptive run(s) not run: no reference L2"}));
  EXPECT_TRUE(panel_points(points, sc::IntegratorKind::kExplicit, 1e-3, 2, "rms").uniform.empty());
}

TEST(TradePlotSvg, TheSvgPlacesEachMarkOnTheLogLogPanel) {
  SweepSetup s;
  s.scene = "block <A&B>";
  s.duration_s = 0.2;
  s.kinds = {sc::IntegratorKind::kImplicit};
  s.dts_s = {1e-3};
  s.max_depths = {2};
  s.th_Pa = {20, 80};
  const std::string svg = svg_text(s, handful(), "rms");
  EXPECT_EQ(svg.rfind("<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"900\" height=\"432\"", 0), 0u)
      << "one panel: the minimum width; 40 title + 70 legend + 36 + 230 + 46 panel + 10";
  EXPECT_EQ(svg.substr(svg.size() - 7), "</svg>\n");
  EXPECT_NE(svg.find("Cost vs error, block &lt;A&amp;B&gt; at t = 0.2 s"), std::string::npos);
  EXPECT_NE(svg.find(">implicit, dt = 1 ms, max depth 2</text>"), std::string::npos);
  // The panel starts at x0 = 70, y0 = 40 + 70 + 36 = 146 and spans 330 x 230
  // px over cost 1e-1..1e1 and error 1e-3..1e0. L1 (cost 1, error 1e-2) sits
  // half way across, x = 70 + 330 / 2 = 235, and two decades of three down,
  // y = 146 + 230 * 2 / 3 = 299.333; its square is drawn 4 px up and left.
  EXPECT_NE(svg.find("<rect x=\"231\" y=\"295.333\" width=\"8\" height=\"8\" fill=\"black\"/><text x=\"241\" "
                     "y=\"294.333\">L1</text>"),
            std::string::npos)
      << svg;
  EXPECT_EQ(count(svg, "<polyline"), 1u);                   // L0 - L1
  EXPECT_EQ(count(svg, "fill-opacity=\"0.85\""), 1u);       // the one adaptive point with an error
  EXPECT_EQ(count(svg, "fill=\"gray\">L2</text>"), 1u);     // the reference's cost line
  EXPECT_EQ(count(svg, "refused/failed at t=0.05 s"), 1u);  // the failed run's note
  EXPECT_EQ(count(svg, "text-anchor=\"middle\">1e"), 3u);   // cost decades -1, 0, 1 label the x axis...
  EXPECT_EQ(count(svg, "text-anchor=\"end\">1e"), 4u);      // ...and error decades -3..0 the y axis
}

// The legend names the uniform levels the sweep ran: from the scene's
// adaptivity.min_depth (it said L0 whatever the lowest level was).
TEST(TradePlotSvg, TheLegendNamesTheLowestUniformLevel) {
  SweepSetup s;
  s.kinds = {sc::IntegratorKind::kImplicit};
  s.dts_s = {1e-3};
  s.max_depths = {4};
  EXPECT_NE(svg_text(s, {}, "rms").find(">uniform levels L0..L(max-1) (line)</text>"), std::string::npos);
  s.base_depth = 2;
  const std::string svg = svg_text(s, {}, "rms");
  EXPECT_NE(svg.find(">uniform levels L2..L(max-1) (line)</text>"), std::string::npos) << svg;
  EXPECT_EQ(svg.find("L0"), std::string::npos) << svg;
}

TEST(TradePlotSvg, OnePanelPerIntegratorRowAndDtAndDepthColumn) {
  SweepSetup s;
  s.kinds = {sc::IntegratorKind::kImplicit, sc::IntegratorKind::kExplicit};
  s.dts_s = {1e-3, 5e-3};
  s.max_depths = {2, 3};
  const std::string svg = svg_text(s, {}, "tip");
  EXPECT_EQ(count(svg, "fill=\"none\" stroke=\"black\"/>"), 8u);
  // 4 columns of 70 + 330 + 20 px + 10; 2 rows of 36 + 230 + 46 px under the 110 px title and legend, + 10.
  EXPECT_EQ(svg.rfind("<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"1690\" height=\"744\"", 0), 0u);
  EXPECT_NE(svg.find(">explicit, dt = 5 ms, max depth 3</text>"), std::string::npos);
  EXPECT_NE(svg.find(">tip error [-]</text>"), std::string::npos);
}

}  // namespace
}  // namespace tissue::app
