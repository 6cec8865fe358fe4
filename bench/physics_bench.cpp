// Integrator cost per spring per step, beside a memory-bandwidth bound that
// the same benchmark measures on the same number of bytes (PERFORMANCE.md:
// compare as ratios measured in one run, never absolute times).
//
// Meshes: PERFORMANCE.md's 0.4 x 0.1 x 0.1 m beam made of cubes (12x3x3 cubes
// of 1/30 m) refined uniformly 0, 3, 6, 9 levels: 10^3 .. 10^6 springs.
//
// bound_ns_per_spring: the bytes one explicit sub-step must move at least
// (per spring: 2 node ids, rest length, stiffness, damping = 32 B; per node:
// x, v read and written, force written and read, inverse mass = 152 B)
// divided by the bandwidth of a triad over buffers of that total size.
#include <benchmark/benchmark.h>

#include <chrono>
#include <vector>

#include "physics/boundary.hpp"
#include "physics/forces.hpp"
#include "physics/integrator.hpp"
#include "physics/simulation.hpp"

namespace {

using namespace tissue;

scene::Scene beam(int level, scene::IntegratorKind kind) {
  scene::Scene s;
  s.object.cubes = {12, 3, 3};
  s.object.cube_size_m = 0.4 / 12;
  s.adaptivity.min_depth = level;
  s.fixed.push_back({scene::Region::box({0, 0, 0}, {0, 0.1, 0.1})});
  s.loads.push_back({"tip", scene::Region::box({0.4, 0, 0}, {0.4, 0.1, 0.1}), {0, 0, -0.05}, {}});
  s.integrator.kind = kind;
  s.integrator.dt_s = 1e-3;
  return s;
}

// Triad a = b + s c over `bytes` in total; returns bytes per ns.
double measured_bandwidth_bytes_per_ns(std::size_t bytes) {
  const std::size_t n = std::max<std::size_t>(1024, bytes / (3 * sizeof(double)));
  std::vector<double> a(n, 0.0), b(n, 1.0), c(n, 2.0);
  double best = 0.0;
  for (int rep = 0; rep < 5; ++rep) {
    const auto t0 = std::chrono::steady_clock::now();
    for (std::size_t i = 0; i < n; ++i) a[i] = b[i] + 0.5 * c[i];
    const double ns = std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - t0).count();
    benchmark::DoNotOptimize(a.data());
    best = std::max(best, 3.0 * n * sizeof(double) / ns);
  }
  return best;
}

void report(benchmark::State& state, const physics::Body& body, double ns_per_call, double bound_ns_per_spring) {
  const double springs = static_cast<double>(body.mesh().edge_count());
  state.counters["nodes"] = static_cast<double>(body.mesh().node_count());
  state.counters["springs"] = springs;
  state.counters["ns_per_spring"] = ns_per_call / springs;
  state.counters["bound_ns_per_spring"] = bound_ns_per_spring;
  state.counters["x_bound"] = ns_per_call / springs / bound_ns_per_spring;
}

double bound_ns_per_spring(const physics::Body& body) {
  const double springs = static_cast<double>(body.mesh().edge_count());
  const double bytes = 32.0 * springs + 152.0 * static_cast<double>(body.mesh().node_count());
  return bytes / measured_bandwidth_bytes_per_ns(static_cast<std::size_t>(bytes)) / springs;
}

// One explicit sub-step: spring forces, then velocity and position update.
void BM_ExplicitSubstep(benchmark::State& state) {
  physics::Simulation sim(beam(static_cast<int>(state.range(0)), scene::IntegratorKind::kExplicit));
  physics::Body& body = sim.mutable_body();
  std::vector<physics::Vec3> f(body.x_m.size());
  const double h = 1e-5;
  const double bound = bound_ns_per_spring(body);
  double total_ns = 0;
  for (auto _ : state) {
    const auto t0 = std::chrono::steady_clock::now();
    std::fill(f.begin(), f.end(), physics::Vec3::Zero());
    physics::add_spring_forces(body, f);
    for (std::size_t n = 0; n < f.size(); ++n) {
      body.v_m_per_s[n] += h * body.inv_mass_per_kg[n] * f[n];
      body.x_m[n] += h * body.v_m_per_s[n];
    }
    total_ns += std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - t0).count();
    benchmark::DoNotOptimize(body.x_m.data());
  }
  report(state, body, total_ns / static_cast<double>(state.iterations()), bound);
}

// Whole steps of each rung at dt = 1 ms (explicit includes its sub-steps).
void BM_Step(benchmark::State& state, scene::IntegratorKind kind, int fixed_cg_iterations) {
  scene::Scene s = beam(static_cast<int>(state.range(0)), kind);
  if (fixed_cg_iterations > 0) {
    s.integrator.cg_tolerance = 1e-300;  // run exactly the cap: cost per iteration is comparable
    s.integrator.cg_max_iterations = fixed_cg_iterations;
  }
  s.integrator.max_substeps = 1000000;
  physics::Simulation sim(s);
  sim.step();  // factorisation / bounds happen once, outside the timing
  const double bound = bound_ns_per_spring(sim.body());
  double total_ns = 0;
  int substeps = 0;
  for (auto _ : state) {
    const auto t0 = std::chrono::steady_clock::now();
    const physics::StepResult r = sim.step();
    total_ns += std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - t0).count();
    substeps = r.substeps;
    if (!r.ok) state.SkipWithError(r.error.c_str());
  }
  report(state, sim.body(), total_ns / static_cast<double>(state.iterations()), bound);
  state.counters["substeps"] = substeps;
  state.counters["ms_per_step"] = total_ns / static_cast<double>(state.iterations()) * 1e-6;
}

// The paper's adaptive cantilever under load: share of the step time spent
// in adaptation at the default cadence (every 5 steps).
void BM_AdaptationShare(benchmark::State& state) {
  scene::Scene s;
  s.object.cubes = {4, 4, 4};
  s.object.cube_size_m = 0.025;
  s.material.rayleigh_beta_s = 0.003;
  s.fixed.push_back({scene::Region::box({0, 0, 0}, {0, 0.1, 0.1})});
  s.loads.push_back({"tip", scene::Region::box({0.1, 0, 0}, {0.1, 0.1, 0.1}), {0, 0, -5}, {}});
  s.adaptivity.enabled = true;
  s.adaptivity.refine_threshold_Pa = 20;
  s.adaptivity.max_depth = 3;
  double with_ns = 0, without_ns = 0;
  for (auto _ : state) {
    for (bool adaptive : {true, false}) {
      s.adaptivity.every_steps = adaptive ? 5 : 1000000000;
      physics::Simulation sim(s);
      // Same mesh for both: let the adaptive run refine first, then time
      // 500 steps; the non-adaptive run is timed on the mesh it starts with,
      // so compare per spring.
      for (int i = 0; i < 200; ++i) sim.step();
      const auto t0 = std::chrono::steady_clock::now();
      for (int i = 0; i < 500; ++i) sim.step();
      const double ns = std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - t0).count() /
                        static_cast<double>(sim.body().mesh().edge_count());
      (adaptive ? with_ns : without_ns) += ns;
    }
  }
  state.counters["adaptation_share"] = (with_ns - without_ns) / with_ns;
}

}  // namespace

BENCHMARK(BM_ExplicitSubstep)->Arg(0)->Arg(3)->Arg(6)->Arg(9)->Iterations(20)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Step, explicit, scene::IntegratorKind::kExplicit, 0)
    ->Arg(0)
    ->Arg(3)
    ->Arg(6)
    ->Iterations(3)
    ->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Step, implicit_cg20, scene::IntegratorKind::kImplicit, 20)
    ->Arg(0)
    ->Arg(3)
    ->Arg(6)
    ->Arg(9)
    ->Iterations(5)
    ->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Step, implicit_tol1e6, scene::IntegratorKind::kImplicit, 0)
    ->Arg(0)
    ->Arg(3)
    ->Arg(6)
    ->Iterations(20)
    ->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Step, projective, scene::IntegratorKind::kProjective, 0)
    ->Arg(0)
    ->Arg(3)
    ->Arg(6)
    ->Iterations(5)
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_AdaptationShare)->Iterations(1)->Unit(benchmark::kMillisecond);
BENCHMARK_MAIN();
