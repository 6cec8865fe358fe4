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
// divided by the bandwidth of a triad over buffers of that total size. It
// counts unpadded 3-vectors and no external force, so it is below what the
// integrator's padded layout really moves (232 B per node): a strict bound.
// The triad is counted as STREAM counts it (3 x 8 B per element, not the
// write-allocate read), which makes the bandwidth lower and the bound looser
// by up to 4/3; at L1/L2-resident sizes it is the cache's bandwidth.
#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <ctime>
#include <memory>
#include <string>
#include <vector>

#include "bench_timing.hpp"
#include "physics/boundary.hpp"
#include "physics/contact_stiffness.hpp"
#include "physics/forces.hpp"
#include "physics/frequency_estimate.hpp"
#include "physics/integrator.hpp"
#include "physics/integrator_impl.hpp"
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

// spring_bytes: 32 with dampers; 24 without (no damping coefficient to read).
// Single precision (explicit_precision: float): 32 / 28 B per spring (ids,
// rest edge vector, rest length, stiffness, damping) and half the node
// bytes, 76.
double bound_ns_per_spring(const physics::Body& body, double spring_bytes = 32.0, double node_bytes = 152.0) {
  const double springs = static_cast<double>(body.mesh().edge_count());
  const double bytes = spring_bytes * springs + node_bytes * static_cast<double>(body.mesh().node_count());
  return bytes / measured_bandwidth_bytes_per_ns(static_cast<std::size_t>(bytes)) / springs;
}

// One explicit sub-step as the integrator runs it (ExplicitIntegrator::
// run_substeps: spring forces from the compact stream, then the fused
// velocity/position update that also resets the force accumulator), timed
// over kSubsteps sub-steps so the copy of the state into and out of the
// integrator's padded arrays (once per step) is amortised as in a real step
// (a 1 ms step at R3 takes 5-6 sub-steps undamped). Second argument 1 times
// the code this replaced instead: add_spring_forces + a plain update loop.
// Third argument 1: springs without dampers (Rayleigh beta = 0, the undamped
// kernels), against the bound for 24 B per spring (no damping coefficient).
// Fourth: explicit_precision float. Fifth argument 1: the gathered stream
// forced where the integrator would take the offset layout, 2: the offset
// layout forced where it would not (counter `offset`: which one ran, `fill`:
// its share of filled lanes; the bound is on the bytes of the one that ran).
void BM_ExplicitSubstep(benchmark::State& state) {
  constexpr int kSubsteps = 10;
  scene::Scene scene = beam(static_cast<int>(state.range(0)), scene::IntegratorKind::kExplicit);
  const bool undamped = state.range(2) == 1;
  if (undamped) scene.material.rayleigh_beta_s = 0.0;
  const bool single = state.range(3) == 1;
  if (single) scene.integrator.explicit_precision = scene::ExplicitPrecision::kFloat;
  physics::Simulation sim(scene);
  physics::Body& body = sim.mutable_body();
  std::vector<physics::Vec3> f(body.x_m.size());
  // Half the stable sub-step: a fixed h would be unstable from depth 10 on,
  // and the exploding state would time the kernel's non-finite fallback.
  const double h = 0.5 * physics::explicit_stable_dt_s(body);
  physics::ExplicitIntegrator integrator(sim.scene().integrator, sim.scene().material);
  if (state.range(4) == 1) integrator.set_layout(physics::ExplicitIntegrator::Layout::kGathered);
  if (state.range(4) == 2) integrator.set_layout(physics::ExplicitIntegrator::Layout::kOffset);
  const std::vector<physics::Vec3> no_force(body.x_m.size(), physics::Vec3::Zero());
  integrator.run_substeps(body, no_force, h, 1);  // builds the spring stream once, outside the timing
  // The bound on the bytes of the stream in use: the offset layout reads no
  // node ids (its own bytes per spring, empty lanes included). The old code
  // (second argument 1) never runs the integrator's layout: it reads the
  // body's gathered double stream (the 32 / 152 B of the header), whichever
  // layout the integrator took, and its rows say offset 0, fill 0.
  const bool old_code = state.range(1) == 1;
  const bool offset_ran = !old_code && integrator.offset_layout();
  const bool single_ran = single && !old_code;
  const double spring_bytes = offset_ran ? integrator.offset_stream_bytes_per_spring()
                                         : (single_ran ? (undamped ? 28.0 : 32.0) : (undamped ? 24.0 : 32.0));
  const double bound = bound_ns_per_spring(body, spring_bytes, single_ran ? 76.0 : 152.0);
  state.counters["offset"] = offset_ran ? 1.0 : 0.0;
  state.counters["fill"] = old_code ? 0.0 : physics::plan_offset_layout(body, single ? 8 : 4).fill;
  state.counters["stream_B"] = spring_bytes;
  std::vector<double> per_substep_ns;
  for (auto _ : state) {
    const auto t0 = std::chrono::steady_clock::now();
    if (!old_code) {
      integrator.run_substeps(body, no_force, h, kSubsteps);
    } else {
      for (int s = 0; s < kSubsteps; ++s) {
        std::fill(f.begin(), f.end(), physics::Vec3::Zero());
        physics::add_spring_forces(body, f);
        for (std::size_t n = 0; n < f.size(); ++n) {
          body.v_m_per_s[n] += h * body.inv_mass_per_kg[n] * f[n];
          body.x_m[n] += h * body.v_m_per_s[n];
        }
      }
    }
    per_substep_ns.push_back(std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - t0).count() /
                             kSubsteps);
    benchmark::DoNotOptimize(body.x_m.data());
  }
  if (!physics::state_is_finite(body)) state.SkipWithError("state became non-finite: the timing is not valid");
  std::sort(per_substep_ns.begin(), per_substep_ns.end());
  report(state, body, per_substep_ns[per_substep_ns.size() / 2], bound);  // median
  state.counters["h_us"] = h * 1e6;
}

// What taking the offset layout costs when a mesh of one depth is built (or
// merges back to one depth): plan_offset_layout for W = 4 (double, the
// default), per spring, and in explicit sub-steps of the same mesh
// (`plan_vs_substep`, timed as BM_ExplicitSubstep on the integrator's own
// stream).
void BM_OffsetPlan(benchmark::State& state) {
  physics::Simulation sim(beam(static_cast<int>(state.range(0)), scene::IntegratorKind::kExplicit));
  physics::Body& body = sim.mutable_body();
  double fill = 0.0;
  std::vector<double> plan_ns;
  for (auto _ : state) {
    const double t0 = bench::thread_cpu_ns();
    const physics::OffsetPlan plan = physics::plan_offset_layout(body, 4);
    plan_ns.push_back(bench::thread_cpu_ns() - t0);
    fill = plan.fill;
    benchmark::DoNotOptimize(plan.batches.data());
  }
  physics::ExplicitIntegrator integrator(sim.scene().integrator, sim.scene().material);
  const std::vector<physics::Vec3> no_force(body.x_m.size(), physics::Vec3::Zero());
  const double h = 0.5 * physics::explicit_stable_dt_s(body);
  integrator.run_substeps(body, no_force, h, 1);
  std::vector<double> substep_ns;
  for (int round = 0; round < 5; ++round) {
    const double t0 = bench::thread_cpu_ns();
    integrator.run_substeps(body, no_force, h, 10);
    substep_ns.push_back((bench::thread_cpu_ns() - t0) / 10.0);
  }
  const double springs = static_cast<double>(body.mesh().edge_count());
  const double plan = bench::median(plan_ns);
  state.counters["springs"] = springs;
  state.counters["fill_w4"] = fill;
  state.counters["plan_ms"] = plan * 1e-6;
  state.counters["plan_ns_per_spring"] = plan / springs;
  state.counters["plan_vs_substep"] = plan / bench::median(substep_ns);
}

// The explicit rung's Lanczos bound (frequency_estimate.hpp) on the beam at
// a depth: its cost against the explicit sub-step it is amortised over
// (alternating rounds; `iteration_vs_substep` sets
// ExplicitIntegrator::kLanczosIterationCost), and what it buys: the stable
// sub-step with it over the guaranteed one, undamped (`undamped_dt_gain`) and
// with the beam's Rayleigh beta = 0.01 s (`damped_dt_gain`), and how close
// the Ritz value is to its bound.
void BM_FrequencyEstimate(benchmark::State& state) {
  constexpr int kSubsteps = 10;
  scene::Scene scene = beam(static_cast<int>(state.range(0)), scene::IntegratorKind::kExplicit);
  physics::Simulation sim(scene);
  physics::Body& body = sim.mutable_body();
  const double h = 0.5 * physics::explicit_stable_dt_s(body);
  physics::ExplicitIntegrator integrator(sim.scene().integrator, sim.scene().material);
  const std::vector<physics::Vec3> no_force(body.x_m.size(), physics::Vec3::Zero());
  integrator.run_substeps(body, no_force, h, 1);
  std::vector<double> estimate_ns, substep_ns;
  physics::FrequencyEstimate estimate;
  for (auto _ : state) {
    double c0 = bench::thread_cpu_ns();
    estimate = physics::rest_frequency2_estimate(body);
    estimate_ns.push_back(bench::thread_cpu_ns() - c0);
    c0 = bench::thread_cpu_ns();
    integrator.run_substeps(body, no_force, h, kSubsteps);
    substep_ns.push_back((bench::thread_cpu_ns() - c0) / kSubsteps);
  }
  const double estimate_median = bench::median(estimate_ns), substep_median = bench::median(substep_ns);
  const physics::ExplicitStableStep guaranteed = physics::explicit_stable_step(body);
  const physics::ExplicitStableStep tight = physics::explicit_stable_step(body, estimate.bound_per_s2);
  state.counters["springs"] = static_cast<double>(body.mesh().edge_count());
  state.counters["iterations"] = estimate.iterations;
  state.counters["estimate_ms"] = estimate_median * 1e-6;
  state.counters["iteration_vs_substep"] = estimate_median / estimate.iterations / substep_median;
  state.counters["undamped_dt_gain"] = tight.undamped_dt_s / guaranteed.undamped_dt_s;
  state.counters["damped_dt_gain"] = tight.dt_s / guaranteed.dt_s;
  state.counters["ritz_vs_bound"] = estimate.ritz_per_s2 / estimate.bound_per_s2;
}

#if defined(__x86_64__)
// The memory-access floor of the explicit sub-step: the integrator's own
// spring stream and padded node layout, every load and store the kernel
// makes (both ends' x and v, f[a] += F and f[b] −= F, then the node update),
// but a linear force F = k Δx + c Δv: no length, square root, division or
// lane sums. No kernel that reads this stream and scatters per spring can
// beat it, so its x_bound says how close to the bandwidth bound this data
// layout can come at each size. (Benchmark only: not a physical law.)
TISSUE_AVX2 void access_floor_substep(const std::vector<physics::ExplicitSpringBatch>& stream, double h,
                                      const double* inv_mass, physics::Pad3* x_pad, physics::Pad3* v_pad,
                                      physics::Pad3* f_pad, std::size_t nodes) {
  const double* x = x_pad[0].v;
  const double* v = v_pad[0].v;
  double* f = f_pad[0].v;
  for (const physics::ExplicitSpringBatch& s : stream) {
    for (int j = 0; j < 4; ++j) {
      const std::uint32_t a4 = s.a4[j], b4 = s.b4[j];
      const __m256d dx = _mm256_sub_pd(_mm256_load_pd(x + b4), _mm256_load_pd(x + a4));
      const __m256d dv = _mm256_sub_pd(_mm256_load_pd(v + b4), _mm256_load_pd(v + a4));
      const __m256d force = _mm256_add_pd(_mm256_mul_pd(_mm256_broadcast_sd(s.k_N_per_m + j), dx),
                                          _mm256_mul_pd(_mm256_broadcast_sd(s.c_N_s_per_m + j), dv));
      _mm256_store_pd(f + a4, _mm256_add_pd(_mm256_load_pd(f + a4), force));
      _mm256_store_pd(f + b4, _mm256_sub_pd(_mm256_load_pd(f + b4), force));
    }
  }
  const __m256d hv = _mm256_set1_pd(h);
  for (std::size_t i = 0; i < nodes; ++i) {
    const __m256d vi = _mm256_add_pd(_mm256_load_pd(v_pad[i].v),
                                     _mm256_mul_pd(_mm256_set1_pd(h * inv_mass[i]), _mm256_load_pd(f_pad[i].v)));
    _mm256_store_pd(v_pad[i].v, vi);
    _mm256_store_pd(x_pad[i].v, _mm256_add_pd(_mm256_load_pd(x_pad[i].v), _mm256_mul_pd(hv, vi)));
    _mm256_store_pd(f_pad[i].v, _mm256_setzero_pd());
  }
}

// Args: depth. Same timing as BM_ExplicitSubstep (median of 10-sub-step
// rounds); floor_vs_kernel is this floor over the shipped kernel timed
// alternately in the same benchmark.
void BM_ExplicitAccessFloor(benchmark::State& state) {
  if (physics::detected_simd() != physics::Simd::kAvx2) {
    state.SkipWithError("needs AVX2");
    return;
  }
  constexpr int kSubsteps = 10;
  physics::Simulation sim(beam(static_cast<int>(state.range(0)), scene::IntegratorKind::kExplicit));
  physics::Body& body = sim.mutable_body();
  const std::size_t nodes = body.x_m.size();
  const double h = 0.5 * physics::explicit_stable_dt_s(body);
  const double bound = bound_ns_per_spring(body);
  physics::ExplicitIntegrator integrator(sim.scene().integrator, sim.scene().material);
  integrator.set_layout(physics::ExplicitIntegrator::Layout::kGathered);  // the floor of the gathered stream
  const std::vector<physics::Vec3> no_force(nodes, physics::Vec3::Zero());
  integrator.run_substeps(body, no_force, h, 1);
  // The floor's own state (pad nodes included), tiny velocities so the
  // linear force stays finite and small over the run.
  std::vector<physics::Pad3> x(nodes + 2), v(nodes + 2), f(nodes + 2);
  std::vector<double> inv_mass(nodes + 2, 0.0);
  for (std::size_t n = 0; n < nodes; ++n) {
    x[n] = physics::Pad3{{body.x_m[n].x(), body.x_m[n].y(), body.x_m[n].z(), 0.0}};
    inv_mass[n] = body.inv_mass_per_kg[n];
  }
  std::vector<double> floor_ns, kernel_ns;
  for (auto _ : state) {
    auto t0 = std::chrono::steady_clock::now();
    for (int s = 0; s < kSubsteps; ++s)
      access_floor_substep(integrator.spring_stream(), h, inv_mass.data(), x.data(), v.data(), f.data(), nodes);
    floor_ns.push_back(std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - t0).count() /
                       kSubsteps);
    benchmark::DoNotOptimize(x.data());
    t0 = std::chrono::steady_clock::now();
    integrator.run_substeps(body, no_force, h, kSubsteps);
    kernel_ns.push_back(std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - t0).count() /
                        kSubsteps);
    benchmark::DoNotOptimize(body.x_m.data());
  }
  bool finite = physics::state_is_finite(body);
  for (std::size_t n = 0; n < nodes; ++n)
    for (int k = 0; k < 4; ++k) finite = finite && std::isfinite(x[n].v[k]) && std::isfinite(v[n].v[k]);
  if (!finite) state.SkipWithError("state became non-finite: the timing is not valid");
  const double floor = bench::median(floor_ns), kernel = bench::median(kernel_ns);
  report(state, body, floor, bound);
  state.counters["kernel_x_bound"] = kernel / static_cast<double>(body.mesh().edge_count()) / bound;
  state.counters["floor_vs_kernel"] = floor / kernel;
}

// The divider floor of the explicit sub-step: the square roots and divisions
// the shipped offset kernels issue per spring, with nothing else — no loads,
// no stores, no other arithmetic. Double: one square root and one division
// per 4 springs (1/l, then multiplications); float: one square root and two
// divisions per 8 springs, three with dampers (integrator_explicit_offset.cpp).
// Eight independent chains, so the divider's throughput is timed, not its
// latency. A kernel that computes each spring's length and force exactly
// (IEEE square root and division, as the bit-identity across instruction
// sets needs) cannot run faster than this. Args: depth (for the spring count
// and the bound beside it), precision (0 double, 1 float), dampers (0, 1).
// Timed alternately with the shipped sub-step on the same mesh (damped and
// precision as asked): divider_x_bound, kernel_x_bound, divider_vs_kernel.
TISSUE_AVX2 double divider_floor_double(std::size_t springs, double seed) {
  __m256d l2[8], acc[8];
  for (int c = 0; c < 8; ++c) {
    l2[c] = _mm256_set_pd(seed + c, seed + 0.1 + c, seed + 0.2 + c, seed + 0.3 + c);
    acc[c] = _mm256_setzero_pd();
  }
  const __m256d one = _mm256_set1_pd(1.0), tiny = _mm256_set1_pd(1e-12);
  for (std::size_t i = 0; i < springs; i += 32) {
    for (int c = 0; c < 8; ++c) {
      const __m256d inv = _mm256_div_pd(one, _mm256_sqrt_pd(l2[c]));
      acc[c] = _mm256_add_pd(acc[c], inv);
      l2[c] = _mm256_add_pd(l2[c], tiny);  // new operands each round
    }
  }
  double sum = 0.0;
  for (int c = 0; c < 8; ++c) sum += _mm256_cvtsd_f64(acc[c]);
  return sum;
}

TISSUE_AVX2 double divider_floor_float(std::size_t springs, bool damped, double seed) {
  __m256 l2[8], acc[8];
  for (int c = 0; c < 8; ++c) {
    l2[c] = _mm256_set1_ps(static_cast<float>(seed) + 0.1f * static_cast<float>(c));
    acc[c] = _mm256_setzero_ps();
  }
  const __m256 rest = _mm256_set1_ps(0.9f), tiny = _mm256_set1_ps(1e-6f);
  for (std::size_t i = 0; i < springs; i += 64) {
    for (int c = 0; c < 8; ++c) {
      const __m256 l = _mm256_sqrt_ps(l2[c]);
      __m256 along = _mm256_div_ps(l2[c], _mm256_add_ps(l, rest));
      if (damped) along = _mm256_add_ps(along, _mm256_div_ps(rest, l));
      acc[c] = _mm256_add_ps(acc[c], _mm256_div_ps(along, l));
      l2[c] = _mm256_add_ps(l2[c], tiny);
    }
  }
  double sum = 0.0;
  for (int c = 0; c < 8; ++c) sum += _mm256_cvtss_f32(acc[c]);
  return sum;
}

void BM_ExplicitDividerFloor(benchmark::State& state) {
  if (physics::detected_simd() != physics::Simd::kAvx2) {
    state.SkipWithError("needs AVX2");
    return;
  }
  constexpr int kSubsteps = 10;
  const bool single = state.range(1) == 1, damped = state.range(2) == 1;
  scene::Scene scene = beam(static_cast<int>(state.range(0)), scene::IntegratorKind::kExplicit);
  if (!damped) scene.material.rayleigh_beta_s = 0.0;
  if (single) scene.integrator.explicit_precision = scene::ExplicitPrecision::kFloat;
  physics::Simulation sim(scene);
  physics::Body& body = sim.mutable_body();
  const std::size_t springs = body.mesh().edge_count();
  const double h = 0.5 * physics::explicit_stable_dt_s(body);
  physics::ExplicitIntegrator integrator(sim.scene().integrator, sim.scene().material);
  const std::vector<physics::Vec3> no_force(body.x_m.size(), physics::Vec3::Zero());
  integrator.run_substeps(body, no_force, h, 1);
  // The bound as BM_ExplicitSubstep takes it, on the bytes of the stream that runs.
  const double spring_bytes = integrator.offset_layout() ? integrator.offset_stream_bytes_per_spring()
                                                         : (single ? (damped ? 32.0 : 28.0) : (damped ? 32.0 : 24.0));
  const double bound = bound_ns_per_spring(body, spring_bytes, single ? 76.0 : 152.0);
  std::vector<double> floor_ns, kernel_ns;
  double sink = 0.0;
  long rounds = 0;
  for (auto _ : state) {
    auto t0 = std::chrono::steady_clock::now();
    for (int s = 0; s < kSubsteps; ++s) {
      // A new seed per call: the floors are pure functions, and calls with
      // equal arguments would be folded into one (measured: 10x too fast).
      const double seed = 1.2345678901234567 + 1e-3 * static_cast<double>(rounds++);
      sink += single ? divider_floor_float(springs, damped, seed) : divider_floor_double(springs, seed);
      benchmark::DoNotOptimize(sink);
    }
    floor_ns.push_back(std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - t0).count() /
                       kSubsteps);
    t0 = std::chrono::steady_clock::now();
    integrator.run_substeps(body, no_force, h, kSubsteps);
    kernel_ns.push_back(std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - t0).count() /
                        kSubsteps);
    benchmark::DoNotOptimize(body.x_m.data());
  }
  benchmark::DoNotOptimize(sink);
  if (!physics::state_is_finite(body)) state.SkipWithError("state became non-finite: the timing is not valid");
  const double floor = bench::median(floor_ns), kernel = bench::median(kernel_ns);
  report(state, body, floor, bound);
  state.counters["offset"] = integrator.offset_layout() ? 1.0 : 0.0;
  state.counters["kernel_x_bound"] = kernel / static_cast<double>(springs) / bound;
  state.counters["divider_vs_kernel"] = floor / kernel;
}
#endif

// Whole steps of each rung at dt = 1 ms (explicit includes its sub-steps).
void BM_Step(benchmark::State& state, scene::IntegratorKind kind, int fixed_cg_iterations,
             scene::CgPreconditioner preconditioner = scene::CgPreconditioner::kJacobi) {
  scene::Scene s = beam(static_cast<int>(state.range(0)), kind);
  s.integrator.cg_preconditioner = preconditioner;
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

// ---------------------------------------------------------------------------
// PERFORMANCE.md's resolutions, reported as that table reports the peers:
// median wall time per step over >= 200 steps (50 for explicit, whose steps
// hold many sub-steps) after a 20-step settle, one thread. Scene as there: beam 0.4 x 0.1 x 0.1 m, left face fixed, E =
// 5e4 Pa, density 100 kg/m^3, 0.05 N down on the free face, gravity off (Rayleigh beta = 0.01 s, the scene default).
//
// The peers' node/tet counts are hex grids of 10x3x3, 20x6x6, 40x12x12 cells
// of 40 x 33.3 x 33.3 mm (R1: 11*4*4 = 176 nodes, 10*3*3*6 = 540 tets; R2:
// 21*7*7 = 1,029 / 4,320; R3: 41*13*13 = 6,929 / 34,560). tissued's lattice
// needs cubes, so a beam of exactly that size and those counts does not
// exist; (8x2x2 cubes refined one level is 16x4x4 = 425 nodes / 1,536 tets,
// not R2). Two stand-ins, both reported:
//   geometry 0 (exact beam, conservative): 24x6x6 cubes of 16.7 mm = 1,225
//     nodes / 5,184 tets for R2 (1.2x its tets), 48x12x12 of 8.3 mm = 8,281 /
//     41,472 for R3 (1.2x);
//   geometry 1 (exact counts): 20x6x6 cubes of 20 mm (R2) and 40x12x12 of
//     10 mm (R3), a 0.4 x 0.12 x 0.12 m beam.
// Args: resolution (2|3), dt in ms (1|10), geometry (0|1).
scene::Scene performance_beam(int resolution, int geometry, scene::IntegratorKind kind, double dt_s) {
  const int scale = resolution == 2 ? 1 : 2;
  scene::Scene s;
  if (geometry == 0) {
    s.object.cubes = {24 * scale, 6 * scale, 6 * scale};
    s.object.cube_size_m = 0.4 / (24 * scale);
  } else {
    s.object.cubes = {20 * scale, 6 * scale, 6 * scale};
    s.object.cube_size_m = 0.02 / scale;
  }
  const double side = s.object.cubes[1] * s.object.cube_size_m;
  const double length = s.object.cubes[0] * s.object.cube_size_m;
  s.fixed.push_back({scene::Region::box({0, 0, 0}, {0, side, side})});
  s.loads.push_back({"tip", scene::Region::box({length, 0, 0}, {length, side, side}), {0, 0, -0.05}, {}});
  s.probes.push_back({"tip", {length, side / 2, side / 2}});
  s.integrator.kind = kind;
  s.integrator.dt_s = dt_s;
  s.integrator.max_substeps = 1000000;
  return s;
}

using bench::median;
using bench::thread_cpu_ns;

// fixed_cg_iterations > 0: exactly that many CG iterations (cg20); 0: the
// default tolerance mode (relative residual 1e-6, at most 100 iterations).
// ms_per_step: median wall; cpu_ms_per_step: median thread CPU time (robust
// on a shared machine); explicit steps include their automatic sub-steps, so
// their ms_per_step is the cost per simulated ms at dt = 1 ms.
// Steps an explicit simulation until its sub-step has been tightened (the
// Lanczos bound a mesh gets once it has stood still: the steady state the
// timings below are about); other rungs return at once. False on a failed
// step (`error` set).
bool settle_explicit(physics::Simulation& sim, std::string& error) {
  const auto* rung = dynamic_cast<const physics::ExplicitIntegrator*>(&sim.integrator());
  for (int i = 0; rung && !rung->tightened() && i < 100000; ++i) {
    const physics::StepResult r = sim.step();
    if (!r.ok) {
      error = r.error;
      return false;
    }
  }
  return true;
}

void BM_PerformanceBeam(benchmark::State& state, scene::IntegratorKind kind, int fixed_cg_iterations) {
  const int resolution = static_cast<int>(state.range(0));
  const double dt_s = 1e-3 * static_cast<double>(state.range(1));
  scene::Scene s = performance_beam(resolution, static_cast<int>(state.range(2)), kind, dt_s);
  s.integrator.cg_preconditioner = scene::CgPreconditioner::kJacobi;  // the figures of the "(Jacobi)" rows
  if (fixed_cg_iterations > 0) {
    s.integrator.cg_tolerance = 1e-300;
    s.integrator.cg_max_iterations = fixed_cg_iterations;
  }
  if (kind == scene::IntegratorKind::kExplicit) {
    // As PERFORMANCE.md's plain explicit stepper: undamped. Stiffness damping
    // (beta = 0.01 s) would cut the stable sub-step ~100x (integrator.hpp);
    // such scenes belong on the implicit rung. Hundreds of sub-steps per step
    // make 50 timed steps enough for a stable median.
    s.material.rayleigh_beta_s = 0.0;
  }
  constexpr int kSettle = 20;
  const int kTimed = kind == scene::IntegratorKind::kExplicit ? 50 : 200;
  std::vector<double> wall, cpu;
  double iterations = 0, tip_mm = 0;
  int substeps = 0;
  for (auto _ : state) {
    physics::Simulation sim(s);
    wall.clear();
    cpu.clear();
    iterations = 0;
    std::string error;
    if (!settle_explicit(sim, error)) {
      state.SkipWithError(error.c_str());
      return;
    }
    for (int i = 0; i < kSettle + kTimed; ++i) {
      const auto t0 = std::chrono::steady_clock::now();
      const double c0 = thread_cpu_ns();
      const physics::StepResult r = sim.step();
      const double c1 = thread_cpu_ns();
      const double ns = std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - t0).count();
      if (!r.ok) {
        state.SkipWithError(r.error.c_str());
        return;
      }
      if (i < kSettle) continue;
      wall.push_back(ns);
      cpu.push_back(c1 - c0);
      iterations += r.solver_iterations;
      substeps = r.substeps;
    }
    tip_mm = -1e3 * sim.probe_displacement_m(0).z();
    state.counters["nodes"] = static_cast<double>(sim.body().mesh().node_count());
    state.counters["tets"] = static_cast<double>(sim.body().mesh().tet_count());
    state.counters["springs"] = static_cast<double>(sim.body().mesh().edge_count());
  }
  state.counters["ms_per_step"] = median(wall) * 1e-6;
  state.counters["cpu_ms_per_step"] = median(cpu) * 1e-6;
  state.counters["cg_iterations"] = iterations / kTimed;
  state.counters["substeps"] = substeps;
  state.counters["tip_mm"] = tip_mm;  // after 0.22 s (dt 1 ms) or 2.2 s (10 ms): finite = stable
}

// Matrix-free vs assembled block-CSR CG matvec, same integrator otherwise
// (cg20, dt = 1 ms, exact-geometry beams): the figures behind the default.
// Args: resolution (2|3), matvec (0 matrix-free | 1 assembled).
void BM_ImplicitMatvec(benchmark::State& state) {
  const scene::Scene s = performance_beam(static_cast<int>(state.range(0)), 0, scene::IntegratorKind::kImplicit, 1e-3);
  scene::IntegratorSpec spec = s.integrator;
  spec.cg_tolerance = 1e-300;
  spec.cg_max_iterations = 20;
  const auto matvec = state.range(1) == 0 ? physics::ImplicitIntegrator::Matvec::kMatrixFree
                                          : physics::ImplicitIntegrator::Matvec::kAssembledBlockCsr;
  std::vector<double> wall, cpu;
  for (auto _ : state) {
    physics::Body body(s);
    physics::ImplicitIntegrator integrator(spec, s.material, matvec);
    physics::LoadDistribution loads;
    loads.rebuild(body);
    std::vector<physics::Vec3> f;
    for (int i = 0; i < 220; ++i) {
      const double t = (i + 1) * spec.dt_s;
      physics::set_kinematic_velocities(body, t, spec.dt_s);
      loads.external_forces(body, t, f);
      const auto t0 = std::chrono::steady_clock::now();
      const double c0 = thread_cpu_ns();
      const physics::StepOutcome r = integrator.step(body, f, spec.dt_s);
      const double c1 = thread_cpu_ns();
      const double ns = std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - t0).count();
      if (!r.ok) {
        state.SkipWithError(r.error.c_str());
        return;
      }
      if (i < 20) continue;
      wall.push_back(ns);
      cpu.push_back(c1 - c0);
    }
    state.counters["springs"] = static_cast<double>(body.mesh().edge_count());
  }
  state.counters["ms_per_step"] = median(wall) * 1e-6;
  state.counters["cpu_ms_per_step"] = median(cpu) * 1e-6;
  state.counters["cpu_ns_per_spring"] = median(cpu) / state.counters["springs"];
}

// Jacobi vs two-level preconditioner on PERFORMANCE.md's beams (exact
// geometry), through the integrator directly (the scene cannot pick a
// preconditioner). 220 steps, the last 200 timed; tip = z displacement of the
// free face's centre node at the end; tip_error_pct against the same run
// solved to a relative residual of 1e-10 (at most 2000 iterations, Jacobi):
// what the fixed iteration budget loses.
// Args: resolution (2|3), dt ms (1|10), preconditioner (0 Jacobi | 1 two-level),
// CG iterations (fixed; 0 = tolerance 1e-6, at most 100).
double implicit_run(const scene::Scene& s, scene::IntegratorSpec spec,
                    physics::ImplicitIntegrator::Preconditioner preconditioner, std::vector<double>* cpu_ns,
                    double* iterations) {
  physics::Body body(s);
  physics::ImplicitIntegrator integrator(spec, s.material, physics::ImplicitIntegrator::Matvec::kMatrixFree,
                                         physics::detected_simd(), preconditioner);
  physics::LoadDistribution loads;
  loads.rebuild(body);
  std::vector<physics::Vec3> f;
  const double length = s.object.cubes[0] * s.object.cube_size_m, side = s.object.cubes[1] * s.object.cube_size_m;
  physics::NodeId tip = 0;
  double best = 1e300;
  body.mesh().for_each_node([&](physics::NodeId n, const mesh::Node&) {
    const double d = (body.rest_m[n] - physics::Vec3(length, side / 2, side / 2)).norm();
    if (d < best) {
      best = d;
      tip = n;
    }
  });
  double its = 0;
  for (int i = 0; i < 220; ++i) {
    const double t = (i + 1) * spec.dt_s;
    physics::set_kinematic_velocities(body, t, spec.dt_s);
    loads.external_forces(body, t, f);
    const double c0 = thread_cpu_ns();
    const physics::StepOutcome r = integrator.step(body, f, spec.dt_s);
    const double c1 = thread_cpu_ns();
    if (!r.ok) return NAN;
    if (i >= 20) {
      if (cpu_ns) cpu_ns->push_back(c1 - c0);
      its += r.solver_iterations;
    }
  }
  if (iterations) *iterations = its / 200;
  return -1e3 * (body.x_m[tip] - body.rest_m[tip]).z();
}

void BM_ImplicitPreconditioner(benchmark::State& state) {
  const double dt_s = 1e-3 * static_cast<double>(state.range(1));
  const scene::Scene s = performance_beam(static_cast<int>(state.range(0)), 0, scene::IntegratorKind::kImplicit, dt_s);
  scene::IntegratorSpec spec = s.integrator;
  if (state.range(3) > 0) {
    spec.cg_tolerance = 1e-300;
    spec.cg_max_iterations = static_cast<int>(state.range(3));
  }
  const auto preconditioner = state.range(2) == 0 ? physics::ImplicitIntegrator::Preconditioner::kJacobi
                                                  : physics::ImplicitIntegrator::Preconditioner::kTwoLevel;
  std::vector<double> cpu;
  double tip_mm = 0, iterations = 0;
  for (auto _ : state) tip_mm = implicit_run(s, spec, preconditioner, &cpu, &iterations);
  scene::IntegratorSpec reference = s.integrator;
  reference.cg_tolerance = 1e-10;
  reference.cg_max_iterations = 2000;
  const double reference_mm =
      implicit_run(s, reference, physics::ImplicitIntegrator::Preconditioner::kJacobi, nullptr, nullptr);
  state.counters["cpu_ms_per_step"] = cpu.empty() ? NAN : median(cpu) * 1e-6;
  state.counters["cg_iterations"] = iterations;
  state.counters["tip_mm"] = tip_mm;
  state.counters["reference_tip_mm"] = reference_mm;
  state.counters["tip_error_pct"] = 100.0 * std::abs(tip_mm - reference_mm) / std::abs(reference_mm);
}

// Where the two-level preconditioner pays in the default tolerance mode
// (relative residual 1e-6), by size and by shape: the slender 0.4 m beam
// (12x3x3 cubes, depths 0..6: 208 .. 8,281 nodes) and the shipped
// cantilever's compact 0.1 m cube (4x4x4 cubes, depths 0..6: 125 .. 4,913
// nodes), dt = 1 or 10 ms; both preconditioners run alternately three times
// (200 timed steps each), medians of thread CPU time per step. The figures
// behind ImplicitIntegrator::kAutoTwoLevelUnknowns, the size from which the
// default (cg_preconditioner: auto) takes two-level (docs/performance.md).
// Args: depth, dt in ms, shape (0 beam, 1 cube).
void BM_PreconditionerCrossover(benchmark::State& state) {
  scene::Scene s = beam(static_cast<int>(state.range(0)), scene::IntegratorKind::kImplicit);
  if (state.range(2) == 1) {  // the shipped cantilever's cube, its 5 N tip load
    s.object.cubes = {4, 4, 4};
    s.object.cube_size_m = 0.025;
    s.fixed = {{scene::Region::box({0, 0, 0}, {0, 0.1, 0.1})}};
    s.loads = {{"tip", scene::Region::box({0.1, 0, 0}, {0.1, 0.1, 0.1}), {0, 0, -5}, {}}};
  }
  s.integrator.dt_s = 1e-3 * static_cast<double>(state.range(1));
  std::vector<double> jacobi_ns, two_level_ns;
  double jacobi_iterations = 0, two_level_iterations = 0, jacobi_tip = 0, two_level_tip = 0;
  for (auto _ : state)
    for (int round = 0; round < 3; ++round) {
      jacobi_tip = implicit_run(s, s.integrator, physics::ImplicitIntegrator::Preconditioner::kJacobi, &jacobi_ns,
                                &jacobi_iterations);
      two_level_tip = implicit_run(s, s.integrator, physics::ImplicitIntegrator::Preconditioner::kTwoLevel,
                                   &two_level_ns, &two_level_iterations);
    }
  if (!std::isfinite(jacobi_tip) || !std::isfinite(two_level_tip)) state.SkipWithError("a run failed");
  const physics::Body body(s);
  state.counters["nodes"] = static_cast<double>(body.mesh().node_count());
  state.counters["jacobi_ms"] = median(jacobi_ns) * 1e-6;
  state.counters["two_level_ms"] = median(two_level_ns) * 1e-6;
  state.counters["two_level_vs_jacobi"] = median(two_level_ns) / median(jacobi_ns);
  state.counters["jacobi_iterations"] = jacobi_iterations;
  state.counters["two_level_iterations"] = two_level_iterations;
}

// PERFORMANCE.md's explicit bar, as a ratio measured in one run: the whole
// explicit step at dt = 1 ms (its automatic sub-steps from the safe bound
// times substep_safety, the copies in and out, the finiteness check) against
// the "plain explicit springs, float" stepper that the bar names (16 B per
// spring: two ids, rest length, stiffness; per node x, v, f, 1/m as floats;
// scalar force loop, then the update), run on the same springs, masses and
// load, with the fewest sub-steps its true stable limit allows (2/ω_max by
// Lanczos, no safety margin, as PERFORMANCE.md counted it: 4 per
// 1 ms at R3). Both undamped. Alternating rounds, thread CPU time; target:
// ours_vs_plain ≤ 0.5 (≤ 0.45 ms per simulated ms at R3 is "2× the plain
// stepper" on the machine PERFORMANCE.md measured).
// Args: resolution (2|3), geometry (0 exact beam | 1 exact counts).
struct PlainSpring {
  std::uint32_t a, b;
  float rest_m, k_N_per_m;
};

void plain_substep(const std::vector<PlainSpring>& springs, float h, const std::vector<float>& inv_mass,
                   const std::vector<float>& f_ext, std::vector<float>& x, std::vector<float>& v,
                   std::vector<float>& f) {
  std::copy(f_ext.begin(), f_ext.end(), f.begin());
  for (const PlainSpring& s : springs) {
    const float dx = x[3 * s.b] - x[3 * s.a], dy = x[3 * s.b + 1] - x[3 * s.a + 1],
                dz = x[3 * s.b + 2] - x[3 * s.a + 2];
    const float l = std::sqrt(dx * dx + dy * dy + dz * dz);
    const float c = s.k_N_per_m * (l - s.rest_m) / l;
    f[3 * s.a] += c * dx;
    f[3 * s.a + 1] += c * dy;
    f[3 * s.a + 2] += c * dz;
    f[3 * s.b] -= c * dx;
    f[3 * s.b + 1] -= c * dy;
    f[3 * s.b + 2] -= c * dz;
  }
  for (std::size_t n = 0; n < inv_mass.size(); ++n)
    for (int k = 0; k < 3; ++k) {
      v[3 * n + k] += h * inv_mass[n] * f[3 * n + k];
      x[3 * n + k] += h * v[3 * n + k];
    }
}

void BM_ExplicitVsPlainStepper(benchmark::State& state) {
  scene::Scene s = performance_beam(static_cast<int>(state.range(0)), static_cast<int>(state.range(1)),
                                    scene::IntegratorKind::kExplicit, 1e-3);
  s.material.rayleigh_beta_s = 0.0;
  if (state.range(2) == 1) s.integrator.explicit_precision = scene::ExplicitPrecision::kFloat;
  physics::Simulation sim(s);
  const physics::Body& body = sim.body();
  const std::size_t nodes = body.x_m.size();
  std::vector<PlainSpring> springs;
  body.mesh().for_each_edge([&](physics::EdgeId e, const mesh::Edge& edge) {
    springs.push_back(
        {edge.a, edge.b, static_cast<float>(body.rest_length_m[e]), static_cast<float>(body.stiffness_N_per_m[e])});
  });
  std::vector<float> x(3 * nodes), v(3 * nodes, 0.0f), f(3 * nodes), f_ext(3 * nodes), inv_mass(nodes);
  physics::LoadDistribution loads;
  loads.rebuild(body);
  std::vector<physics::Vec3> load_N;
  loads.external_forces(body, 1.0, load_N);
  for (std::size_t n = 0; n < nodes; ++n) {
    inv_mass[n] = static_cast<float>(body.inv_mass_per_kg[n]);
    for (int k = 0; k < 3; ++k) {
      x[3 * n + k] = static_cast<float>(body.x_m[n][k]);
      f_ext[3 * n + k] = static_cast<float>(load_N[n][k]);
    }
  }
  // ω_max² of M⁻¹K at rest: the Lanczos Ritz value, from below (the plain
  // stepper gets at most the sub-steps it needs; within 0.1 % of the dense
  // eigensolver's value on the beams the tests check).
  const double lambda = physics::rest_frequency2_estimate(body).ritz_per_s2;
  const double plain_limit_s = 2.0 / std::sqrt(lambda);
  const int plain_substeps = static_cast<int>(std::ceil(s.integrator.dt_s / plain_limit_s));
  const float h = static_cast<float>(s.integrator.dt_s / plain_substeps);

  constexpr int kRounds = 5, kSteps = 20;
  std::vector<double> ours_ns, plain_ns;
  int our_substeps = 0;
  std::string error;
  if (!settle_explicit(sim, error)) {
    state.SkipWithError(error.c_str());
    return;
  }
  for (auto _ : state)
    for (int round = 0; round < kRounds; ++round) {
      for (int i = 0; i < kSteps; ++i) {
        const double c0 = thread_cpu_ns();
        const physics::StepResult r = sim.step();
        ours_ns.push_back(thread_cpu_ns() - c0);
        if (!r.ok) {
          state.SkipWithError(r.error.c_str());
          return;
        }
        our_substeps = r.substeps;
      }
      for (int i = 0; i < kSteps; ++i) {
        const double c0 = thread_cpu_ns();
        for (int k = 0; k < plain_substeps; ++k) plain_substep(springs, h, inv_mass, f_ext, x, v, f);
        plain_ns.push_back(thread_cpu_ns() - c0);
        benchmark::DoNotOptimize(x.data());
      }
    }
  for (const float xi : x)
    if (!std::isfinite(xi)) state.SkipWithError("the plain stepper went non-finite: its timing is not valid");
  state.counters["springs"] = static_cast<double>(springs.size());
  state.counters["ours_substeps"] = our_substeps;
  state.counters["plain_substeps"] = plain_substeps;
  state.counters["ours_ms_per_sim_ms"] = median(ours_ns) * 1e-6;
  state.counters["plain_ms_per_sim_ms"] = median(plain_ns) * 1e-6;
  state.counters["plain_ns_per_spring"] = median(plain_ns) / plain_substeps / static_cast<double>(springs.size());
  state.counters["ours_vs_plain"] = median(ours_ns) / median(plain_ns);
  // Our sub-step as a fraction of the true stable limit (safety x bound),
  // tightened, and before the Lanczos bound tightened it.
  const auto& rung = dynamic_cast<const physics::ExplicitIntegrator&>(sim.integrator());
  state.counters["ours_h_vs_limit"] = s.integrator.substep_safety * rung.stable_step().dt_s / plain_limit_s;
  state.counters["guaranteed_h_vs_limit"] =
      s.integrator.substep_safety * physics::explicit_stable_dt_s(sim.body()) / plain_limit_s;
}

// The issue's implicit target as ratios measured in one run: one implicit
// step (dt = 1 ms, exactly 20 Jacobi-CG iterations; exactly 5 two-level ones,
// the more accurate of the two on these beams; and the scene default, auto
// at cg20) against one explicit sub-step (BM_ExplicitSubstep's timing: the
// kernel amortised over 10 sub-steps at half the stable sub-step; on the
// layout the integrator takes, and `_gathered` on the gathered stream), on
// the same mesh, alternating rounds. Target: ≤ 25.
// Arg: refinement depth of the 12x3x3 beam (as BM_Step).
void BM_ImplicitVsExplicitSubstep(benchmark::State& state) {
  const int depth = static_cast<int>(state.range(0));
  const auto implicit_sim = [&](scene::CgPreconditioner preconditioner, int iterations) {
    scene::Scene s = beam(depth, scene::IntegratorKind::kImplicit);
    s.integrator.cg_preconditioner = preconditioner;
    s.integrator.cg_tolerance = 1e-300;
    s.integrator.cg_max_iterations = iterations;
    return std::make_unique<physics::Simulation>(s);
  };
  auto jacobi = implicit_sim(scene::CgPreconditioner::kJacobi, 20);
  auto two_level = implicit_sim(scene::CgPreconditioner::kTwoLevel, 5);
  auto automatic = implicit_sim(scene::CgPreconditioner::kAuto, 20);
  physics::Simulation explicit_sim(beam(depth, scene::IntegratorKind::kExplicit));
  physics::Body& body = explicit_sim.mutable_body();
  const double h = 0.5 * physics::explicit_stable_dt_s(body);
  physics::ExplicitIntegrator integrator(explicit_sim.scene().integrator, explicit_sim.scene().material);
  // The same sub-step on the gathered stream, for the ratios of meshes that
  // are not of one depth (BM_ExplicitSubstep's fifth argument).
  physics::ExplicitIntegrator gathered(explicit_sim.scene().integrator, explicit_sim.scene().material);
  gathered.set_layout(physics::ExplicitIntegrator::Layout::kGathered);
  const std::vector<physics::Vec3> no_force(body.x_m.size(), physics::Vec3::Zero());
  integrator.run_substeps(body, no_force, h, 1);  // builds the stream outside the timing
  gathered.run_substeps(body, no_force, h, 1);
  const int rounds = depth >= 9 ? 3 : 5, steps = depth >= 9 ? 3 : 10;
  std::vector<double> substep_ns, gathered_ns, jacobi_ns, two_level_ns, auto_ns;
  const auto time_steps = [&](physics::Simulation& sim, std::vector<double>& out) {
    for (int i = 0; i < steps; ++i) {
      const double c0 = thread_cpu_ns();
      const physics::StepResult r = sim.step();
      out.push_back(thread_cpu_ns() - c0);
      if (!r.ok) return false;
    }
    return true;
  };
  for (auto _ : state)
    for (int round = 0; round < rounds; ++round) {
      for (int i = 0; i < steps; ++i) {
        const double c0 = thread_cpu_ns();
        integrator.run_substeps(body, no_force, h, 10);
        substep_ns.push_back((thread_cpu_ns() - c0) / 10);
        const double g0 = thread_cpu_ns();
        gathered.run_substeps(body, no_force, h, 10);
        gathered_ns.push_back((thread_cpu_ns() - g0) / 10);
      }
      if (!time_steps(*jacobi, jacobi_ns) || !time_steps(*two_level, two_level_ns) ||
          !time_steps(*automatic, auto_ns)) {
        state.SkipWithError("an implicit step failed");
        return;
      }
    }
  if (!physics::state_is_finite(body)) state.SkipWithError("the explicit state went non-finite");
  const double substep = median(substep_ns);
  state.counters["springs"] = static_cast<double>(body.mesh().edge_count());
  state.counters["substep_ns_per_spring"] = substep / static_cast<double>(body.mesh().edge_count());
  state.counters["jacobi_cg20_x"] = median(jacobi_ns) / substep;
  state.counters["two_level_cg5_x"] = median(two_level_ns) / substep;
  state.counters["auto_cg20_x"] = median(auto_ns) / substep;
  state.counters["offset_layout"] = integrator.offset_layout() ? 1.0 : 0.0;
  state.counters["jacobi_cg20_x_gathered"] = median(jacobi_ns) / median(gathered_ns);
  state.counters["two_level_cg5_x_gathered"] = median(two_level_ns) / median(gathered_ns);
}

// The paper's adaptive cantilever under load: share of the step time spent
// in adaptation at the default cadence (every 5 steps). Two identical runs
// refine for 200 steps (deterministic: the same mesh); then one keeps
// adapting and the other has adaptation paused, and both time 500 steps on
// that same mesh, alternating so machine noise hits both alike.
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
  s.adaptivity.every_steps = 5;
  double with_ns = 0, without_ns = 0;
  double cadence_ns = 0, other_ns = 0;
  int cadence_steps = 0, other_steps = 0;
  std::size_t springs = 0;
  for (auto _ : state) {
    physics::Simulation adaptive(s), paused(s);
    // The loading transient, where the mesh refines from 384 to 2,560 tets:
    // steps that adapt (every 5th) against the others around them.
    for (int i = 0; i < 200; ++i) {
      const auto t0 = std::chrono::steady_clock::now();
      adaptive.step();
      const double ns = std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - t0).count();
      if (adaptive.counters().steps % s.adaptivity.every_steps == 0) {
        cadence_ns += ns;
        ++cadence_steps;
      } else {
        other_ns += ns;
        ++other_steps;
      }
      paused.step();
    }
    paused.set_adaptation_paused(true);
    springs = adaptive.body().mesh().edge_count();
    for (int block = 0; block < 10; ++block)
      for (physics::Simulation* sim : {&adaptive, &paused}) {
        const auto t0 = std::chrono::steady_clock::now();
        for (int i = 0; i < 50; ++i) sim->step();
        (sim == &adaptive ? with_ns : without_ns) +=
            std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - t0).count();
      }
  }
  state.counters["springs"] = static_cast<double>(springs);
  state.counters["step_us_adapting"] = with_ns / 500e3 / static_cast<double>(state.iterations());
  state.counters["step_us_paused"] = without_ns / 500e3 / static_cast<double>(state.iterations());
  state.counters["adaptation_share"] = (with_ns - without_ns) / with_ns;
  // Transient: extra cost of an adapting step, spread over its cadence, as a
  // share of the mean step.
  const double cadence_mean = cadence_ns / cadence_steps, other_mean = other_ns / other_steps;
  const double mean_step = (cadence_ns + other_ns) / (cadence_steps + other_steps);
  state.counters["transient_adaptation_share"] = (cadence_mean - other_mean) / s.adaptivity.every_steps / mean_step;
}

// What a tool contact costs an adaptation pass: one adapt() of a body at rest
// (4^3 cubes of 25 mm refined uniformly to depth 9: 196,608 tets, every split
// node old, relaxed and mergeable; the pass merges its budget of 64), with no
// contact and with a 2 mm frozen sphere on the top face, as the service's sim
// runner sets on every contact. Each pass runs on a fresh copy (a pass
// changes the mesh); only adapt() is timed. The pass used to walk the edges
// of every merge candidate to test the sphere (26 (K + 1) hash lookups each):
// 10.5-18.3 ms unfrozen, 218-227 ms frozen (2026-11-28, load average 8 on 2
// cores); walking those of the nodes in the sphere once, 14.6 ms frozen,
// 18.3 ms unfrozen (frozen_x 0.80: within the machine's noise).
void BM_AdaptationFrozen(benchmark::State& state) {
  scene::Scene s;
  s.name = "cube";
  s.object.cubes = {4, 4, 4};
  s.object.cube_size_m = 0.025;
  s.adaptivity.enabled = true;
  s.adaptivity.max_depth = 12;
  physics::Body body(s);
  for (int depth = 0; depth < 9; ++depth) {
    std::vector<mesh::Key> keys;
    body.mesh().for_each_tet([&](mesh::TetId t, const mesh::Tet& tet) {
      if (tet.depth == depth) keys.push_back(body.mesh().diamond_of(t));
    });
    for (const mesh::Key k : keys)
      if (body.mesh().can_split(k)) body.split(k);
  }
  body.step_index = 1000;
  std::vector<double> unfrozen_ns, frozen_ns;
  int merges = 0, walks = 0;
  for (auto _ : state) {
    for (const bool frozen : {false, true}) {
      physics::Body copy = body;
      physics::Adaptivity adaptivity(s.adaptivity);
      if (frozen) adaptivity.freeze_sphere(physics::Vec3(0.05, 0.05, 0.1), 0.002);
      const auto t0 = std::chrono::steady_clock::now();
      const physics::AdaptStats stats = adaptivity.adapt(copy);
      const double ns = std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - t0).count();
      (frozen ? frozen_ns : unfrozen_ns).push_back(ns);
      merges = stats.merges;
      if (frozen) walks = stats.frozen_edge_walks;
    }
  }
  state.counters["tets"] = static_cast<double>(body.mesh().tet_count());
  state.counters["unfrozen_ms"] = bench::median(unfrozen_ns) * 1e-6;
  state.counters["frozen_ms"] = bench::median(frozen_ns) * 1e-6;
  state.counters["frozen_x"] = bench::median(frozen_ns) / bench::median(unfrozen_ns);
  state.counters["merges"] = merges;
  state.counters["frozen_edge_walks"] = walks;
}

// The two O(mesh) energy sums the daemon writes into every recorded sim row,
// beside the step they follow (shipped default: implicit, 1e-6 tolerance).
void BM_EnergySumsPerStep(benchmark::State& state) {
  physics::Simulation sim(beam(static_cast<int>(state.range(0)), scene::IntegratorKind::kImplicit));
  sim.step();
  double step_ns = 0.0, energy_ns = 0.0, sink = 0.0;
  for (auto _ : state) {
    const auto t0 = std::chrono::steady_clock::now();
    sim.step();
    const auto t1 = std::chrono::steady_clock::now();
    sink += sim.kinetic_energy_J() + sim.elastic_energy_J();
    const auto t2 = std::chrono::steady_clock::now();
    step_ns += std::chrono::duration<double, std::nano>(t1 - t0).count();
    energy_ns += std::chrono::duration<double, std::nano>(t2 - t1).count();
  }
  benchmark::DoNotOptimize(sink);
  state.counters["step_ms"] = step_ns / static_cast<double>(state.iterations()) * 1e-6;
  state.counters["energy_ms"] = energy_ns / static_cast<double>(state.iterations()) * 1e-6;
  state.counters["energy_share"] = energy_ns / step_ns;
}

}  // namespace

// Args: depth, old code (1: add_spring_forces + plain update), undamped,
// single precision, layout (0 the integrator's, 1 gathered forced, 2 offset
// forced). The old code runs no layout: registered with the fifth argument 0 only.
BENCHMARK(BM_ExplicitSubstep)
    ->ArgsProduct({{0, 3, 6, 9, 10, 11}, {0}, {0}, {0}, {0, 1}})
    ->Iterations(21)
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_ExplicitSubstep)
    ->ArgsProduct({{0, 3, 6, 9, 10, 11}, {1}, {0}, {0}, {0}})
    ->Iterations(21)
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_ExplicitSubstep)
    ->ArgsProduct({{0, 3, 6, 9, 10, 11}, {0}, {0, 1}, {1}, {0, 1}})
    ->Iterations(21)
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_ExplicitSubstep)
    ->ArgsProduct({{0, 3, 6, 9, 10, 11}, {0}, {1}, {0}, {0, 1}})
    ->Iterations(21)
    ->Unit(benchmark::kMillisecond);
// Where the offset layout stops paying: forced on the meshes it is not taken
// on (depth 11, and depths 1-2 of a short beam), against the gathered stream.
BENCHMARK(BM_ExplicitSubstep)
    ->ArgsProduct({{1, 2, 11}, {0}, {0, 1}, {0, 1}, {1, 2}})
    ->Iterations(21)
    ->Unit(benchmark::kMillisecond);
#if defined(__x86_64__)
BENCHMARK(BM_ExplicitAccessFloor)->DenseRange(0, 9, 3)->Arg(10)->Arg(11)->Iterations(21)->Unit(benchmark::kMillisecond);
// Args: depth, precision (1 float), dampers.
BENCHMARK(BM_ExplicitDividerFloor)
    ->ArgsProduct({{0, 3, 6, 9, 10, 11}, {0, 1}, {0, 1}})
    ->Iterations(21)
    ->Unit(benchmark::kMillisecond);
#endif
// The beam keeps the scene default Rayleigh beta = 0.01 s, which the explicit
// rung pays for in sub-steps (measured: 28 per 1 ms step at depth 0, 1,749 at
// depth 9; undamped, BM_PerformanceBeam/explicit needs 3-6 at R2-R3).
BENCHMARK_CAPTURE(BM_Step, explicit, scene::IntegratorKind::kExplicit, 0)
    ->Arg(0)
    ->Arg(3)
    ->Arg(6)
    ->Arg(9)
    ->Iterations(3)
    ->Unit(benchmark::kMillisecond);
// Depths 0, 3, 6, 9, 11 of the beam: 10^3 .. 1.6x10^6 springs.
#define CG_STEP_ARGS ArgsProduct({{0, 3, 6, 9, 11}})->Iterations(5)->Unit(benchmark::kMillisecond)
BENCHMARK_CAPTURE(BM_Step, implicit_cg20, scene::IntegratorKind::kImplicit, 20)->CG_STEP_ARGS;
// The two-level preconditioner at 5 iterations (more accurate than Jacobi at
// 20 on these beams: docs/performance.md), coarse factorisation included in every step.
BENCHMARK_CAPTURE(BM_Step, implicit_two_level_cg5, scene::IntegratorKind::kImplicit, 5,
                  scene::CgPreconditioner::kTwoLevel)
    ->CG_STEP_ARGS;
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
// Ten local/global iterations, as projective dynamics is usually run (the
// default tolerance can take the full 100-iteration cap on fine meshes).
// Depths 10 and 11 take ~1 and ~7 minutes (the sparse direct factorisation:
// 2.1 GB at depth 11); filter them out for a quick run.
BENCHMARK_CAPTURE(BM_Step, projective_it10, scene::IntegratorKind::kProjective, 10)
    ->Arg(0)
    ->Arg(3)
    ->Arg(6)
    ->Arg(9)
    ->Arg(10)
    ->Arg(11)
    ->Iterations(5)
    ->Unit(benchmark::kMillisecond);
// The contact stiffness a tool feels past ContactStiffness's cap (the node's
// own spring block) for a tool sliding over the top face: every query a new
// node. Beside it, in the same run, the same block summed by a walk over
// every edge (how it was found before KuhnMesh::for_each_edge_at_node).
// A 16x16x16-cube block clamped at its base (4,624 free nodes at depth 0,
// past the 3,000-node cap). Arg: uniform refinement depth (0: 3.1x10^4
// springs, 3: 2.4x10^5). Measured 2026-11-26: 1.0 / 1.7 us per query by
// lookup, 17 / 220 us by the walk.
void BM_ContactStiffnessPastTheCap(benchmark::State& state) {
  scene::Scene s;
  s.object.cubes = {16, 16, 16};
  s.object.cube_size_m = 0.1 / 16;
  s.adaptivity.min_depth = static_cast<int>(state.range(0));
  s.fixed.push_back({scene::Region::box({0, 0, 0}, {0.1, 0.1, 0})});
  physics::Simulation sim(s);
  const physics::Body& body = sim.body();
  std::vector<mesh::NodeId> top;
  for (mesh::NodeId n = 0; n < body.x_m.size(); ++n)
    if (body.mesh().node_alive(n) && body.x_m[n].z() > 0.1 - 1e-9) top.push_back(n);
  physics::ContactStiffness contact;
  double lookup_ns = 0.0, walk_ns = 0.0, checksum = 0.0;
  for (auto _ : state) {
    const double c0 = thread_cpu_ns();
    for (const mesh::NodeId n : top) checksum += contact.stiffness_N_per_m_at_node(body, n)(2, 2);
    lookup_ns = (thread_cpu_ns() - c0) / static_cast<double>(top.size());
    const double w0 = thread_cpu_ns();
    for (const mesh::NodeId n : top) {
      double k_zz = 0.0;
      body.mesh().for_each_edge([&](mesh::EdgeId e, const mesh::Edge& edge) {
        if (edge.a != n && edge.b != n) return;
        const physics::Vec3 d = (body.rest_m[edge.b] - body.rest_m[edge.a]).normalized();
        k_zz += body.stiffness_N_per_m[e] * d.z() * d.z();
      });
      checksum -= k_zz;
    }
    walk_ns = (thread_cpu_ns() - w0) / static_cast<double>(top.size());
  }
  benchmark::DoNotOptimize(checksum);
  if (!contact.local_bound()) state.SkipWithError("under the cap: the condensed answer was timed");
  state.counters["springs"] = static_cast<double>(body.mesh().edge_count());
  state.counters["queries"] = static_cast<double>(top.size());
  state.counters["lookup_us_per_query"] = lookup_ns * 1e-3;
  state.counters["edge_walk_us_per_query"] = walk_ns * 1e-3;
  state.counters["walk_x_lookup"] = walk_ns / lookup_ns;
}

// R2/R3 (PERFORMANCE.md): {resolution, dt ms, geometry}.
#define PERFORMANCE_BEAM_ARGS ArgsProduct({{2, 3}, {1, 10}, {0, 1}})->Iterations(1)->Unit(benchmark::kMillisecond)
BENCHMARK_CAPTURE(BM_PerformanceBeam, implicit_cg20, scene::IntegratorKind::kImplicit, 20)->PERFORMANCE_BEAM_ARGS;
BENCHMARK_CAPTURE(BM_PerformanceBeam, implicit_tol1e6, scene::IntegratorKind::kImplicit, 0)->PERFORMANCE_BEAM_ARGS;
BENCHMARK_CAPTURE(BM_PerformanceBeam, explicit, scene::IntegratorKind::kExplicit, 0)
    ->ArgsProduct({{2, 3}, {1}, {0, 1}})
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_ImplicitMatvec)->ArgsProduct({{2, 3}, {0, 1}})->Iterations(1)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_ImplicitPreconditioner)
    ->ArgsProduct({{2, 3}, {1, 10}, {0, 1}, {5, 7, 10, 20, 0}})
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_PreconditionerCrossover)
    ->ArgsProduct({{0, 1, 2, 3, 4, 5, 6}, {1, 10}, {0, 1}})
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond);
// Args: resolution, geometry (0 exact beam | 1 exact counts), our precision
// (0 double | 1 float: integrator.explicit_precision).
BENCHMARK(BM_ExplicitVsPlainStepper)
    ->ArgsProduct({{2, 3}, {0, 1}, {0, 1}})
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_ImplicitVsExplicitSubstep)->DenseRange(0, 9, 3)->Arg(11)->Iterations(1)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_FrequencyEstimate)->DenseRange(0, 9, 3)->Iterations(5)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_OffsetPlan)->DenseRange(0, 9, 3)->Arg(11)->Iterations(3)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_AdaptationShare)->Iterations(3)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_AdaptationFrozen)->Iterations(5)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_EnergySumsPerStep)->Arg(0)->Arg(3)->Arg(6)->Iterations(50)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_ContactStiffnessPastTheCap)->Arg(0)->Arg(3)->Iterations(1)->Unit(benchmark::kMillisecond);
BENCHMARK_MAIN();
