#include "app/trade_plot_svg.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "app/trade_format.hpp"
#include "app/trade_scenes.hpp"
#include "util/xml.hpp"

namespace tissue::app {
namespace {

const std::vector<std::string> kColours = {"#d62728", "#ff7f0e", "#2ca02c", "#1f77b4",
                                           "#9467bd", "#8c564b", "#e377c2", "#17becf"};

// Panel size and margins, the legend and title bands [px].
constexpr double kPanelW = 330, kPanelH = 230, kMarginL = 70, kMarginR = 20, kMarginT = 36, kMarginB = 46;
constexpr double kLegendH = 70, kTitleH = 40;

// One panel's position and its log-log mapping of cost and error to pixels.
struct Panel {
  double x0, y0;
  PlotDecades d;
  double X(double cost) const { return x0 + kPanelW * (std::log10(cost) - d.lc0) / (d.lc1 - d.lc0); }
  double Y(double err) const { return y0 + kPanelH * (1.0 - (std::log10(err) - d.le0) / (d.le1 - d.le0)); }
};

// The colour of threshold `th`: its place in the sweep's Th list.
const std::string& th_colour(const std::vector<double>& th_Pa, double th) {
  std::size_t index = 0;
  for (std::size_t i = 0; i < th_Pa.size(); ++i)
    if (th_Pa[i] == th) {
      index = i;
      break;
    }
  return kColours[index % kColours.size()];
}

std::string metric_label(const std::string& metric) {
  return metric == "tip"    ? "tip displacement error"
         : metric == "max"  ? "max node error / max |u_ref|"
         : metric == "path" ? "tip path error vs the truth run / max |u_tip,truth|"
                            : "RMS node error / max |u_ref|";
}

void write_title_and_legend(std::ostream& o, const SweepSetup& s, const std::string& metric) {
  o << "<text x=\"10\" y=\"22\" font-size=\"15\" font-weight=\"bold\">Cost vs error, "
    << tissue::util::escape_xml(s.scene) << " at t = " << s.duration_s
    << " s: adaptive points below the uniform curve = adaptivity pays</text>\n";
  const double lx = 10, ly = kTitleH + 10;
  o << "<rect x=\"" << lx << "\" y=\"" << ly - 6 << "\" width=\"10\" height=\"10\" fill=\"black\"/><text x=\""
    << lx + 14 << "\" y=\"" << ly + 3 << "\">uniform levels " << level_name(s.base_depth)
    << "..L(max-1) (line)</text>\n";  // from the scene's adaptivity.min_depth
  o << "<line x1=\"" << lx + 230 << "\" y1=\"" << ly - 6 << "\" x2=\"" << lx + 230 << "\" y2=\"" << ly + 6
    << "\" stroke=\"gray\" stroke-dasharray=\"4,3\" stroke-width=\"1.5\"/><text x=\"" << lx + 236 << "\" y=\"" << ly + 3
    << "\">uniform reference at max depth (error 0 by definition): its cost</text>\n";
  for (std::size_t i = 0; i < s.th_Pa.size(); ++i) {
    const double x = lx + 14 + 120 * static_cast<double>(i % 6), y = ly + 22 + 16 * static_cast<double>(i / 6);
    o << "<circle cx=\"" << x - 8 << "\" cy=\"" << y - 4 << "\" r=\"4.5\" fill=\"" << kColours[i % kColours.size()]
      << "\"/><text x=\"" << x << "\" y=\"" << y << "\">adaptive Th = " << s.th_Pa[i] << " Pa</text>\n";
  }
  o << "<text x=\"" << lx << "\" y=\"" << ly + 54 << "\">x: cost = " << (s.cost_uses_cpu ? "thread CPU" : "wall")
    << " s per simulated s (step incl. adaptation); y: " << metric_label(metric)
    << " vs the uniform reference at the same max depth (log-log)</text>\n";
}

// The panel's title, frame, decade grid lines with their labels, and axis titles.
void write_panel_frame(std::ostream& o, const Panel& p, const std::string& title, bool cost_uses_cpu,
                       const std::string& metric) {
  const double x0 = p.x0, y0 = p.y0;
  o << "<text x=\"" << x0 << "\" y=\"" << y0 - 8 << "\" font-weight=\"bold\">" << title << "</text>\n";
  o << "<rect x=\"" << x0 << "\" y=\"" << y0 << "\" width=\"" << kPanelW << "\" height=\"" << kPanelH
    << "\" fill=\"none\" stroke=\"black\"/>\n";
  for (double d = p.d.lc0; d <= p.d.lc1 + 1e-9; d += 1) {
    const double x = p.X(std::pow(10.0, d));
    o << "<line x1=\"" << x << "\" y1=\"" << y0 << "\" x2=\"" << x << "\" y2=\"" << y0 + kPanelH
      << "\" stroke=\"#ddd\"/><text x=\"" << x << "\" y=\"" << y0 + kPanelH + 14 << "\" text-anchor=\"middle\">1e" << d
      << "</text>\n";
  }
  for (double d = p.d.le0; d <= p.d.le1 + 1e-9; d += 1) {
    const double y = p.Y(std::pow(10.0, d));
    o << "<line x1=\"" << x0 << "\" y1=\"" << y << "\" x2=\"" << x0 + kPanelW << "\" y2=\"" << y
      << "\" stroke=\"#ddd\"/><text x=\"" << x0 - 4 << "\" y=\"" << y + 4 << "\" text-anchor=\"end\">1e" << d
      << "</text>\n";
  }
  o << "<text x=\"" << x0 + kPanelW / 2 << "\" y=\"" << y0 + kPanelH + 30 << "\" text-anchor=\"middle\">cost ["
    << (cost_uses_cpu ? "CPU" : "wall") << " s / simulated s]</text>\n";
  o << "<text transform=\"translate(" << x0 - 48 << "," << y0 + kPanelH / 2 << ") rotate(-90)\" text-anchor=\"middle\">"
    << (metric == "tip"    ? "tip error [-]"
        : metric == "path" ? "tip path error [-]"
                           : "node error [-]")
    << "</text>\n";
}

// The reference's cost line, the uniform curve and squares, the adaptive
// circles and up to 8 notes.
void write_panel_marks(std::ostream& o, const Panel& p, const PanelPoints& pp, int max_depth,
                       const std::vector<double>& th_Pa, const std::string& metric) {
  const SweepPoint* ref = pp.reference;
  if (ref && std::isfinite(ref->st.cost()) && ref->st.cost() > 0) {
    const double x = p.X(ref->st.cost());
    o << "<line x1=\"" << x << "\" y1=\"" << p.y0 << "\" x2=\"" << x << "\" y2=\"" << p.y0 + kPanelH
      << "\" stroke=\"gray\" stroke-dasharray=\"4,3\" stroke-width=\"1.5\"/><text x=\"" << x + 3 << "\" y=\""
      << p.y0 + 12 << "\" fill=\"gray\">L" << max_depth << (ref->st.capped ? " (capped)" : "") << "</text>\n";
  }
  if (pp.uniform.size() > 1) {
    o << "<polyline fill=\"none\" stroke=\"black\" stroke-width=\"1.5\" points=\"";
    for (const SweepPoint* q : pp.uniform) o << p.X(q->st.cost()) << ',' << p.Y(metric_of(*q, metric)) << ' ';
    o << "\"/>\n";
  }
  for (const SweepPoint* q : pp.uniform) {
    const double x = p.X(q->st.cost()), y = p.Y(metric_of(*q, metric));
    o << "<rect x=\"" << x - 4 << "\" y=\"" << y - 4 << "\" width=\"8\" height=\"8\" fill=\"black\"/><text x=\""
      << x + 6 << "\" y=\"" << y - 5 << "\">L" << q->level << "</text>\n";
  }
  for (const SweepPoint* q : pp.adaptive) {
    const std::string& colour = th_colour(th_Pa, q->th_Pa);
    o << "<circle cx=\"" << p.X(q->st.cost()) << "\" cy=\"" << p.Y(metric_of(*q, metric))
      << "\" r=\"4.5\" fill-opacity=\"0.85\" fill=\"" << colour
      << "\" stroke=\"black\" stroke-width=\"0.5\"/><text x=\"" << p.X(q->st.cost()) + 6 << "\" y=\""
      << p.Y(metric_of(*q, metric)) + 10 << "\" font-size=\"9\" fill=\"" << colour << "\">" << q->th_Pa << "</text>\n";
  }
  for (std::size_t i = 0; i < pp.notes.size() && i < 8; ++i)
    o << "<text x=\"" << p.x0 + 6 << "\" y=\"" << p.y0 + kPanelH - 8 - 12 * static_cast<double>(i)
      << "\" fill=\"#a00\" font-size=\"10\">" << pp.notes[i] << "</text>\n";
}

// Why a run has no mark of its own: it hit the cap or failed.
std::string stopped_short_note(const SweepPoint& p) {
  std::ostringstream n;
  n << (p.adaptive ? "Th " + format_number("%g", p.th_Pa) : level_name(p.level))
    << (p.st.ok ? " hit the run cap (cost " + format_number("%.3g", p.st.cost()) + " s/s)"
                : " refused/failed at t=" + format_number("%.3g", p.st.error_time_s) + " s");
  return n.str();
}

}  // namespace

PlotDecades plot_decades(const std::vector<SweepPoint>& points, const std::string& metric) {
  double cmin = INFINITY, cmax = 0, emin = INFINITY, emax = 0;
  for (const auto& p : points) {
    const double c = p.st.cost();
    if (std::isfinite(c) && c > 0) cmin = std::min(cmin, c), cmax = std::max(cmax, c);
    const double e = metric_of(p, metric);
    if (std::isfinite(e) && e > 0) emin = std::min(emin, e), emax = std::max(emax, e);
  }
  if (!(cmax > 0)) cmin = 1e-3, cmax = 1;
  if (!(emax > 0)) emin = 1e-3, emax = 1;
  return {std::floor(std::log10(cmin)), std::ceil(std::log10(cmax) + 1e-9), std::floor(std::log10(emin)),
          std::ceil(std::log10(emax) + 1e-9)};
}

PanelPoints panel_points(const std::vector<SweepPoint>& points, scene::IntegratorKind kind, double dt_s, int max_depth,
                         const std::string& metric) {
  PanelPoints out;
  int skipped_levels = 0, skipped_adaptive = 0;
  for (const auto& p : points) {
    if (p.integrator != integrator_name(kind) || p.dt_s != dt_s || p.max_depth != max_depth) continue;
    if (!p.adaptive && p.level == max_depth) out.reference = &p;
    if (p.skipped) {
      ++(p.adaptive ? skipped_adaptive : skipped_levels);
    } else if (!p.st.ok || p.st.capped) {
      out.notes.push_back(stopped_short_note(p));
    }
    const double e = metric_of(p, metric), cost = p.st.cost();
    if (!(std::isfinite(e) && e > 0 && std::isfinite(cost) && cost > 0)) continue;
    (p.adaptive ? out.adaptive : out.uniform).push_back(&p);
  }
  if (skipped_levels > 0) out.notes.push_back(std::to_string(skipped_levels) + " finer uniform level(s) not run");
  if (skipped_adaptive > 0)
    out.notes.push_back(std::to_string(skipped_adaptive) + " adaptive run(s) not run: no reference L" +
                        std::to_string(max_depth));
  if (out.reference && !out.reference->captured)
    out.notes.push_back("no errors: the reference L" + std::to_string(max_depth) + " did not finish");
  std::sort(out.uniform.begin(), out.uniform.end(),
            [](const SweepPoint* a, const SweepPoint* b) { return a->level < b->level; });
  return out;
}

std::string svg_text(const SweepSetup& s, const std::vector<SweepPoint>& points, const std::string& metric) {
  const PlotDecades decades = plot_decades(points, metric);
  // Rows: integrators; columns: (dt, max depth).
  struct Column {
    double dt;
    int max_depth;
  };
  std::vector<Column> columns;
  for (double dt : s.dts_s)
    for (int md : s.max_depths) columns.push_back({dt, md});
  const auto& rows = s.kinds;
  const int cols = static_cast<int>(columns.size());
  const double width = std::max(900.0, cols * (kMarginL + kPanelW + kMarginR) + 10);
  const double height = kTitleH + kLegendH + rows.size() * (kMarginT + kPanelH + kMarginB) + 10;

  std::ostringstream o;
  o << "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" << width << "\" height=\"" << height
    << "\" font-family=\"sans-serif\" font-size=\"11\">\n<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n";
  write_title_and_legend(o, s, metric);
  for (std::size_t r = 0; r < rows.size(); ++r) {
    for (int c = 0; c < cols; ++c) {
      const int md = columns[static_cast<std::size_t>(c)].max_depth;
      const double dt = columns[static_cast<std::size_t>(c)].dt;
      const Panel panel{c * (kMarginL + kPanelW + kMarginR) + kMarginL,
                        kTitleH + kLegendH + r * (kMarginT + kPanelH + kMarginB) + kMarginT, decades};
      std::ostringstream title;
      title << integrator_name(rows[r]) << ", dt = " << dt * 1e3 << " ms, max depth " << md;
      write_panel_frame(o, panel, title.str(), s.cost_uses_cpu, metric);
      write_panel_marks(o, panel, panel_points(points, rows[r], dt, md, metric), md, s.th_Pa, metric);
    }
  }
  o << "</svg>\n";
  return o.str();
}

}  // namespace tissue::app
