// Symplectic Euler with automatic sub-steps, and the explicit stable bound.
//
// Two spring streams: on a mesh whose tets all have one depth (a lattice)
// the sub-steps run on the offset layout of integrator_explicit_offset.cpp
// (no gathers or scatters); every other mesh, and the one-depth meshes whose
// lanes it would fill too sparsely, runs on the gathered stream below.
//
// The sub-step runs on the integrator's own copy of the state: positions,
// velocities and forces padded to 4 doubles by node id (one AVX register),
// springs in a 32 B-per-spring stream of live springs with a free end, four
// to a record (structure of arrays), rebuilt when Body::parameters_version
// changes. The AVX2 kernel (run-time dispatch, bit-identical to the scalar
// one) takes lengths, square roots and divisions four springs at a time and
// the update pass also resets the force accumulator to f_ext. Measured with
// physics_bench BM_ExplicitSubstep, same session, load 2-3: 6.8-7.9 ns per
// spring before (add_spring_forces + update), 2.9-3.1 ns at 10^3-10^5
// springs and 4.5-4.7 ns at 4x10^5 after; against the bandwidth bound 5.1-
// 5.7x at L1/L2-resident sizes, 2.0x at 5x10^4 springs, 2.4x at 4x10^5 (was
// 12-14x, 4.2-5x). At cache-resident sizes the bound is 0.5 ns per spring
// (~1.4 cycles) while the kernel issues ~29 instructions per spring (~7.5
// cycles at the measured ~3 ns): it is issue-bound, not divider-bound — a
// division-free 1/√l (integer first guess + 4 Newton steps, deterministic on
// every CPU) ran slower, 3.8 vs 3.1 ns per spring, and was dropped. Also
// tried and dropped (BM_ExplicitSubstep at 10^3..1.6x10^6 springs, alternated
// with this kernel in one session, load ~1): batches whose four springs share
// one end, summing its force in a register (f[a] touched once per batch),
// together with nodes renumbered along a Morton curve, ran the same to 9 %
// slower; software prefetch of the stream and of the next batches' nodes
// 0-10 % slower; huge pages (MADV_HUGEPAGE) no change. Without the square
// root and division the force pass is only ~15 % faster, without the scatter
// ~10 %: the cost is spread over the shuffles and loads of every spring.
// Later (physics_bench BM_ExplicitAccessFloor, this stream and layout with a
// linear force and no arithmetic beyond it): the loads and stores alone take
// ~half the kernel's time at cache-resident sizes and ~3/4 from 4x10^5
// springs. Tried and dropped against that: nodes updated as soon as their
// last spring has run (springs ordered by larger end, chunked updates;
// bit-identical) ±7 %, no gain; a float-seeded 1/√l (float sqrt and division,
// two Newton steps in double) 30-45 % slower than sqrt + division.
// A stream without dampers (every c = 0: Rayleigh beta = 0 and the paper's
// damping off) runs kernels that read no velocities and skip the damper
// terms, same bits as c = 0 (tested): whole undamped explicit steps of the
// PERFORMANCE.md beams (BM_PerformanceBeam/explicit, R2/R3, three rounds
// alternating with the build before, 2026-11-25, load 1.8-2.6) 11-18 %
// faster, e.g. R3 exact counts 0.70-0.71 -> 0.60-0.62 CPU ms per step.
//
// Tried and dropped (2026-11-25): taking the spring dampers out of the force
// and applying them after each kick as a polynomial p(h M⁻¹C) with p in
// [0, 1] on the damping spectrum (p = q², q a damped Chebyshev polynomial
// with p(0) = 1, p'(0) = −1), which keeps symplectic Euler stable at the
// undamped sub-step with ~√(hγ) damper passes instead of ~hγ sub-steps. It
// ran stable, but q's zeros leave modes with no velocity at all each
// sub-step, so they stop creeping back (overdamped modes relax at ω²/γ; a
// factor r per sub-step gives rs/(1 − r) per step instead): the shipped
// cantilever at explicit kept 3.1e-5 J of elastic energy 1 s after the
// release where the force-damped run relaxed to 6e-28 J, and its mesh kept
// 194 nodes instead of simplifying back to 125 (tissued --batch --scene
// config/scenes/cantilever.yaml --duration 2 --set integrator.kind=explicit).
// Right creep needs p ≈ 1/(1 + z) to relative accuracy, ~√(hγ) ln(hγ)/2
// passes: no cheaper than the sub-steps on the shipped scenes (hγ ≈ 40 at
// the undamped sub-step: ~16 passes against ~15 sub-steps).
// Also dropped (same day, BM_ExplicitSubstep/{6,9,10,11}/0/{0,1}/0, two
// rounds alternating): the stream sorted by each spring's lower node id,
// 9-13 % slower at 4x10^5-8x10^5 springs (damped 4.71-4.95 vs 4.26-4.39 ns
// per spring) and no better elsewhere; dealt round-robin from 2 chunks the
// same, from 8 chunks (no two consecutive springs near each other) 30-40 %
// slower there (5.6-6.2 vs 4.2-4.3 ns). The edge-creation order's locality
// is what the large meshes run on; store-to-load chains are not the limit.
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <array>
#include <cmath>
#include <iomanip>
#include <sstream>
#include <string>

#include "physics/forces.hpp"
#include "physics/frequency_estimate.hpp"
#include "physics/integrator.hpp"
#include "physics/integrator_impl.hpp"
#include "physics/spring_law.hpp"

namespace tissue::physics {

Simd detected_simd() {
#if defined(__x86_64__)
  static const Simd simd = __builtin_cpu_supports("avx2") ? Simd::kAvx2 : Simd::kScalar;
  return simd;
#else
  return Simd::kScalar;
#endif
}

double tet_frequency2_per_s2(const Body& body, const std::array<NodeId, 4>& v, int depth) {
  const auto shares = body.tet_edge_shares_m3(v, depth);
  const double youngs_Pa = body.scene().material.youngs_modulus_Pa;
  Eigen::Matrix<double, 12, 12> k = Eigen::Matrix<double, 12, 12>::Zero();
  for (int e = 0; e < 6; ++e) {
    const int i = mesh::kTetEdgeSlots[e][0], j = mesh::kTetEdgeSlots[e][1];
    const Vec3 d = body.rest_m[v[j]] - body.rest_m[v[i]];
    const double length = d.norm();
    const Vec3 unit_d = d / length;
    const Eigen::Matrix3d block = spring_stiffness_N_per_m(youngs_Pa, shares[e], length) * unit_d * unit_d.transpose();
    k.block<3, 3>(3 * i, 3 * i) += block;
    k.block<3, 3>(3 * j, 3 * j) += block;
    k.block<3, 3>(3 * i, 3 * j) -= block;
    k.block<3, 3>(3 * j, 3 * i) -= block;
  }
  const double unit = body.mesh().lattice_unit_m();
  const double volume_m3 = static_cast<double>(body.mesh().six_volume_at_depth(depth)) * unit * unit * unit / 6.0;
  const double corner_mass_kg = body.scene().material.density_kg_per_m3 * volume_m3 / 4.0;  // eq. (2)
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 12, 12>> solver(k, Eigen::EigenvaluesOnly);
  return solver.eigenvalues().maxCoeff() / corner_mass_kg;
}

double element_frequency2_bound_per_s2(const Body& body) {
  // Tets of one depth are congruent in this hierarchy (Maubach bisection of
  // Kuhn cubes; a test checks it on adaptively refined meshes), so λ depends
  // on the depth alone: one 12x12 eigenproblem per depth present.
  std::array<double, 64> by_depth{};
  double bound = 0.0;
  body.mesh().for_each_tet([&](TetId, const mesh::Tet& t) {
    double& lambda = by_depth.at(t.depth);
    if (lambda > 0.0) return;
    lambda = tet_frequency2_per_s2(body, t.v, t.depth);
    bound = std::max(bound, lambda);
  });
  return bound;
}

double explicit_stable_dt_s(const Body& body) { return explicit_stable_step(body).dt_s; }

ExplicitBounds explicit_bounds(const Body& body) {
  const std::size_t nodes = body.x_m.size();
  std::vector<double> sum_k(nodes, 0.0), sum_c(nodes, 0.0);
  body.mesh().for_each_edge([&](EdgeId e, const mesh::Edge& edge) {
    sum_k[edge.a] += body.stiffness_N_per_m[e];
    sum_k[edge.b] += body.stiffness_N_per_m[e];
    sum_c[edge.a] += body.damping_N_s_per_m[e];
    sum_c[edge.b] += body.damping_N_s_per_m[e];
  });
  ExplicitBounds bounds;
  for (std::size_t n = 0; n < nodes; ++n) {
    if (body.inv_mass_per_kg[n] == 0.0) continue;  // kinematic nodes do not oscillate
    bounds.graph_per_s2 = std::max(bounds.graph_per_s2, 2.0 * sum_k[n] * body.inv_mass_per_kg[n]);
    bounds.damping_rate_per_s = std::max(bounds.damping_rate_per_s, 2.0 * sum_c[n] * body.inv_mass_per_kg[n]);
  }
  // With c ≤ r k on every spring, C ⪯ r K, so the damping rate is bounded by
  // r times the stiffness bound.
  body.mesh().for_each_edge([&](EdgeId e, const mesh::Edge&) {
    const double k = body.stiffness_N_per_m[e], c = body.damping_N_s_per_m[e];
    if (k > 0.0)
      bounds.damping_per_stiffness_s = std::max(bounds.damping_per_stiffness_s, c / k);
    else if (c > 0.0)
      bounds.damping_per_stiffness_s = INFINITY;  // a damper without a spring: no such bound
  });
  bounds.rest_per_s2 = std::min(bounds.graph_per_s2, element_frequency2_bound_per_s2(body));
  return bounds;
}

namespace {

// Symplectic Euler's stable step for modes ω² ≤ omega2 with damping rates
// γ ≤ gamma.
ExplicitStableStep stable_step_for(double omega2, double gamma) {
  if (omega2 <= 0.0) return {gamma > 0.0 ? 2.0 / gamma : INFINITY, INFINITY};
  const double omega = std::sqrt(omega2);
  const double zeta = gamma / (2.0 * omega);
  return {2.0 / omega * (std::sqrt(1.0 + zeta * zeta) - zeta), 2.0 / omega};
}

}  // namespace

ExplicitStableStep explicit_stable_step(const ExplicitBounds& bounds, double frequency2_per_s2) {
  // Both are upper bounds: keep the smaller.
  const double omega2 = std::min(bounds.graph_per_s2, frequency2_per_s2);
  const double gamma = std::min(bounds.damping_rate_per_s, bounds.damping_per_stiffness_s * frequency2_per_s2);
  return stable_step_for(omega2, gamma);
}

ExplicitStableStep collapsed_stable_step(const ExplicitBounds& bounds, double collapse_factor) {
  // The dampers act along their springs only, so a collapsing spring does
  // not raise their bound: γ as at the graph cap.
  const double gamma = std::min(bounds.damping_rate_per_s, bounds.damping_per_stiffness_s * bounds.graph_per_s2);
  return stable_step_for(collapse_factor * bounds.graph_per_s2, gamma);
}

ExplicitStableStep explicit_stable_step(const Body& body, double frequency2_bound_per_s2) {
  const ExplicitBounds bounds = explicit_bounds(body);
  return explicit_stable_step(bounds, std::min(bounds.rest_per_s2, frequency2_bound_per_s2));
}

double deformed_frequency2_bound_per_s2(double rest_per_s2, double graph_per_s2, double end_displacement_ratio) {
  const double r = end_displacement_ratio;
  if (!(r < 0.5)) return std::max(rest_per_s2, graph_per_s2);  // the cap; NaN lands here too
  const double epsilon = r + r / (1.0 - r);
  return std::min(rest_per_s2 + epsilon * graph_per_s2, std::max(rest_per_s2, graph_per_s2));
}

ShortestSpring shortest_spring(const Body& body) {
  ShortestSpring out;
  for (std::size_t e = 0; e < body.edge_a.size(); ++e) {
    const NodeId a = body.edge_a[e], b = body.edge_b[e];
    if (!(body.stiffness_N_per_m[e] > 0.0) || !(body.rest_length_m[e] > 0.0)) continue;  // dead
    if (body.inv_mass_per_kg[a] == 0.0 && body.inv_mass_per_kg[b] == 0.0) continue;      // moves nothing
    const double ratio = (body.x_m[b] - body.x_m[a]).norm() / body.rest_length_m[e];
    if (!(ratio >= out.length_ratio)) out = {ratio, a, b};  // NaN wins: the caller refuses it
  }
  return out;
}

double collapse_factor(double length_ratio) {
  if (!(length_ratio > 0.0)) return INFINITY;  // collapsed, or NaN
  return std::max(1.0, 1.0 / length_ratio - 1.0);
}

bool state_is_finite(const Body& body) {
  constexpr double kLimit = 1e100;
  bool finite = true;
  // Component by component: a NaN fails every comparison, but Eigen's
  // maxCoeff() over a vector holding one may return another component
  // (a NaN in y or z passed as finite).
  const auto within = [](const Vec3& v) {
    return std::abs(v.x()) < kLimit && std::abs(v.y()) < kLimit && std::abs(v.z()) < kLimit;
  };
  body.mesh().for_each_node(
      [&](NodeId n, const mesh::Node&) { finite = finite && within(body.x_m[n]) && within(body.v_m_per_s[n]); });
  return finite;
}

namespace {

// max over n of |a[n] − b[n]|² (b = nullptr: of |a[n]|²), in four running
// maxima: one maximum runs as a chain of dependent instructions, which made
// this pass ~2.5 % of an undamped R3 step; four chains overlap. The maximum
// is exact, so the order does not change the result.
double max_squared_norm(const std::vector<Vec3>& a, const std::vector<Vec3>* b = nullptr) {
  double m[4] = {0.0, 0.0, 0.0, 0.0};
  const std::size_t count = a.size(), whole = count - count % 4;
  const auto at = [&](std::size_t n) { return b ? (a[n] - (*b)[n]).squaredNorm() : a[n].squaredNorm(); };
  for (std::size_t n = 0; n < whole; n += 4)
    for (int j = 0; j < 4; ++j) m[j] = std::max(m[j], at(n + j));
  for (std::size_t n = whole; n < count; ++n) m[0] = std::max(m[0], at(n));
  return std::max(std::max(m[0], m[1]), std::max(m[2], m[3]));
}

// --- Explicit kernels -------------------------------------------------------
// Scalar and AVX2 versions do the same operations in the same order (lane
// sums ((x + y) + (z + 0)), correctly rounded sqrt and division, no FMA):
// bit-identical results. F on a = (k (l − L) + c (v_b − v_a)·d̂) d̂, written
// as ((k (l − L) + c ((Δv·Δx) / l)) / l) Δx with one division.

// kDamped false: a stream whose every c is zero; velocities are not read and
// the damper term is left out (the damped formula with c = 0 gives the same
// bits: k (l − L) + 0 is exact).
template <bool kDamped>
void spring_scalar(const ExplicitSpringBatch& s, int j, const double* x, const double* v, const Vec3* rest_m,
                   double* f) {
  const std::uint32_t a4 = s.a4[j], b4 = s.b4[j];
  const double rest = s.rest_m[j], k = s.k_N_per_m[j], c = s.c_N_s_per_m[j];
  const double dx[3] = {x[b4] - x[a4], x[b4 + 1] - x[a4 + 1], x[b4 + 2] - x[a4 + 2]};
  double dv[3] = {0.0, 0.0, 0.0};
  if constexpr (kDamped)
    for (int i = 0; i < 3; ++i) dv[i] = v[b4 + i] - v[a4 + i];
  const double l2 = (dx[0] * dx[0] + dx[1] * dx[1]) + (dx[2] * dx[2] + 0.0);
  const double l = std::sqrt(l2);
  double force[3];
  if (l > kCollapsedSpringRatio * rest) {
    const double inv = 1.0 / l;
    double along = k * (l - rest);
    if constexpr (kDamped) {
      const double vd = (dv[0] * dx[0] + dv[1] * dx[1]) + (dv[2] * dx[2] + 0.0);
      along = along + c * (vd * inv);
    }
    const double coef = along * inv;
    for (int i = 0; i < 3; ++i) force[i] = coef * dx[i];
  } else {
    // Collapsed spring: the rest direction stands in (as spring_frame).
    Vec3 d = rest_m[b4 / 4] - rest_m[a4 / 4];
    const double r = d.norm();
    d = r > 0.0 ? Vec3(d / r) : Vec3::Zero();
    double magnitude = k * (l - rest);
    if constexpr (kDamped) magnitude = magnitude + c * (dv[0] * d.x() + dv[1] * d.y() + dv[2] * d.z());
    for (int i = 0; i < 3; ++i) force[i] = magnitude * d[i];
  }
  for (int i = 0; i < 3; ++i) {
    f[a4 + i] += force[i];
    f[b4 + i] -= force[i];
  }
}

template <bool kDamped>
void forces_scalar(const ExplicitSpringBatch* batches, std::size_t count, const Pad3* x, const Pad3* v,
                   const Vec3* rest_m, Pad3* f) {
  for (std::size_t i = 0; i < count; ++i)
    for (int j = 0; j < 4; ++j)
      spring_scalar<kDamped>(batches[i], j, x[0].v, kDamped ? v[0].v : nullptr, rest_m, f[0].v);
}

// v += h w f (then / (1 + h α) when damped), x += h v, f = f_ext: one pass.
void update_scalar(double h, double damping_divisor, const double* inv_mass, const Pad3* f_ext, Pad3* x, Pad3* v,
                   Pad3* f, std::size_t n) {
  for (std::size_t i = 0; i < n; ++i) {
    const double w = inv_mass[i];
    if (w != 0.0) {
      const double hw = h * w;
      for (int k = 0; k < 3; ++k) v[i].v[k] = v[i].v[k] + hw * f[i].v[k];
      if (damping_divisor != 1.0)
        for (int k = 0; k < 3; ++k) v[i].v[k] = v[i].v[k] / damping_divisor;
    }
    for (int k = 0; k < 3; ++k) x[i].v[k] = x[i].v[k] + h * v[i].v[k];
    f[i] = f_ext[i];
  }
}

#if defined(__x86_64__)
template <bool kDamped>
TISSUE_AVX2 void forces_avx2(const ExplicitSpringBatch* batches, std::size_t count, const Pad3* x_pad,
                             const Pad3* v_pad, const Vec3* rest_m, Pad3* f_pad) {
  const double* x = x_pad[0].v;
  const double* v = kDamped ? v_pad[0].v : nullptr;
  double* f = f_pad[0].v;
  const __m256d xyz = _mm256_castsi256_pd(_mm256_setr_epi64x(-1, -1, -1, 0));
  const __m256d collapse = _mm256_set1_pd(kCollapsedSpringRatio);
  for (std::size_t i = 0; i < count; ++i) {
    const ExplicitSpringBatch& s = batches[i];
    __m256d dx[4], dv[4];
    for (int j = 0; j < 4; ++j) {
      const std::uint32_t a4 = s.a4[j], b4 = s.b4[j];
      dx[j] = _mm256_sub_pd(_mm256_load_pd(x + b4), _mm256_load_pd(x + a4));
      if constexpr (kDamped) dv[j] = _mm256_sub_pd(_mm256_load_pd(v + b4), _mm256_load_pd(v + a4));
    }
    const __m256d l2 = lane_sums_avx2(_mm256_mul_pd(dx[0], dx[0]), _mm256_mul_pd(dx[1], dx[1]),
                                      _mm256_mul_pd(dx[2], dx[2]), _mm256_mul_pd(dx[3], dx[3]));
    const __m256d l = _mm256_sqrt_pd(l2);
    const __m256d rest = _mm256_loadu_pd(s.rest_m);
    if (_mm256_movemask_pd(_mm256_cmp_pd(l, _mm256_mul_pd(collapse, rest), _CMP_GT_OQ)) != 0xF) {
      forces_scalar<kDamped>(&s, 1, x_pad, v_pad, rest_m, f_pad);  // a collapsed (or non-finite) spring: rare
      continue;
    }
    const __m256d inv = _mm256_div_pd(_mm256_set1_pd(1.0), l);
    __m256d along = _mm256_mul_pd(_mm256_loadu_pd(s.k_N_per_m), _mm256_sub_pd(l, rest));
    if constexpr (kDamped) {
      const __m256d vd = lane_sums_avx2(_mm256_mul_pd(dv[0], dx[0]), _mm256_mul_pd(dv[1], dx[1]),
                                        _mm256_mul_pd(dv[2], dx[2]), _mm256_mul_pd(dv[3], dx[3]));
      along = _mm256_add_pd(along, _mm256_mul_pd(_mm256_loadu_pd(s.c_N_s_per_m), _mm256_mul_pd(vd, inv)));
    }
    alignas(32) double coef[4];
    _mm256_store_pd(coef, _mm256_mul_pd(along, inv));
    for (int j = 0; j < 4; ++j) {
      const __m256d force = _mm256_and_pd(_mm256_mul_pd(_mm256_broadcast_sd(coef + j), dx[j]), xyz);
      const std::uint32_t a4 = s.a4[j], b4 = s.b4[j];
      _mm256_store_pd(f + a4, _mm256_add_pd(_mm256_load_pd(f + a4), force));
      _mm256_store_pd(f + b4, _mm256_sub_pd(_mm256_load_pd(f + b4), force));
    }
  }
}

TISSUE_AVX2 void update_avx2(double h, double damping_divisor, const double* inv_mass, const Pad3* f_ext, Pad3* x,
                             Pad3* v, Pad3* f, std::size_t n) {
  const __m256d hv = _mm256_set1_pd(h), divisor = _mm256_set1_pd(damping_divisor);
  for (std::size_t i = 0; i < n; ++i) {
    __m256d vi = _mm256_load_pd(v[i].v);
    const double w = inv_mass[i];
    if (w != 0.0) {
      vi = _mm256_add_pd(vi, _mm256_mul_pd(_mm256_set1_pd(h * w), _mm256_load_pd(f[i].v)));
      if (damping_divisor != 1.0) vi = _mm256_div_pd(vi, divisor);
      _mm256_store_pd(v[i].v, vi);
    }
    _mm256_store_pd(x[i].v, _mm256_add_pd(_mm256_load_pd(x[i].v), _mm256_mul_pd(hv, vi)));
    _mm256_store_pd(f[i].v, _mm256_load_pd(f_ext[i].v));
  }
}
#endif

void update(Simd simd, double h, double damping_divisor, const double* inv_mass, const Pad3* f_ext, Pad3* x, Pad3* v,
            Pad3* f, std::size_t n) {
#if defined(__x86_64__)
  if (simd == Simd::kAvx2) return update_avx2(h, damping_divisor, inv_mass, f_ext, x, v, f, n);
#endif
  update_scalar(h, damping_divisor, inv_mass, f_ext, x, v, f, n);
}

Pad3 padded(const Vec3& v) { return Pad3{{v.x(), v.y(), v.z(), 0.0}}; }

}  // namespace

void explicit_spring_forces(Simd simd, const ExplicitSpringBatch* batches, std::size_t count, const Pad3* x,
                            const Pad3* v, const Vec3* rest_m, Pad3* f) {
#if defined(__x86_64__)
  if (simd == Simd::kAvx2)
    return v ? forces_avx2<true>(batches, count, x, v, rest_m, f) : forces_avx2<false>(batches, count, x, v, rest_m, f);
#endif
  if (v)
    forces_scalar<true>(batches, count, x, v, rest_m, f);
  else
    forces_scalar<false>(batches, count, x, v, rest_m, f);
}

ExplicitIntegrator::ExplicitIntegrator(const scene::IntegratorSpec& spec, const scene::MaterialSpec& material,
                                       Simd simd)
    : spec_(spec),
      alpha_per_s_(material.rayleigh_alpha_per_s),
      paper_damping_(material.damping == scene::DampingLaw::kPaper),
      simd_(simd) {}

void ExplicitIntegrator::build_layout(const Body& body) {
  bounds_ = explicit_bounds(body);
  rest_bound_per_s2_ = bounds_.rest_per_s2;
  stable_ = stable_step_at(0.0);
  end_displacement_ratio_ = -1.0;
  r_rise_bound_ = 0.0;
  shortest_rest_m_ = INFINITY;
  for (const EdgeId e : moving_springs(body))
    if (body.stiffness_N_per_m[e] > 0.0) shortest_rest_m_ = std::min(shortest_rest_m_, body.rest_length_m[e]);
  tightened_ = false;
  lanczos_.reset();
  lanczos_credit_ = 0.0;
  layout_substeps_ = 0;
  lanczos_wait_substeps_ =
      kLanczosWaitCostMultiple * kLanczosIterationCost *
      lanczos_iterations(3 * free_node_count(body), kLanczosRelativeGap, kLanczosFailureProbability);
  layout_version_ = body.parameters_version();
  // The offset layout where the mesh is a lattice (integrator_explicit_offset.cpp);
  // the gathered stream below everywhere else.
  offset_ = false;
  if (layout_choice_ != Layout::kGathered) {
    const bool force = layout_choice_ == Layout::kOffset;
    offset_ = single_precision() ? offset_float_.build(body, force) : offset_double_.build(body, force);
    if (offset_) return;
  }
  if (single_precision()) {
    float_.build(body);
    return;
  }
  const std::size_t nodes = body.x_m.size();
  const auto pad0 = static_cast<std::uint32_t>(4 * nodes), pad1 = pad0 + 4;
  batches_.clear();
  std::size_t filled = 0;
  for (const EdgeId e : moving_springs(body)) {
    const NodeId a = body.edge_a[e], b = body.edge_b[e];
    if (filled % 4 == 0) batches_.push_back({{pad0, pad0, pad0, pad0}, {pad1, pad1, pad1, pad1}, {1, 1, 1, 1}, {}, {}});
    ExplicitSpringBatch& batch = batches_.back();
    const std::size_t j = filled++ % 4;
    batch.a4[j] = static_cast<std::uint32_t>(4 * a);
    batch.b4[j] = static_cast<std::uint32_t>(4 * b);
    batch.rest_m[j] = body.rest_length_m[e];
    batch.k_N_per_m[j] = body.stiffness_N_per_m[e];
    batch.c_N_s_per_m[j] = body.damping_N_s_per_m[e];
  }
  damped_ = std::any_of(batches_.begin(), batches_.end(), [](const ExplicitSpringBatch& b) {
    return b.c_N_s_per_m[0] != 0.0 || b.c_N_s_per_m[1] != 0.0 || b.c_N_s_per_m[2] != 0.0 || b.c_N_s_per_m[3] != 0.0;
  });
  for (auto* v : {&x_, &v_, &f_, &f_ext_}) v->assign(nodes + 2, Pad3{});
  x_[nodes + 1].v[0] = 1.0;  // the filler springs: length 1 = rest, no stiffness
  inv_mass_.assign(nodes + 2, 0.0);
  std::copy(body.inv_mass_per_kg.begin(), body.inv_mass_per_kg.end(), inv_mass_.begin());
}

void ExplicitIntegrator::run_substeps(Body& body, const std::vector<Vec3>& f_ext_N, double h_s, int count) {
  if (body.parameters_version() != layout_version_) build_layout(body);
  load(body, f_ext_N);
  rest_m_ = body.rest_m.data();
  advance(h_s, count);
  store(body, count);
}

void ExplicitIntegrator::load(const Body& body, const std::vector<Vec3>& f_ext_N) {
  if (offset_) {
    if (single_precision())
      offset_float_.load(body, f_ext_N);
    else
      offset_double_.load(body, f_ext_N);
    return;
  }
  if (single_precision()) return float_.load(body, f_ext_N);
  for (std::size_t n = 0; n < body.x_m.size(); ++n) {
    x_[n] = padded(body.x_m[n]);
    v_[n] = padded(body.v_m_per_s[n]);
    f_ext_[n] = f_[n] = padded(f_ext_N[n]);
  }
}

void ExplicitIntegrator::advance(double h_s, int count, double* end_displacement_ratio, const Body* body) {
  if (offset_) {
    if (single_precision())
      offset_float_.substeps(simd_, h_s, alpha_per_s_, count, end_displacement_ratio);
    else
      offset_double_.substeps(simd_, h_s, alpha_per_s_, count, end_displacement_ratio);
    return;
  }
  // The gathered streams measure in a pass of their own, on the state reached.
  if (single_precision()) {
    float_.substeps(simd_, h_s, alpha_per_s_, count);
    if (end_displacement_ratio) *end_displacement_ratio = float_.end_displacement_ratio();
    return;
  }
  // Symplectic Euler (kick, then drift). Spring dampers are explicit so
  // every mode gets its exact Rayleigh ratio; the stable bound accounts for
  // them. Mass-proportional damping is taken implicitly (free of any bound).
  const std::size_t nodes = x_.size() - 2;
  const double divisor = 1.0 + h_s * alpha_per_s_;
  for (int s = 0; s < count; ++s) {
    explicit_spring_forces(simd_, batches_.data(), batches_.size(), x_.data(), damped_ ? v_.data() : nullptr, rest_m_,
                           f_.data());
    update(simd_, h_s, divisor, inv_mass_.data(), f_ext_.data(), x_.data(), v_.data(), f_.data(), nodes);
  }
  if (end_displacement_ratio) *end_displacement_ratio = measure_end_displacement_ratio(*body);
}

double ExplicitIntegrator::measure_end_displacement_ratio(const Body& body) const {
  if (offset_)
    return single_precision() ? offset_float_.end_displacement_ratio(simd_)
                              : offset_double_.end_displacement_ratio(simd_);
  if (single_precision()) return float_.end_displacement_ratio();
  double worst = 0.0;  // (|Δu| / L)²
  for (const ExplicitSpringBatch& s : batches_)
    for (int j = 0; j < 4; ++j) {
      if (!(s.k_N_per_m[j] > 0.0)) continue;  // filler
      const std::uint32_t a = s.a4[j] / 4, b = s.b4[j] / 4;
      const Vec3 du = (Vec3(x_[b].v[0], x_[b].v[1], x_[b].v[2]) - body.rest_m[b]) -
                      (Vec3(x_[a].v[0], x_[a].v[1], x_[a].v[2]) - body.rest_m[a]);
      worst = std::max(worst, du.squaredNorm() / (s.rest_m[j] * s.rest_m[j]));
    }
  return std::sqrt(worst);
}

ExplicitStableStep ExplicitIntegrator::stable_step_at(double end_displacement_ratio) const {
  return explicit_stable_step(
      bounds_, deformed_frequency2_bound_per_s2(rest_bound_per_s2_, bounds_.graph_per_s2, end_displacement_ratio));
}

bool ExplicitIntegrator::advanced_state_is_finite(const Body& body) const {
  if (offset_) return single_precision() ? offset_float_.finite() : offset_double_.finite();
  if (single_precision()) return float_.finite(body);
  constexpr double kLimit = 1e100;  // as state_is_finite
  bool finite = true;
  body.mesh().for_each_node([&](NodeId n, const mesh::Node&) {
    for (int k = 0; k < 3; ++k) finite = finite && std::abs(x_[n].v[k]) < kLimit && std::abs(v_[n].v[k]) < kLimit;
  });
  return finite;  // NaN fails every comparison, so it is caught too
}

void ExplicitIntegrator::store(Body& body, int substeps) const {
  // The one way a step reaches the body: the caller's hook sees the state
  // the step started from first (Simulation keeps it for a checked step).
  if (before_store_) before_store_->before_store(body, substeps);
  if (offset_) return single_precision() ? offset_float_.store(body) : offset_double_.store(body);
  if (single_precision()) return float_.store(body);
  for (std::size_t n = 0; n < body.x_m.size(); ++n) {
    body.x_m[n] = Vec3(x_[n].v[0], x_[n].v[1], x_[n].v[2]);
    body.v_m_per_s[n] = Vec3(v_[n].v[0], v_[n].v[1], v_[n].v[2]);
  }
}

void ExplicitIntegrator::spend_on_estimate(const Body& body, int substeps) {
  const std::int64_t before = layout_substeps_;
  layout_substeps_ += substeps;
  if (tightened_ || layout_substeps_ <= lanczos_wait_substeps_) return;
  if (!lanczos_) lanczos_.emplace(body, kLanczosRelativeGap, kLanczosFailureProbability);
  const auto paid = static_cast<double>(layout_substeps_ - std::max(before, lanczos_wait_substeps_));
  lanczos_credit_ += kLanczosShare * paid / static_cast<double>(kLanczosIterationCost);
  const int iterations = static_cast<int>(lanczos_credit_);
  lanczos_credit_ -= iterations;
  if (!lanczos_->iterate(iterations)) return;
  estimate_ = lanczos_->estimate();
  lanczos_.reset();
  if (estimate_.bound_per_s2 > 0.0) {
    rest_bound_per_s2_ = std::min(bounds_.rest_per_s2, estimate_.bound_per_s2);
    stable_ = stable_step_at(0.0);
  }
  tightened_ = true;
}

namespace {

constexpr const char* kNonFiniteRejected =
    "explicit integrator: state became non-finite; step rejected, previous state kept";

// The refusal when a step needs more than max_substeps. `limit_s` is the
// sub-step taken, `fraction` of the stable bound (substep_safety on the
// margin path; it was printed as "stable sub-step", which it is not).
std::string too_many_substeps(double dt_s, double needed, double limit_s, double fraction,
                              const ExplicitStableStep& stable, int max_substeps, bool paper_damping,
                              const char* bound_at = "") {
  std::ostringstream os;
  os << "explicit integrator: dt_s = " << dt_s << " needs " << needed << " sub-steps (sub-step " << limit_s
     << " s = " << fraction << " x the stable bound" << bound_at
     << "), more than integrator.max_substeps = " << max_substeps
     << "; lower dt_s, raise max_substeps, or use the implicit integrator";
  // Stiffness-proportional (or the paper's) spring dampers are explicit
  // here: say so when they, not the springs, set the sub-step.
  if (stable.dt_s < 0.5 * stable.undamped_dt_s)
    os << " (the spring dampers cut the stable sub-step " << std::setprecision(2) << stable.undamped_dt_s / stable.dt_s
       << (paper_damping ? "-fold: switch material.damping to rayleigh with a small rayleigh_beta_s"
                         : "-fold: lower material.rayleigh_beta_s")
       << ", or take the implicit integrator, which damps implicitly)";
  return os.str();
}

}  // namespace

double ExplicitIntegrator::last_substep_rise(const Body& body, double h_s) const {
  return 2.0 * h_s * std::sqrt(max_squared_norm(body.v_m_per_s)) / shortest_rest_m_;
}

int ExplicitIntegrator::verified_substeps(double dt_s, double end_displacement_ratio) const {
  const double fraction = verified_fraction();
  const double limit = fraction * stable_step_at(end_displacement_ratio).dt_s;
  const double needed = std::ceil(dt_s / limit);
  return needed <= spec_.max_substeps ? std::max(1, static_cast<int>(needed)) : spec_.max_substeps + 1;
}

StepOutcome ExplicitIntegrator::step(Body& body, const std::vector<Vec3>& f_ext_N, double dt_s) {
  if (body.parameters_version() != layout_version_) build_layout(body);
  rest_m_ = body.rest_m.data();
  StepOutcome out;
  out.offset_layout = offset_;
  // The margin as before: substep_safety of the rest bound, which allows
  // for stiffening under deformation without looking at it.
  const double limit = spec_.substep_safety * stable_.dt_s;
  const double needed = std::ceil(dt_s / limit);
  if (!(needed <= spec_.max_substeps)) {
    out.ok = false;
    out.error =
        too_many_substeps(dt_s, needed, limit, spec_.substep_safety, stable_, spec_.max_substeps, paper_damping_);
    return out;
  }
  int count = std::max(1, static_cast<int>(needed));
  // What a refusal below restores: the body is untouched then, so the
  // integrator must be too, or the step asked again (the service retries)
  // would run on r and growth from a run thrown away and be accepted.
  const double r_before = end_displacement_ratio_, growth_before = growth_per_step_, rise_before = r_rise_bound_;
  const int since_before = steps_since_measured_;
  const auto refuse = [&](std::string error) {
    end_displacement_ratio_ = r_before;
    growth_per_step_ = growth_before;
    r_rise_bound_ = rise_before;
    steps_since_measured_ = since_before;
    out.ok = false;
    out.error = std::move(error);
    return out;
  };
  // The sub-steps run on the integrator's own copy: the body changes only
  // when a result is accepted (no save and restore of the body needed).
  load(body, f_ext_N);
  // Fewer sub-steps where the deformation, measured, allows them (see
  // integrator_impl.hpp): taken only when it saves at least one, as the
  // measuring pass costs 0.4-0.8 of a sub-step.
  // Beyond r = ½ the deformed bound is only a cap (a spring may collapse), so
  // r is measured every step there and the shortest spring sets the count.
  // Also as soon as r may have reached ½ since it was measured (r_rise_bound_).
  if (end_displacement_ratio_ < 0.0 || end_displacement_ratio_ + r_rise_bound_ >= 0.5 ||
      steps_since_measured_ >= kRemeasureSteps) {
    end_displacement_ratio_ = measure_end_displacement_ratio(body);
    growth_per_step_ = 0.0;
    steps_since_measured_ = 0;
    r_rise_bound_ = 0.0;
  }
  ++steps_since_measured_;
  if (end_displacement_ratio_ >= 0.5) {
    // Within its bound or refused: the graph bound times the collapse factor
    // bounds every spring's stiffness, positive or negative. A spring
    // shrinking fast within one step is seen at the next.
    const ShortestSpring shortest = shortest_spring(body);
    const double factor = collapse_factor(shortest.length_ratio);
    const double collapse_limit = spec_.substep_safety * collapsed_stable_step(bounds_, factor).dt_s;
    const double collapse_needed = std::ceil(dt_s / collapse_limit);
    if (!(collapse_needed <= spec_.max_substeps)) {
      std::ostringstream os;
      os << "explicit integrator: the spring between nodes " << shortest.a << " and " << shortest.b
         << " is compressed to " << std::setprecision(3) << 100.0 * shortest.length_ratio
         << " % of its rest length, where no stable sub-step holds within integrator.max_substeps = "
         << spec_.max_substeps << " (dt_s = " << dt_s << " needs " << collapse_needed
         << "); step refused, previous state kept: the mesh is collapsing under its "
         << "loads; lower the loads or dt_s, or use the implicit integrator";
      out.ok = false;
      out.error = os.str();
      return out;
    }
    return run_and_accept(body, dt_s, std::max(count, static_cast<int>(collapse_needed)), out);
  }
  // Chosen for r grown by as much again as over the last step, so a load's
  // onset (r rising step after step) does not run steps twice.
  const int fewer = verified_substeps(dt_s, end_displacement_ratio_ + growth_per_step_);
  if (fewer < count) {
    double reached = 0.0;
    advance(dt_s / fewer, fewer, &reached, &body);
    if (!advanced_state_is_finite(body)) {
      out.ok = false;
      out.error = kNonFiniteRejected;
      return out;
    }
    if (verified_substeps(dt_s, reached) <= fewer) {
      steps_since_measured_ = 0;
      growth_per_step_ = std::max(0.0, reached - end_displacement_ratio_);
      end_displacement_ratio_ = reached;
      ++verified_steps_;
      out.substeps = fewer;
      out.verified_substeps = true;
      store(body, out.substeps);
      // On the offset layout r was measured at the last sub-step's forces,
      // i.e. at its start: its move (h times the velocity it ended with, the
      // drift of symplectic Euler) is added as r_rise_bound_ is in
      // run_and_accept. The gathered streams measured the state reached.
      r_rise_bound_ = offset_ ? last_substep_rise(body, dt_s / fewer) : 0.0;
      spend_on_estimate(body, out.substeps);
      return out;
    }
    // Within its bound or refused: where the bound at the state reached asks
    // for more than max_substeps, the step is refused (it was run at the
    // cap), the integrator's r left as it was so that asked again it is
    // refused again.
    const int asked = verified_substeps(dt_s, reached);
    if (asked > spec_.max_substeps) {
      const ExplicitStableStep at_reached = stable_step_at(reached);
      const double limit_s = verified_fraction() * at_reached.dt_s;
      return refuse(too_many_substeps(dt_s, std::ceil(dt_s / limit_s), limit_s, verified_fraction(), at_reached,
                                      spec_.max_substeps, paper_damping_, " at the deformation the step reached"));
    }
    // The state reached needs more: run the step again from the body, with
    // the margin as before or what the bound asks there, whichever is more.
    // r is measured again at the end of that run (run_and_accept), as on the
    // verified path: `reached` is of a state thrown away, and the next step
    // chooses its count from r (it read 0.3844 for a true 0.4080 of the
    // state kept: ExplicitIntegrator.AfterARerunTheIntegratorHolds...).
    ++rerun_steps_;
    out.rerun = true;
    count = std::max(count, asked);
    load(body, f_ext_N);
    return run_and_accept(body, dt_s, count, out, /*measure_r=*/true);
  } else if (verified_substeps(dt_s, end_displacement_ratio_) > spec_.max_substeps) {
    // The margin's count fits, but r, measured, asks for more than
    // max_substeps: within its bound or refused, as a rerun is. On an r
    // measured before this step (the body may have relaxed since) the step
    // is taken again on a fresh measurement first (once: it is fresh then).
    if (steps_since_measured_ > 1) {
      end_displacement_ratio_ = -1.0;
      return step(body, f_ext_N, dt_s);
    }
    const ExplicitStableStep at_r = stable_step_at(end_displacement_ratio_);
    const double limit_s = verified_fraction() * at_r.dt_s;
    return refuse(too_many_substeps(dt_s, std::ceil(dt_s / limit_s), limit_s, verified_fraction(), at_r,
                                    spec_.max_substeps, paper_damping_, " at the deformation measured"));
  }
  return run_and_accept(body, dt_s, count, out);
}

StepOutcome ExplicitIntegrator::run_and_accept(Body& body, double dt_s, int count, StepOutcome out, bool measure_r) {
  out.substeps = count;
  double reached = 0.0;
  advance(dt_s / count, count, measure_r ? &reached : nullptr, &body);
  if (!advanced_state_is_finite(body)) {
    out.ok = false;
    out.error = kNonFiniteRejected;
    return out;
  }
  if (measure_r) {
    // r of the state stored, as a verified step keeps it (see there): the
    // gathered streams measured the state reached, the offset layout the
    // last sub-step's start, whose move r_rise_bound_ then covers.
    steps_since_measured_ = 0;
    growth_per_step_ = std::max(0.0, reached - end_displacement_ratio_);
    end_displacement_ratio_ = reached;
    store(body, out.substeps);
    r_rise_bound_ = offset_ ? last_substep_rise(body, dt_s / count) : 0.0;
    spend_on_estimate(body, out.substeps);
    return out;
  }
  // How far the step moved the nodes bounds how far r rose (r_rise_bound_):
  // a copy and a pass over the nodes, no square root per spring.
  x_start_m_.assign(body.x_m.begin(), body.x_m.end());
  store(body, out.substeps);
  const double moved2_m2 = max_squared_norm(body.x_m, &x_start_m_);
  r_rise_bound_ += 2.0 * std::sqrt(moved2_m2) / shortest_rest_m_;
  spend_on_estimate(body, out.substeps);
  return out;
}

}  // namespace tissue::physics
