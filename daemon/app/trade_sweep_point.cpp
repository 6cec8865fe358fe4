#include "app/trade_sweep_point.hpp"

#include "app/trade_format.hpp"
#include "app/trade_scenes.hpp"

namespace tissue::app {

namespace ph = tissue::physics;

std::string SweepPoint::status() const {
  if (skipped) return "skipped";
  if (st.interrupted_by != 0) return "interrupted";
  if (!st.ok) return "failed";
  if (st.capped) return "capped";
  return "ok";
}

long path_stride(long steps) { return steps <= kMaxPathSamples ? 1 : (steps + kMaxPathSamples - 1) / kMaxPathSamples; }

bool is_path_sample(long step, long steps) { return step % path_stride(steps) == 0 || step == steps; }

SweepPoint not_run_point(scene::IntegratorKind kind, double dt_s, const std::string& reason) {
  SweepPoint p;
  p.integrator = integrator_name(kind);
  p.dt_s = dt_s;
  p.skipped = true;
  p.st.ok = false;
  p.st.error = reason;
  return p;
}

void fill_errors(SweepPoint& p, const SweepPoint& ref) {
  if (!p.captured || !ref.captured) return;
  p.tip_err = (p.tip - ref.tip).norm() / ref.tip.norm();
  const ph::FieldError fe = ph::compare_displacement_fields(ref.field, p.field);
  p.rms_err = fe.rms_rel;
  p.max_err = fe.max_rel;
  p.unlocated = fe.unlocated;
  p.has_error = true;
}

std::map<int, std::string> set_path_errors(std::vector<SweepPoint>& points) {
  std::map<int, const SweepPoint*> truth;
  const auto rank = [](const SweepPoint& p) {
    return p.integrator == "explicit" ? 0 : p.integrator == "implicit" ? 1 : 2;
  };
  for (const SweepPoint& p : points) {
    if (p.adaptive || p.level != p.max_depth || !p.st.ok || p.st.capped || p.tip_path_m.empty()) continue;
    const SweepPoint*& best = truth[p.max_depth];
    if (!best || rank(p) < rank(*best) || (rank(p) == rank(*best) && p.dt_s < best->dt_s)) best = &p;
  }
  std::map<int, std::string> described;
  for (const auto& [md, t] : truth)
    described[md] =
        t ? t->integrator + " at dt " + format_number("%g", t->dt_s * 1e3) + " ms, uniform L" + std::to_string(md)
          : std::string();
  for (SweepPoint& p : points) {
    const auto it = truth.find(p.max_depth);
    if (it == truth.end() || !it->second || !p.st.ok || p.st.capped || p.tip_path_m.empty()) continue;
    p.path_err = ph::compare_trajectories(it->second->tip_t_s, it->second->tip_path_m, p.tip_t_s, p.tip_path_m).rms_rel;
  }
  return described;
}

double metric_of(const SweepPoint& p, const std::string& metric) {
  if (metric == "tip") return p.tip_err;
  if (metric == "path") return p.path_err;
  if (metric == "max") return p.max_err;
  return p.rms_err;
}

}  // namespace tissue::app
