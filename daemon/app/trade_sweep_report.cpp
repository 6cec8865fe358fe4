#include "app/trade_sweep_report.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <regex>

#include "app/trade_format.hpp"

namespace tissue::app {

void print_sweep_header(const TradeOptions& o, const SweepSetup& s) {
  const std::string about = s.from_file ? "scene file " + o.scene_file + ", its loads and boundary conditions"
                            : s.is_builtin_beam()
                                ? "0.05 N ramped over the first quarter, Rayleigh alpha 30/s: static-ish"
                                : "seed §4.1, constant 5 N: static from ~0.3 s on";
  std::printf("\n## Sweep: %s (%s), state at t = %.2f s%s\n\n", s.scene.c_str(), about.c_str(), s.duration_s,
              o.quick ? " (--quick)" : "");
  if (s.from_file && s.from_file->probes.empty())
    std::printf("The scene has no probes: no tip error (the first probe is the tip).\n");
  std::printf("Th (Pa):");
  for (double t : s.th_Pa) std::printf(" %g", t);
  std::printf("; max depths:");
  for (int d : s.max_depths) std::printf(" %d", d);
  // %g: a cap of 0.4 s printed as "0" with %.0f; the clock is the one the cap reads.
  std::printf("; per-run cap %g s of %s time (a capped run still gives its cost, not its error).\n\n", s.run_cap_s,
              s.cost_uses_cpu ? "thread CPU" : "wall");
}

namespace {

// The status column: why a run stopped and when, and whether CG was capped.
std::string status_text(const SweepPoint& p) {
  std::string status = p.status();
  if (!p.st.ok && !p.skipped) status += " at t=" + format_number("%.3g", p.st.error_time_s) + " s";
  if (p.st.unconverged_steps > 0)  // cheaper, but short of the tolerance: say so beside the cost
    status += ", " + std::to_string(p.st.unconverged_steps) + " steps CG-capped";
  return status;
}

void print_point_row(const SweepPoint& p) {
  const std::string mesh =
      p.adaptive ? "adaptive Th " + format_number("%g", p.th_Pa) : "uniform L" + std::to_string(p.level);
  const bool is_reference = !(p.adaptive || p.level != p.max_depth);
  std::printf(
      "| %s | %g | %d | %s | %s | %zu | %zu | %d (%zu) | %s | %s | %s | %s | %s | %.1f | %d | %s |\n",
      p.integrator.c_str(), p.dt_s * 1e3, p.max_depth, mesh.c_str(), status_text(p).c_str(), p.tets, p.peak_tets,
      p.deepest, p.tets_at_deepest,
      std::isfinite(p.st.wall_cost())
          ? (format_number("%.3g", p.st.wall_cost()) + " (" + format_number("%.3g", p.st.cpu_cost()) + ")").c_str()
          : "n/a",
      is_reference ? "ref" : percent_text(p.tip_err).c_str(), is_reference ? "ref" : percent_text(p.rms_err).c_str(),
      is_reference ? "ref" : percent_text(p.max_err).c_str(), percent_text(p.path_err).c_str(), p.st.mean_iterations(),
      p.st.max_substeps,
      p.adaptive && std::isfinite(p.st.last_adapt_s) ? format_number("%.3f", p.st.last_adapt_s).c_str() : "");
}

}  // namespace

void print_sweep_table(const std::vector<SweepPoint>& points, const std::map<int, std::string>& truth) {
  for (const auto& [md, what] : truth)
    std::printf(
        "Tip path error at max depth %d: RMS over the run of |u_tip(t) - u_truth(t)| / max |u_truth|, "
        "truth = %s.\n",
        md, what.c_str());
  std::printf("\n");
  std::printf(
      "| integrator | dt (ms) | max depth | mesh | status | tets (end) | peak tets | deepest leaf (tets there) | "
      "cost wall (cpu) s/s | tip err | node RMS err | node max err | tip path err | mean iters | max substeps | "
      "last mesh change (s) |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  for (const auto& p : points) print_point_row(p);
}

namespace {

// `message` with each number in it (12, -0.5, 1.5e-05, and nan or inf, as a
// non-finite energy prints) as "#": two refusals with the same cause then
// read the same. Only whole numbers are masked, not digits within a name
// (explicit_f32, L2): the character before a number is no letter, digit,
// '_' or '.', and the one after it no letter, digit or '_'.
std::string mask_numbers(const std::string& message) {
  static const std::regex number(R"((^|[^\w.])[-+]?(nan|inf|(\d+(\.\d+)?|\.\d+)([eE][-+]?\d+)?)(?!\w))");
  return std::regex_replace(message, number, "$1#");
}

}  // namespace

void print_refusals(const std::vector<SweepPoint>& points) {
  // Grouped by cause, i.e. by the message with its numbers masked: the
  // explicit rung's energy refusal gives each run's energy and budget, and
  // grouped by the whole message every refused run was a group of its own.
  // A group shows its first run's message whole (the advice is at its end).
  struct Group {
    std::string example;
    bool numbers_differ = false;
    std::vector<std::string> runs;
  };
  std::map<std::string, Group> refusals;
  for (const auto& p : points)
    if (!p.st.ok) {
      const std::string who = std::string(p.integrator) + " dt " + format_number("%g", p.dt_s * 1e3) + " ms " +
                              (p.adaptive ? "Th " + format_number("%g", p.th_Pa) + " md " + std::to_string(p.max_depth)
                                          : level_name(p.level)) +
                              (p.skipped ? "" : " at t=" + format_number("%.3g", p.st.error_time_s) + " s");
      auto [it, first] = refusals.try_emplace(mask_numbers(p.st.error));
      Group& group = it->second;
      if (first) group.example = p.st.error;
      group.numbers_differ = group.numbers_differ || p.st.error != group.example;
      if (std::find(group.runs.begin(), group.runs.end(), who) == group.runs.end()) group.runs.push_back(who);
    }
  if (refusals.empty()) return;
  std::printf("\nRefusals / failures:\n");
  for (const auto& [cause, group] : refusals) {
    std::printf("- %s\n  runs%s:", group.example.c_str(),
                group.numbers_differ ? " (the numbers above are the first run's)" : "");
    for (const auto& w : group.runs) std::printf(" [%s]", w.c_str());
    std::printf("\n");
  }
}

namespace {

// Whether uniform point `q` is on p's uniform curve (uniform_curve).
bool on_uniform_curve(const SweepPoint& q, const SweepPoint& p, const std::string& metric) {
  const bool against_truth = metric == "path";
  return !q.adaptive && q.integrator == p.integrator && q.dt_s == p.dt_s && q.max_depth == p.max_depth &&
         (q.level < q.max_depth || against_truth) && std::isfinite(metric_of(q, metric)) && metric_of(q, metric) > 0 &&
         std::isfinite(q.st.cost());
}

}  // namespace

LogCurve uniform_curve(const std::vector<SweepPoint>& points, const SweepPoint& p, const std::string& metric) {
  LogCurve curve;
  for (const auto& q : points)
    if (on_uniform_curve(q, p, metric)) curve.emplace_back(std::log10(q.st.cost()), std::log10(metric_of(q, metric)));
  std::sort(curve.begin(), curve.end());
  return curve;
}

int cheapest_uniform_level(const std::vector<SweepPoint>& points, const SweepPoint& p, const std::string& metric) {
  const SweepPoint* cheapest = nullptr;
  for (const auto& q : points)
    if (on_uniform_curve(q, p, metric) && (!cheapest || q.st.cost() < cheapest->st.cost())) cheapest = &q;
  return cheapest ? cheapest->level : -1;
}

double reference_cost(const std::vector<SweepPoint>& points, const SweepPoint& p) {
  double ref_cost = NAN;
  for (const auto& q : points)
    if (!q.adaptive && q.integrator == p.integrator && q.dt_s == p.dt_s && q.max_depth == p.max_depth &&
        q.level == q.max_depth)
      ref_cost = q.st.ok ? q.st.cost() : NAN;
  return ref_cost;
}

CurveVerdict compare_with_uniform_curve(double cost, double error, const LogCurve& curve, double ref_cost,
                                        int cheapest_level) {
  CurveVerdict v{"n/a", "no uniform curve"};
  if (curve.size() < 2) return v;
  const double lc = std::log10(cost);
  if (lc < curve.front().first) {
    v.uniform_error = "—";
    v.verdict = "cheaper than " + level_name(cheapest_level);
    if (std::log10(error) < curve.front().second) v.verdict += ", and more accurate: below";
  } else if (lc > curve.back().first) {
    v.uniform_error = "—";
    const bool cheaper_than_ref = std::isfinite(ref_cost) && cost < ref_cost;
    v.verdict = std::log10(error) < curve.back().second
                    ? (cheaper_than_ref ? "below (between L(max-1) and the reference in cost)"
                                        : "costs more than the reference itself")
                    : (cheaper_than_ref ? "above (costlier and less accurate than L(max-1))"
                                        : "costs more than the reference itself");
  } else {
    for (std::size_t i = 0; i + 1 < curve.size(); ++i)
      if (lc >= curve[i].first && lc <= curve[i + 1].first) {
        const double w = (lc - curve[i].first) / std::max(curve[i + 1].first - curve[i].first, 1e-12);
        const double le = curve[i].second + w * (curve[i + 1].second - curve[i].second);
        v.uniform_error = percent_text(std::pow(10.0, le));
        v.verdict = std::log10(error) < le
                        ? format_number("below (%.2gx less error)", std::pow(10.0, le - std::log10(error)))
                        : format_number("above (%.2gx more error)", std::pow(10.0, std::log10(error) - le));
        break;
      }
  }
  return v;
}

// Where do the adaptive points lie relative to the uniform curve? Compare
// each adaptive point's error with the uniform curve interpolated (log-log)
// at the same cost.
void print_verdicts(const std::vector<SweepPoint>& points, const std::string& metric) {
  std::printf("\nAdaptive vs uniform curve (%s metric; 'below' = less error than uniform at equal cost):\n\n",
              metric.c_str());
  std::printf("| integrator | dt (ms) | max depth | Th | cost | error | uniform error at that cost | verdict |\n");
  std::printf("|---|---|---|---|---|---|---|---|\n");
  for (const auto& p : points) {
    if (!p.adaptive) continue;
    const double e = metric_of(p, metric), c = p.st.cost();
    if (!(std::isfinite(e) && std::isfinite(c))) continue;
    const CurveVerdict v = compare_with_uniform_curve(c, e, uniform_curve(points, p, metric), reference_cost(points, p),
                                                      cheapest_uniform_level(points, p, metric));
    std::printf("| %s | %g | %d | %g | %.3g | %s | %s | %s |\n", p.integrator.c_str(), p.dt_s * 1e3, p.max_depth,
                p.th_Pa, c, percent_text(e).c_str(), v.uniform_error.c_str(), v.verdict.c_str());
  }
}

}  // namespace tissue::app
