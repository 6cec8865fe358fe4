// What the sweep runs: the scene (built in, or a user's scene file), the
// grid Th x max depth x integrator x dt, the duration and the per-run cap,
// resolved from the options and the scene's own defaults.
//
// The state is the one at the duration (default 0.5 s, quick 0.2 s). The
// damped cantilever is static from ~0.3 s on (errors at 0.3, 0.5 and 1.0 s
// agree to 5 digits), so this is the paper's "at t2" state at half the cost.
// --scene beam: load ramped over the first quarter of the run, mass damping
// alpha = 30/s (first mode about critical), default 1 s (quick 0.5 s).
#pragma once

#include <atomic>
#include <optional>
#include <string>
#include <vector>

#include "app/trade_options.hpp"
#include "app/trade_scenes.hpp"
#include "scene/scene.hpp"

namespace tissue::app {

struct SweepSetup {
  std::string scene;                                           // its name (CSV, plot)
  std::optional<scene::Scene> from_file;                       // --scene-file: the user's scene
  int base_depth = 0;                                          // uniform levels and adaptive runs start here
  std::optional<scene::CgPreconditioner> preconditioner;       // unset: the scene's own
  std::optional<scene::ExplicitPrecision> explicit_precision;  // unset: the scene's own
  double duration_s = 0.0;
  std::vector<double> th_Pa;
  std::vector<int> max_depths;
  std::vector<scene::IntegratorKind> kinds;
  std::vector<double> dts_s;
  double run_cap_s = 0.0;      // per run, on the cost clock (wall, or thread CPU time with --clock cpu)
  bool cost_uses_cpu = false;  // --clock cpu: costs, the cap and the plot's axis in thread CPU time
  // Read before every step: a signal number there ends the sweep (the run in
  // progress is marked interrupted, the rest are not run).
  const std::atomic<int>* stop = nullptr;
  bool stopped() const { return stop && *stop != 0; }
  // One of the built-in beams (not a scene file that happens to be named so).
  bool is_builtin_beam() const { return !from_file && (scene == "beam" || scene == "beam-r"); }
};

// The sweep `o` asks for. Loads --scene-file (with --set); throws
// std::invalid_argument for a scene that does not load, an unknown
// integrator or a max depth at or below the scene's min depth.
SweepSetup make_sweep_setup(const TradeOptions& o, const std::atomic<int>* stop);

// The scene of one run: the setup's scene with mesh `m`, integrator `kind`
// and step dt_s.
scene::Scene sweep_scene(const SweepSetup& s, const MeshChoice& m, scene::IntegratorKind kind, double dt_s);

}  // namespace tissue::app
