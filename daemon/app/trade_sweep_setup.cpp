#include "app/trade_sweep_setup.hpp"

#include <cmath>
#include <limits>
#include <stdexcept>

#include "scene/scene_names.hpp"
#include "scene/scene_yaml.hpp"

namespace tissue::app {

namespace sc = tissue::scene;

namespace {

// --preconditioner and --explicit-precision, or the built-in scenes'
// defaults (jacobi, double, as the README's tables); a scene file keeps its own.
void set_solver_choices(const TradeOptions& o, SweepSetup& s) {
  const std::string preconditioner = !o.preconditioner.empty() ? o.preconditioner : s.from_file ? "" : "jacobi";
  if (!preconditioner.empty())
    s.preconditioner = sc::value_named(sc::kCgPreconditionerNames, preconditioner).value();  // checked by the options
  const std::string precision = !o.explicit_precision.empty() ? o.explicit_precision : s.from_file ? "" : "double";
  if (!precision.empty()) s.explicit_precision = sc::value_named(sc::kExplicitPrecisionNames, precision).value();
}

// --th, or thresholds around the scene file's own, or the built-in scene's list.
std::vector<double> default_thresholds_Pa(const TradeOptions& o, const SweepSetup& s) {
  if (!o.th_Pa.empty()) return o.th_Pa;
  if (s.from_file) {  // around the scene's own threshold
    const double th = s.from_file->adaptivity.refine_threshold_Pa;
    return o.quick ? std::vector<double>{th, 4 * th} : std::vector<double>{0.25 * th, th, 4 * th};
  }
  if (s.is_builtin_beam())
    return o.quick ? std::vector<double>{0.01, 0.1} : std::vector<double>{0.003, 0.01, 0.03, 0.1, 0.3};
  return o.quick ? std::vector<double>{5, 20, 80} : std::vector<double>{5, 20, 40, 80, 300};
}

// --depths, or the scene file's max depth, or {3, 6} (quick {3}); each must
// leave something to refine above the base depth.
std::vector<int> checked_max_depths(const TradeOptions& o, const SweepSetup& s) {
  std::vector<int> depths;
  if (!o.max_depths.empty())
    depths = o.max_depths;
  else if (s.from_file)
    depths = {s.from_file->adaptivity.max_depth};
  else
    depths = o.quick ? std::vector<int>{3} : std::vector<int>{3, 6};
  for (const int md : depths)
    if (md <= s.base_depth)
      throw std::invalid_argument("max depth " + std::to_string(md) + " leaves nothing to refine above the scene's " +
                                  "adaptivity.min_depth " + std::to_string(s.base_depth) +
                                  " (give --depths above it, or raise the scene's adaptivity.max_depth)");
  return depths;
}

std::vector<sc::IntegratorKind> integrator_kinds(const TradeOptions& o) {
  if (o.integrators.empty())
    return {sc::IntegratorKind::kImplicit, sc::IntegratorKind::kExplicit, sc::IntegratorKind::kProjective};
  std::vector<sc::IntegratorKind> kinds;
  for (const auto& k : o.integrators) kinds.push_back(integrator_kind(k));
  return kinds;
}

std::vector<double> default_dts_s(const TradeOptions& o, const SweepSetup& s) {
  if (!o.dts_s.empty()) return o.dts_s;
  if (s.from_file) return {s.from_file->integrator.dt_s};
  return {1e-3, 5e-3};
}

// Every run the sweep would make, checked before the first: its scene as
// the scene checks say (--dts 1e-300 or 5, or --depths whose uniform levels
// exceed the mesh budget, ran as zero-step "ok" points or ran out of memory),
// and its step count (at least one, at most 1e8).
void check_runs(const SweepSetup& s) {
  constexpr double kMaxSteps = 1e8;
  for (const double dt : s.dts_s) {
    const double steps = std::round(s.duration_s / dt);
    if (!(steps >= 1.0 && steps <= kMaxSteps))
      throw std::invalid_argument("--dts " + yaml_util::fmt_num(dt) + ": a run of " + yaml_util::fmt_num(s.duration_s) +
                                  " s would take " + yaml_util::fmt_num(steps) + " steps (must be 1 to 1e8)");
    for (const sc::IntegratorKind kind : s.kinds)
      for (const int md : s.max_depths) {
        std::vector<MeshChoice> meshes;
        for (int level = s.base_depth; level <= md; ++level) meshes.push_back({false, level, 0.0, level});
        for (const double th : s.th_Pa) meshes.push_back({true, 0, th, md});
        for (const MeshChoice& m : meshes) {
          try {
            sc::validate_scene(sweep_scene(s, m, kind, dt));
          } catch (const sc::SceneError& e) {
            throw std::invalid_argument(std::string("the sweep's ") + (m.adaptive ? "adaptive" : "uniform") +
                                        " run at depth " + std::to_string(m.adaptive ? m.max_depth : m.depth) +
                                        ", dt " + yaml_util::fmt_num(dt) + " s: " + e.reason() + " (" + e.key_path() +
                                        ")");
          }
        }
      }
  }
}

}  // namespace

SweepSetup make_sweep_setup(const TradeOptions& o, const std::atomic<int>* stop) {
  SweepSetup s;
  s.scene = o.sweep_scene;
  s.cost_uses_cpu = o.cpu_clock;
  s.stop = stop;
  if (!o.scene_file.empty()) {
    s.from_file = sc::load_scene_file_with_overrides(o.scene_file, o.scene_overrides);
    s.scene = s.from_file->name;
    s.base_depth = s.from_file->adaptivity.min_depth;
  }
  set_solver_choices(o, s);
  const bool is_beam = s.is_builtin_beam();
  s.duration_s = o.sweep_duration_s > 0 ? o.sweep_duration_s : is_beam ? (o.quick ? 0.5 : 1.0) : (o.quick ? 0.2 : 0.5);
  s.th_Pa = default_thresholds_Pa(o, s);
  s.max_depths = checked_max_depths(o, s);
  s.kinds = integrator_kinds(o);
  s.dts_s = default_dts_s(o, s);
  s.run_cap_s = o.run_cap_s > 0 ? o.run_cap_s : (o.quick ? 3.0 : 30.0);
  check_runs(s);
  return s;
}

sc::Scene sweep_scene(const SweepSetup& s, const MeshChoice& m, sc::IntegratorKind kind, double dt_s) {
  sc::Scene out;
  if (s.from_file) {
    // The user's scene as it is, but for what each run of the sweep sets.
    out = *s.from_file;
    apply_mesh(out, m);
    if (m.adaptive) out.adaptivity.min_depth = s.base_depth;
    out.integrator.kind = kind;
    out.integrator.dt_s = dt_s;
  } else if (s.scene == "beam" || s.scene == "beam-r") {
    // Static-ish: ramp the load over a quarter of the run and damp the first
    // bending mode (2.3 Hz) about critically with mass-proportional damping.
    out = performance_beam(m, kind, dt_s, 0.25 * s.duration_s, s.scene == "beam-r");
    out.material.rayleigh_alpha_per_s = 30.0;
  } else {
    out = paper_cantilever(m, kind, dt_s, std::numeric_limits<double>::infinity());
  }
  if (s.preconditioner) out.integrator.cg_preconditioner = *s.preconditioner;
  if (s.explicit_precision) out.integrator.explicit_precision = *s.explicit_precision;
  return out;
}

}  // namespace tissue::app
