// The explicit sub-steps on the offset layout: a spring stream without
// gathers, transposes or scatters, for meshes whose nodes form a lattice.
//
// On a mesh whose tets all have one depth, numbering the nodes row by row
// (lexicographic in lattice z, then y; within a row, nodes of one kind
// together, in x order) makes most springs join positions p and p + δ for a
// handful of offsets δ that repeat along every row. Rows are split by parity
// (the Kuhn split alternates between neighbouring cubes) and, where that
// fills under 85 % of the lanes, also by each node's signature (its springs'
// lattice offsets), keeping the fuller: the signature finds the period of
// the depths 2 mod 3 too (beam at depth 11: 0.95-0.98 of the lanes filled,
// 0.26-0.45 by parity).
// Springs are then taken W at a time as (a0 + j, a0 + j + δ), j < W, a0 a
// multiple of W (W = 4 doubles or 8 floats, one AVX register): with the node
// state as structure of arrays, both ends' coordinates are plain vector
// loads and both ends' forces plain vector read-modify-writes. The gathered
// stream (integrator_explicit.cpp) spends ~half its time on per-spring
// 128/256-bit loads, lane transposes and scattered stores (physics_bench
// BM_ExplicitAccessFloor); here they are gone. Lanes with no spring are
// masked (k = 0).
//
// Batches sharing a0 form a group: the a-side forces are summed in registers
// and written once per group; δ = 1 (springs between neighbours in the
// numbering, whose b-side overlaps the a-side) is folded in by rotating its
// forces one lane and carrying the last lane into the next group, so no
// store is reloaded at an offset (a store-forwarding stall). Other offsets
// below W (short rows) run as plain read-modify-writes: correct, slower.
//
// An adaptively refined mesh has ~40 % of its lanes filled in lattice order
// (the cantilever refined to depth 9, 8x10^4 springs: 0.39-0.40 float,
// measured while planning), where the gathered stream costs less, so the
// layout is taken only when every tet has one depth and at least
// kMinOffsetFill of the lanes hold a spring.
//
// The per-spring arithmetic is that of the gathered kernels (double: position
// form; float: displacement form, see integrator_explicit_float.cpp); the
// summation order into the nodes differs, so the two layouts agree to
// rounding, not bit for bit. Scalar and AVX2 kernels of this layout do the
// same operations in the same order: bit-identical.
//
// How much of the float sub-step is its arithmetic (2026-11-25, a timing
// probe, not kept: AvxFloat::force with its square root and divisions
// replaced by multiplications; BM_ExplicitSubstep/{0,3}/0/{0,1}/1/0, three
// rounds alternating with the shipped kernel, the other core busy): 10-17 %
// faster (10^3 springs damped 2.25-2.29 -> 1.93-1.95 ns per spring, 7x10^3
// undamped 1.64-1.73 -> 1.37-1.41), still 2.97-3.08x the bandwidth bound
// measured beside it (three more runs of the probe, 11 of 12 readings).
// So no cheaper square root or division (an approximate reciprocal square
// root included, which would also give different bits on different CPUs)
// brings this layout within 2x of the bound at cache-resident sizes: the
// loads, stores and lane shuffles of the group loop are most of it.
//
// Nodes numbered in blocks of 32 or 64 distinct x values (2026-11-26, Intel
// host with 2 MB L2; tried for 1.6x10^6 springs, where the signature order's
// offsets reach 11,761 positions and the sub-step costs ~2x per spring what
// it costs at 4x10^5): no faster there (double damped 6.5-6.8 vs 6.2-6.6 ns
// per spring), up to 18 % slower below, as the cross-block springs fill one lane
// each (fill 0.92-0.98 -> 0.80-0.93). Not kept; docs/performance.md.
#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <tuple>
#include <type_traits>
#include <vector>

#include "physics/forces.hpp"
#include "physics/integrator_impl.hpp"

namespace tissue::physics {

namespace {

template <typename Real>
using OffsetBatch = std::conditional_t<std::is_same_v<Real, float>, OffsetBatchF, OffsetBatchD>;

// --- One lane, scalar: the reference the AVX2 kernels match bit for bit ---

// Force on the lower end of lane j (zero for an empty lane), double:
// positions x, the gathered kernel's formula and collapse fallback.
template <bool kDamped>
void lane_force(const OffsetBatchD& s, int j, std::size_t stride, const double* x, const double* v,
                const Vec3* rest_by_position, double force[3]) {
  const std::uint32_t a = s.a0 + j, b = s.b0 + j;
  double dx[3], dv[3] = {0.0, 0.0, 0.0};
  for (int i = 0; i < 3; ++i) dx[i] = x[i * stride + b] - x[i * stride + a];
  if constexpr (kDamped)
    for (int i = 0; i < 3; ++i) dv[i] = v[i * stride + b] - v[i * stride + a];
  const double k = s.k_N_per_m[j], rest = s.rest_m[j];
  if (!(k > 0.0)) {  // empty lane
    for (int i = 0; i < 3; ++i) force[i] = 0.0 * dx[i];
    return;
  }
  const double l = std::sqrt((dx[0] * dx[0] + dx[1] * dx[1]) + (dx[2] * dx[2] + 0.0));
  if (l > kCollapsedSpringRatio * rest) {
    const double inv = 1.0 / l;
    double along = k * (l - rest);
    if constexpr (kDamped) {
      const double vd = (dv[0] * dx[0] + dv[1] * dx[1]) + (dv[2] * dx[2] + 0.0);
      along = along + s.c_N_s_per_m[j] * (vd * inv);
    }
    const double coef = along * inv;
    for (int i = 0; i < 3; ++i) force[i] = coef * dx[i];
    return;
  }
  // Collapsed: the rest direction stands in (as the gathered kernels).
  Vec3 d = rest_by_position[b] - rest_by_position[a];
  const double r = d.norm();
  d = r > 0.0 ? Vec3(d / r) : Vec3::Zero();
  double magnitude = k * (l - rest);
  if constexpr (kDamped) magnitude = magnitude + s.c_N_s_per_m[j] * (dv[0] * d.x() + dv[1] * d.y() + dv[2] * d.z());
  for (int i = 0; i < 3; ++i) force[i] = magnitude * d[i];
}

// Float: displacements u and rest edge vectors, as spring_float_scalar.
template <bool kDamped>
void lane_force(const OffsetBatchF& s, int j, std::size_t stride, const float* u, const float* v, const Vec3*,
                float force[3]) {
  const std::uint32_t a = s.a0 + j, b = s.b0 + j;
  const float e[3] = {s.ex[j], s.ey[j], s.ez[j]};
  const float rest = s.rest_m[j], k = s.k_N_per_m[j];
  float du[3];
  for (int i = 0; i < 3; ++i) du[i] = u[i * stride + b] - u[i * stride + a];
  const float d[3] = {e[0] + du[0], e[1] + du[1], e[2] + du[2]};
  if (!(k > 0.0f)) {  // empty lane
    for (int i = 0; i < 3; ++i) force[i] = 0.0f * d[i];
    return;
  }
  const float ed = (e[0] * du[0] + e[1] * du[1]) + e[2] * du[2];
  const float dd = (du[0] * du[0] + du[1] * du[1]) + du[2] * du[2];
  const float stretch = (ed + ed) + dd;
  const float l2 = rest * rest + stretch;
  const float near_collapse = 0.01f * rest;
  float dv[3] = {0.0f, 0.0f, 0.0f};
  if constexpr (kDamped)
    for (int i = 0; i < 3; ++i) dv[i] = v[i * stride + b] - v[i * stride + a];
  if (l2 > near_collapse * near_collapse) {
    const float l = std::sqrt(l2);
    float along = (k * stretch) / (l + rest);
    if constexpr (kDamped) {
      const float vd = (dv[0] * d[0] + dv[1] * d[1]) + dv[2] * d[2];
      along = along + s.c_N_s_per_m[j] * (vd / l);
    }
    const float coef = along / l;
    for (int i = 0; i < 3; ++i) force[i] = coef * d[i];
    return;
  }
  const float l = std::sqrt((d[0] * d[0] + d[1] * d[1]) + d[2] * d[2]);
  const bool collapsed = !(l > 1e-6f * rest);
  float dir[3];
  for (int i = 0; i < 3; ++i) dir[i] = collapsed ? e[i] / rest : d[i] / l;
  float magnitude = k * (l - rest);
  if constexpr (kDamped)
    magnitude = magnitude + s.c_N_s_per_m[j] * ((dv[0] * dir[0] + dv[1] * dir[1]) + dv[2] * dir[2]);
  for (int i = 0; i < 3; ++i) force[i] = magnitude * dir[i];
}

// (|Δu| / L)² over the springs, largest (integrator.hpp,
// deformed_frequency2_bound_per_s2): Δu from displacements x (float) or
// positions x minus rest positions (double, rest non-null); empty lanes 0.
template <typename Real>
Real end_ratio2_scalar(const OffsetBatch<Real>* batches, std::size_t count, std::size_t stride, const Real* x,
                       const Real* rest) {
  constexpr int W = OffsetBatch<Real>::kLanes;
  Real worst = 0;
  for (std::size_t q = 0; q < count; ++q) {
    const OffsetBatch<Real>& s = batches[q];
    for (int j = 0; j < W; ++j) {
      Real dd = 0;
      for (int i = 0; i < 3; ++i) {
        const std::size_t a = i * stride + s.a0 + j, b = i * stride + s.b0 + j;
        Real du = x[b] - x[a];
        if (rest) du = du - (rest[b] - rest[a]);
        dd = dd + du * du;
      }
      const Real ratio2 = s.k_N_per_m[j] != Real(0) ? dd / (s.rest_m[j] * s.rest_m[j]) : Real(0);
      worst = std::max(worst, ratio2);
    }
  }
  return worst;
}

// The group loop, scalar. Per group: the a-side sum starts at zero and takes
// each batch's forces; δ = 1 batches go to `next` rotated one lane (lane
// j + 1 gets lane j, lane 0 the last), the others are subtracted at b0 in
// memory; then lane 0 of the sum takes off the previous group's carried
// lane, lanes 1.. the rotated ones, and the sum is added at a0.
// kMeasure: also the largest (|Δu| / L)² into *worst (end_ratio2_scalar).
template <typename Real, bool kDamped, bool kMeasure>
void forces_scalar(const OffsetBatch<Real>* batches, const OffsetGroup* groups, std::size_t group_count,
                   std::size_t stride, const Real* x, const Real* v, const Vec3* rest_by_position, Real* f,
                   const Real* rest, Real* worst) {
  constexpr int W = OffsetBatch<Real>::kLanes;
  Real carry[3][W] = {};
  std::uint32_t expect = 0;
  for (std::size_t g = 0; g < group_count; ++g) {
    const std::uint32_t a0 = groups[g].a0;
    if (a0 != expect) {
      for (int i = 0; i < 3; ++i) {
        f[i * stride + expect] -= carry[i][0];
        for (int j = 0; j < W; ++j) carry[i][j] = Real(0);
      }
    }
    Real sum[3][W] = {}, next[3][W] = {};
    for (std::uint32_t q = groups[g].first; q < groups[g].end; ++q) {
      const OffsetBatch<Real>& s = batches[q];
      Real force[W][3];
      for (int j = 0; j < W; ++j) lane_force<kDamped>(s, j, stride, x, v, rest_by_position, force[j]);
      if constexpr (kMeasure) *worst = std::max(*worst, end_ratio2_scalar<Real>(&s, 1, stride, x, rest));
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < W; ++j) sum[i][j] = sum[i][j] + force[j][i];
      if (s.b0 == a0 + 1) {
        for (int i = 0; i < 3; ++i)
          for (int j = 0; j < W; ++j) next[i][j] = force[(j + W - 1) % W][i];
      } else {
        for (int i = 0; i < 3; ++i)
          for (int j = 0; j < W; ++j) f[i * stride + s.b0 + j] = f[i * stride + s.b0 + j] - force[j][i];
      }
    }
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < W; ++j) {
        sum[i][j] = sum[i][j] - (j == 0 ? carry[i][0] : next[i][j]);
        f[i * stride + a0 + j] = f[i * stride + a0 + j] + sum[i][j];
      }
      for (int j = 0; j < W; ++j) carry[i][j] = next[i][j];
    }
    expect = a0 + W;
  }
  for (int i = 0; i < 3; ++i) f[i * stride + expect] -= carry[i][0];
}

// v += h w f (then / (1 + h α)) where w ≠ 0, x += h v, f = f_ext: elementwise
// over the three component arrays (the same bits however it is vectorised).
template <typename Real>
void update_plain(Real h, Real divisor, const Real* inv_mass, std::size_t stride, const Real* f_ext, Real* x, Real* v,
                  Real* f) {
  for (int i = 0; i < 3; ++i) {
    Real* xi = x + i * stride;
    Real* vi = v + i * stride;
    Real* fi = f + i * stride;
    const Real* ei = f_ext + i * stride;
    for (std::size_t p = 0; p < stride; ++p) {
      const Real w = inv_mass[p];
      if (w != Real(0)) {
        Real vp = vi[p] + (h * w) * fi[p];
        if (divisor != Real(1)) vp = vp / divisor;
        vi[p] = vp;
      }
      xi[p] = xi[p] + h * vi[p];
      fi[p] = ei[p];
    }
  }
}

#if defined(__x86_64__)
// --- AVX2: the same operations, W lanes at a time ---

struct AvxDouble {
  using Real = double;
  using V = __m256d;
  static constexpr int W = 4;
  TISSUE_AVX2 static V zero() { return _mm256_setzero_pd(); }
  TISSUE_AVX2 static V load(const double* p) { return _mm256_loadu_pd(p); }
  TISSUE_AVX2 static void store(double* p, V a) { _mm256_storeu_pd(p, a); }
  TISSUE_AVX2 static V add(V a, V b) { return _mm256_add_pd(a, b); }
  TISSUE_AVX2 static V sub(V a, V b) { return _mm256_sub_pd(a, b); }
  // Lane j + 1 gets lane j, lane 0 the last.
  TISSUE_AVX2 static V rotate(V a) { return _mm256_permute4x64_pd(a, _MM_SHUFFLE(2, 1, 0, 3)); }
  // Lane 0 from b, the others from a.
  TISSUE_AVX2 static V lane0_from(V a, V b) { return _mm256_blend_pd(a, b, 1); }
  TISSUE_AVX2 static double first(V a) { return _mm256_cvtsd_f64(a); }
  TISSUE_AVX2 static V splat(double a) { return _mm256_set1_pd(a); }
  TISSUE_AVX2 static V mul(V a, V b) { return _mm256_mul_pd(a, b); }
  TISSUE_AVX2 static V div(V a, V b) { return _mm256_div_pd(a, b); }
  TISSUE_AVX2 static V not_zero(V a) { return _mm256_cmp_pd(a, zero(), _CMP_NEQ_UQ); }
  TISSUE_AVX2 static V select(V mask, V yes, V no) { return _mm256_blendv_pd(no, yes, mask); }
  TISSUE_AVX2 static V max(V a, V b) { return _mm256_max_pd(a, b); }

  // The batch's forces on its lower ends; false when a spring is collapsed
  // (the caller then takes the scalar lanes).
  // kMeasure: d gets the position differences (for the deformation measure).
  template <bool kDamped, bool kMeasure>
  TISSUE_AVX2 static bool force(const OffsetBatchD& s, std::size_t stride, const double* x, const double* v,
                                const V (&xa)[3], const V (&va)[3], V (&F)[3], V (&d)[3]) {
    const std::uint32_t b = s.b0;
    V dx[3];
    for (int i = 0; i < 3; ++i) dx[i] = sub(load(x + i * stride + b), xa[i]);
    if constexpr (kMeasure)
      for (int i = 0; i < 3; ++i) d[i] = dx[i];
    const V k = load(s.k_N_per_m), rest = load(s.rest_m);
    const V lane = _mm256_cmp_pd(k, zero(), _CMP_GT_OQ);
    const V l2 = _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(dx[0], dx[0]), _mm256_mul_pd(dx[1], dx[1])),
                               _mm256_add_pd(_mm256_mul_pd(dx[2], dx[2]), zero()));
    const V l = _mm256_sqrt_pd(l2);
    const V ok = _mm256_or_pd(_mm256_cmp_pd(l, _mm256_mul_pd(_mm256_set1_pd(kCollapsedSpringRatio), rest), _CMP_GT_OQ),
                              _mm256_andnot_pd(lane, _mm256_castsi256_pd(_mm256_set1_epi64x(-1))));
    if (_mm256_movemask_pd(ok) != 0xF) return false;
    const V inv = _mm256_div_pd(_mm256_set1_pd(1.0), l);
    V along = _mm256_mul_pd(k, _mm256_sub_pd(l, rest));
    if constexpr (kDamped) {
      V dv[3];
      for (int i = 0; i < 3; ++i) dv[i] = sub(load(v + i * stride + b), va[i]);
      const V vd = _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(dv[0], dx[0]), _mm256_mul_pd(dv[1], dx[1])),
                                 _mm256_add_pd(_mm256_mul_pd(dv[2], dx[2]), zero()));
      along = _mm256_add_pd(along, _mm256_mul_pd(load(s.c_N_s_per_m), _mm256_mul_pd(vd, inv)));
    }
    const V coef = _mm256_and_pd(_mm256_mul_pd(along, inv), lane);
    for (int i = 0; i < 3; ++i) F[i] = _mm256_mul_pd(coef, dx[i]);
    return true;
  }
};

struct AvxFloat {
  using Real = float;
  using V = __m256;
  static constexpr int W = 8;
  TISSUE_AVX2 static V zero() { return _mm256_setzero_ps(); }
  TISSUE_AVX2 static V load(const float* p) { return _mm256_loadu_ps(p); }
  TISSUE_AVX2 static void store(float* p, V a) { _mm256_storeu_ps(p, a); }
  TISSUE_AVX2 static V add(V a, V b) { return _mm256_add_ps(a, b); }
  TISSUE_AVX2 static V sub(V a, V b) { return _mm256_sub_ps(a, b); }
  TISSUE_AVX2 static V rotate(V a) { return _mm256_permutevar8x32_ps(a, _mm256_setr_epi32(7, 0, 1, 2, 3, 4, 5, 6)); }
  TISSUE_AVX2 static V lane0_from(V a, V b) { return _mm256_blend_ps(a, b, 1); }
  TISSUE_AVX2 static float first(V a) { return _mm256_cvtss_f32(a); }
  TISSUE_AVX2 static V splat(float a) { return _mm256_set1_ps(a); }
  TISSUE_AVX2 static V mul(V a, V b) { return _mm256_mul_ps(a, b); }
  TISSUE_AVX2 static V div(V a, V b) { return _mm256_div_ps(a, b); }
  TISSUE_AVX2 static V not_zero(V a) { return _mm256_cmp_ps(a, zero(), _CMP_NEQ_UQ); }
  TISSUE_AVX2 static V select(V mask, V yes, V no) { return _mm256_blendv_ps(no, yes, mask); }
  TISSUE_AVX2 static V max(V a, V b) { return _mm256_max_ps(a, b); }

  // kMeasure: d gets the displacement differences (the deformation measure's Δu).
  template <bool kDamped, bool kMeasure>
  TISSUE_AVX2 static bool force(const OffsetBatchF& s, std::size_t stride, const float* u, const float* v,
                                const V (&ua)[3], const V (&va)[3], V (&F)[3], V (&d)[3]) {
    const std::uint32_t b = s.b0;
    V du[3];
    for (int i = 0; i < 3; ++i) du[i] = sub(load(u + i * stride + b), ua[i]);
    if constexpr (kMeasure)
      for (int i = 0; i < 3; ++i) d[i] = du[i];
    const V ex = load(s.ex), ey = load(s.ey), ez = load(s.ez), rest = load(s.rest_m), k = load(s.k_N_per_m);
    const V lane = _mm256_cmp_ps(k, zero(), _CMP_GT_OQ);
    const V ed =
        _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(ex, du[0]), _mm256_mul_ps(ey, du[1])), _mm256_mul_ps(ez, du[2]));
    const V dd = _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(du[0], du[0]), _mm256_mul_ps(du[1], du[1])),
                               _mm256_mul_ps(du[2], du[2]));
    const V stretch = _mm256_add_ps(_mm256_add_ps(ed, ed), dd);
    const V l2 = _mm256_add_ps(_mm256_mul_ps(rest, rest), stretch);
    const V limit = _mm256_mul_ps(_mm256_set1_ps(0.01f), rest);
    const V ok = ok_or_empty(_mm256_cmp_ps(l2, _mm256_mul_ps(limit, limit), _CMP_GT_OQ), lane);
    if (_mm256_movemask_ps(ok) != 0xFF) return false;
    const V l = _mm256_sqrt_ps(l2);
    const V dx = _mm256_add_ps(ex, du[0]), dy = _mm256_add_ps(ey, du[1]), dz = _mm256_add_ps(ez, du[2]);
    V along = _mm256_div_ps(_mm256_mul_ps(k, stretch), _mm256_add_ps(l, rest));
    if constexpr (kDamped) {
      V dv[3];
      for (int i = 0; i < 3; ++i) dv[i] = sub(load(v + i * stride + b), va[i]);
      const V vd =
          _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(dv[0], dx), _mm256_mul_ps(dv[1], dy)), _mm256_mul_ps(dv[2], dz));
      along = _mm256_add_ps(along, _mm256_mul_ps(load(s.c_N_s_per_m), _mm256_div_ps(vd, l)));
    }
    const V coef = _mm256_and_ps(_mm256_div_ps(along, l), lane);
    F[0] = _mm256_mul_ps(coef, dx);
    F[1] = _mm256_mul_ps(coef, dy);
    F[2] = _mm256_mul_ps(coef, dz);
    return true;
  }
  // ok | !lane: an empty lane never asks for the scalar path.
  TISSUE_AVX2 static V ok_or_empty(V ok, V lane) {
    return _mm256_or_ps(ok, _mm256_andnot_ps(lane, _mm256_castsi256_ps(_mm256_set1_epi32(-1))));
  }
};

// update_plain, W nodes at a time (w = 0 lanes keep their velocity).
template <class K>
TISSUE_AVX2 void update_avx2(typename K::Real h, typename K::Real divisor, const typename K::Real* inv_mass,
                             std::size_t stride, const typename K::Real* f_ext, typename K::Real* x,
                             typename K::Real* v, typename K::Real* f) {
  using V = typename K::V;
  const V hv = K::splat(h), divisor_v = K::splat(divisor);
  const bool divide = divisor != typename K::Real(1);
  for (std::size_t p = 0; p < stride; p += K::W) {
    const V w = K::load(inv_mass + p);
    const V free = K::not_zero(w);
    const V hw = K::mul(hv, w);
    for (int i = 0; i < 3; ++i) {
      const std::size_t at = i * stride + p;
      const V vi = K::load(v + at);
      V kicked = K::add(vi, K::mul(hw, K::load(f + at)));
      if (divide) kicked = K::div(kicked, divisor_v);
      const V vn = K::select(free, kicked, vi);
      K::store(v + at, vn);
      K::store(x + at, K::add(K::load(x + at), K::mul(hv, vn)));
      K::store(f + at, K::load(f_ext + at));
    }
  }
}

template <class K, bool kDamped, bool kMeasure>
TISSUE_AVX2 void forces_avx2(const OffsetBatch<typename K::Real>* batches, const OffsetGroup* groups,
                             std::size_t group_count, std::size_t stride, const typename K::Real* x,
                             const typename K::Real* v, const Vec3* rest_by_position, typename K::Real* f,
                             const typename K::Real* rest, typename K::Real* worst_out) {
  using Real = typename K::Real;
  using V = typename K::V;
  constexpr int W = K::W;
  V worst = K::zero();
  V carry[3] = {K::zero(), K::zero(), K::zero()};
  std::uint32_t expect = 0;
  for (std::size_t g = 0; g < group_count; ++g) {
    const std::uint32_t a0 = groups[g].a0;
    if (a0 != expect) {
      for (int i = 0; i < 3; ++i) {
        f[i * stride + expect] -= K::first(carry[i]);
        carry[i] = K::zero();
      }
    }
    V sum[3] = {K::zero(), K::zero(), K::zero()}, next[3] = {K::zero(), K::zero(), K::zero()};
    // The a-side state, loaded once per group.
    V xa[3], va[3], ra[3];
    for (int i = 0; i < 3; ++i) {
      xa[i] = K::load(x + i * stride + a0);
      va[i] = kDamped ? K::load(v + i * stride + a0) : K::zero();
      if constexpr (kMeasure) ra[i] = rest ? K::load(rest + i * stride + a0) : K::zero();
    }
    for (std::uint32_t q = groups[g].first; q < groups[g].end; ++q) {
      const OffsetBatch<Real>& s = batches[q];
      V F[3], d[3];
      const bool vector_lanes = K::template force<kDamped, kMeasure>(s, stride, x, v, xa, va, F, d);
      if constexpr (kMeasure) {
        // end_ratio2_scalar's operations, lane by lane: Δu = d (float), or
        // d minus the rest positions' difference (double).
        V dd = K::zero();
        for (int i = 0; i < 3; ++i) {
          const V du = rest ? K::sub(d[i], K::sub(K::load(rest + i * stride + s.b0), ra[i])) : d[i];
          dd = K::add(dd, K::mul(du, du));
        }
        const V r = K::load(s.rest_m);
        worst = K::max(worst, K::select(K::not_zero(K::load(s.k_N_per_m)), K::div(dd, K::mul(r, r)), K::zero()));
      }
      if (!vector_lanes) {
        alignas(32) Real lanes[3][W];
        for (int j = 0; j < W; ++j) {
          Real one[3];
          lane_force<kDamped>(s, j, stride, x, v, rest_by_position, one);
          for (int i = 0; i < 3; ++i) lanes[i][j] = one[i];
        }
        for (int i = 0; i < 3; ++i) F[i] = K::load(lanes[i]);
      }
      for (int i = 0; i < 3; ++i) sum[i] = K::add(sum[i], F[i]);
      if (s.b0 == a0 + 1) {
        for (int i = 0; i < 3; ++i) next[i] = K::rotate(F[i]);
      } else {
        for (int i = 0; i < 3; ++i) {
          Real* fb = f + i * stride + s.b0;
          K::store(fb, K::sub(K::load(fb), F[i]));
        }
      }
    }
    for (int i = 0; i < 3; ++i) {
      Real* fa = f + i * stride + a0;
      sum[i] = K::sub(sum[i], K::lane0_from(next[i], carry[i]));
      K::store(fa, K::add(K::load(fa), sum[i]));
      carry[i] = next[i];
    }
    expect = a0 + W;
  }
  for (int i = 0; i < 3; ++i) f[i * stride + expect] -= K::first(carry[i]);
  if constexpr (kMeasure) {
    alignas(32) Real lanes[W];
    K::store(lanes, worst);
    for (int j = 0; j < W; ++j) *worst_out = std::max(*worst_out, lanes[j]);
  }
}
#endif

#if defined(__x86_64__)
template <class K>
TISSUE_AVX2 typename K::Real end_ratio2_avx2(const OffsetBatch<typename K::Real>* batches, std::size_t count,
                                             std::size_t stride, const typename K::Real* x,
                                             const typename K::Real* rest) {
  using V = typename K::V;
  V worst = K::zero();
  for (std::size_t q = 0; q < count; ++q) {
    const OffsetBatch<typename K::Real>& s = batches[q];
    V dd = K::zero();
    for (int i = 0; i < 3; ++i) {
      V du = K::sub(K::load(x + i * stride + s.b0), K::load(x + i * stride + s.a0));
      if (rest) du = K::sub(du, K::sub(K::load(rest + i * stride + s.b0), K::load(rest + i * stride + s.a0)));
      dd = K::add(dd, K::mul(du, du));
    }
    const V r = K::load(s.rest_m);
    const V ratio2 = K::select(K::not_zero(K::load(s.k_N_per_m)), K::div(dd, K::mul(r, r)), K::zero());
    worst = K::max(worst, ratio2);
  }
  alignas(32) typename K::Real lanes[K::W];
  K::store(lanes, worst);
  return *std::max_element(lanes, lanes + K::W);
}
#endif

// Two numberings in which a lattice's springs repeat their offsets along
// each row. Rows split by parity: lexicographic (z, y, x), then within each
// row every other node first, then the rest.
std::vector<NodeId> order_by_parity(const Body& body, std::vector<NodeId> nodes) {
  const auto key = [&](NodeId n) {
    const mesh::Vec3i& p = body.mesh().node(n).lattice;
    return std::make_tuple(p[2], p[1], p[0]);
  };
  std::sort(nodes.begin(), nodes.end(), [&](NodeId a, NodeId b) { return key(a) < key(b); });
  // Within each row, every other node first, then the rest: the cubes of the
  // lattice alternate their Kuhn split (reflected neighbours), so a diagonal
  // spring leaves every other node of a row; split by parity, a run of
  // consecutive positions has the same springs.
  std::vector<NodeId> row, odd;
  for (std::size_t begin = 0; begin < nodes.size();) {
    const mesh::Vec3i& first = body.mesh().node(nodes[begin]).lattice;
    std::size_t end = begin;
    while (end < nodes.size() && body.mesh().node(nodes[end]).lattice[1] == first[1] &&
           body.mesh().node(nodes[end]).lattice[2] == first[2])
      ++end;
    std::int64_t gap = 0;
    for (std::size_t i = begin + 1; i < end; ++i) {
      const std::int64_t d = body.mesh().node(nodes[i]).lattice[0] - body.mesh().node(nodes[i - 1]).lattice[0];
      gap = gap == 0 ? d : std::min(gap, d);
    }
    if (gap > 0) {
      row.clear();
      odd.clear();
      for (std::size_t i = begin; i < end; ++i)
        (((body.mesh().node(nodes[i]).lattice[0] - first[0]) / gap) % 2 == 0 ? row : odd).push_back(nodes[i]);
      row.insert(row.end(), odd.begin(), odd.end());
      std::copy(row.begin(), row.end(), nodes.begin() + static_cast<std::ptrdiff_t>(begin));
    }
    begin = end;
  }
  return nodes;
}

// Rows split by the kind of node: nodes with the same lattice offsets to
// their neighbours (a signature) together, each kind in x order. Finds the
// period of any lattice — it fills the depths 2 mod 3 (rows mixing face and
// cube centres) that the parity split leaves at 0.26-0.45 — but splits off
// every node of a boundary row whose neighbours the boundary cuts.
std::vector<NodeId> order_by_signature(const Body& body, std::vector<NodeId> nodes) {
  // Each node's signature: the lattice offsets of its springs, sorted.
  std::vector<std::vector<std::array<std::int64_t, 3>>> offsets(body.x_m.size());
  body.mesh().for_each_edge([&](EdgeId, const mesh::Edge& edge) {
    const mesh::Vec3i& a = body.mesh().node(edge.a).lattice;
    const mesh::Vec3i& b = body.mesh().node(edge.b).lattice;
    offsets[edge.a].push_back({b[0] - a[0], b[1] - a[1], b[2] - a[2]});
    offsets[edge.b].push_back({a[0] - b[0], a[1] - b[1], a[2] - b[2]});
  });
  std::map<std::vector<std::array<std::int64_t, 3>>, int> kinds;
  std::vector<int> kind(body.x_m.size(), 0);
  for (const NodeId n : nodes) {
    std::sort(offsets[n].begin(), offsets[n].end());
    kind[n] = kinds.emplace(offsets[n], static_cast<int>(kinds.size())).first->second;
  }
  const auto key = [&](NodeId n) {
    const mesh::Vec3i& p = body.mesh().node(n).lattice;
    return std::make_tuple(p[2], p[1], kind[n], p[0]);
  };
  std::sort(nodes.begin(), nodes.end(), [&](NodeId a, NodeId b) { return key(a) < key(b); });
  return nodes;
}

OffsetPlan plan_in_order(const Body& body, int lanes, std::vector<NodeId> order) {
  OffsetPlan plan;
  plan.node_at = std::move(order);
  const std::size_t nodes = plan.node_at.size();
  std::vector<std::uint32_t> position(body.x_m.size(), 0);
  for (std::size_t p = 0; p < nodes; ++p) position[plan.node_at[p]] = static_cast<std::uint32_t>(p);
  plan.stride = (nodes + 2 * static_cast<std::size_t>(lanes) - 1) / lanes * lanes;  // ≥ nodes + W − 1, whole vectors
  struct Entry {
    std::uint32_t a0, b0, lane;
    EdgeId edge;
  };
  std::vector<Entry> entries;
  for (const EdgeId e : moving_springs(body)) {
    std::uint32_t p = position[body.edge_a[e]], q = position[body.edge_b[e]];
    if (p > q) std::swap(p, q);
    const std::uint32_t a0 = p - p % lanes;
    entries.push_back({a0, a0 + (q - p), p - a0, e});
  }
  std::sort(entries.begin(), entries.end(),
            [](const Entry& x, const Entry& y) { return std::tie(x.a0, x.b0, x.lane) < std::tie(y.a0, y.b0, y.lane); });
  for (const Entry& entry : entries) {
    if (plan.batches.empty() || plan.batches.back().a0 != entry.a0 || plan.batches.back().b0 != entry.b0) {
      OffsetPlan::Batch batch{entry.a0, entry.b0, {}};
      batch.edge.fill(mesh::kInvalidId);
      plan.batches.push_back(batch);
      const auto index = static_cast<std::uint32_t>(plan.batches.size() - 1);
      if (plan.groups.empty() || plan.groups.back().a0 != entry.a0) plan.groups.push_back({entry.a0, index, index});
      plan.groups.back().end = index + 1;
    }
    plan.batches.back().edge[entry.lane] = entry.edge;
  }
  plan.fill = plan.batches.empty() ? 0.0
                                   : static_cast<double>(entries.size()) /
                                         (static_cast<double>(lanes) * static_cast<double>(plan.batches.size()));
  return plan;
}

}  // namespace

bool mesh_has_one_depth(const Body& body) {
  int depth = -1;
  bool one = true;
  body.mesh().for_each_tet([&](TetId, const mesh::Tet& t) {
    if (depth < 0) depth = t.depth;
    one = one && t.depth == depth;
  });
  return one;
}

OffsetPlan plan_offset_layout(const Body& body, int lanes) {
  // The parity order first (the cheaper: no per-node signatures); the
  // signature order too unless parity already fills kParityEnough of the
  // lanes, and the one filling more is kept.
  constexpr double kParityEnough = 0.85;
  std::vector<NodeId> live;
  body.mesh().for_each_node([&](NodeId n, const mesh::Node&) { live.push_back(n); });
  OffsetPlan by_parity = plan_in_order(body, lanes, order_by_parity(body, live));
  if (by_parity.fill >= kParityEnough) return by_parity;
  OffsetPlan by_signature = plan_in_order(body, lanes, order_by_signature(body, live));
  return by_signature.fill > by_parity.fill ? by_signature : by_parity;
}

template <typename Real>
void offset_spring_forces(Simd simd, const OffsetBatch<Real>* batches, const OffsetGroup* groups,
                          std::size_t group_count, std::size_t stride, const Real* x, const Real* v,
                          const Vec3* rest_by_position, Real* f, const Real* rest, Real* worst_ratio2) {
  const bool measure = worst_ratio2 != nullptr;
#if defined(__x86_64__)
  using K = std::conditional_t<std::is_same_v<Real, float>, AvxFloat, AvxDouble>;
  if (simd == Simd::kAvx2) {
    if (measure)
      return v ? forces_avx2<K, true, true>(batches, groups, group_count, stride, x, v, rest_by_position, f, rest,
                                            worst_ratio2)
               : forces_avx2<K, false, true>(batches, groups, group_count, stride, x, v, rest_by_position, f, rest,
                                             worst_ratio2);
    return v ? forces_avx2<K, true, false>(batches, groups, group_count, stride, x, v, rest_by_position, f, rest,
                                           nullptr)
             : forces_avx2<K, false, false>(batches, groups, group_count, stride, x, v, rest_by_position, f, rest,
                                            nullptr);
  }
#endif
  if (measure) {
    if (v)
      forces_scalar<Real, true, true>(batches, groups, group_count, stride, x, v, rest_by_position, f, rest,
                                      worst_ratio2);
    else
      forces_scalar<Real, false, true>(batches, groups, group_count, stride, x, v, rest_by_position, f, rest,
                                       worst_ratio2);
    return;
  }
  if (v)
    forces_scalar<Real, true, false>(batches, groups, group_count, stride, x, v, rest_by_position, f, rest, nullptr);
  else
    forces_scalar<Real, false, false>(batches, groups, group_count, stride, x, v, rest_by_position, f, rest, nullptr);
}

template <typename Real>
void offset_update(Simd simd, Real h, Real divisor, const Real* inv_mass, std::size_t stride, const Real* f_ext,
                   Real* x, Real* v, Real* f) {
#if defined(__x86_64__)
  using K = std::conditional_t<std::is_same_v<Real, float>, AvxFloat, AvxDouble>;
  if (simd == Simd::kAvx2) return update_avx2<K>(h, divisor, inv_mass, stride, f_ext, x, v, f);
#endif
  update_plain<Real>(h, divisor, inv_mass, stride, f_ext, x, v, f);
}

template void offset_spring_forces<double>(Simd, const OffsetBatchD*, const OffsetGroup*, std::size_t, std::size_t,
                                           const double*, const double*, const Vec3*, double*, const double*, double*);
template void offset_spring_forces<float>(Simd, const OffsetBatchF*, const OffsetGroup*, std::size_t, std::size_t,
                                          const float*, const float*, const Vec3*, float*, const float*, float*);

template <typename Real>
bool ExplicitOffsetState<Real>::build(const Body& body, bool force) {
  constexpr int W = Batch::kLanes;
  *this = ExplicitOffsetState<Real>{};
  if (!force && !mesh_has_one_depth(body)) return false;
  OffsetPlan plan = plan_offset_layout(body, W);
  fill_ = plan.fill;
  if (!force && plan.fill < kMinOffsetFill) return false;
  node_at_ = std::move(plan.node_at);
  stride_ = plan.stride;
  groups_ = std::move(plan.groups);
  batches_.assign(plan.batches.size(), Batch{});
  damped_ = false;
  rest_by_position_.assign(stride_, Vec3::Zero());
  for (std::size_t p = 0; p < node_at_.size(); ++p) rest_by_position_[p] = body.rest_m[node_at_[p]];
  for (std::size_t q = 0; q < batches_.size(); ++q) {
    const OffsetPlan::Batch& planned = plan.batches[q];
    Batch& batch = batches_[q];
    batch.a0 = planned.a0;
    batch.b0 = planned.b0;
    for (int j = 0; j < W; ++j) {
      const EdgeId e = planned.edge[j];
      // An empty lane: k = 0 masks it; rest 1 keeps its arithmetic finite.
      Real rest = Real(1), k = Real(0), c = Real(0);
      if (e != mesh::kInvalidId) {
        // k > 0 tells a spring from an empty lane; a spring without
        // stiffness (not made by eq. (3)) keeps the gathered stream.
        if (!(body.stiffness_N_per_m[e] > 0.0) || !(static_cast<Real>(body.stiffness_N_per_m[e]) > Real(0))) {
          const double fill = fill_;
          *this = ExplicitOffsetState<Real>{};
          fill_ = fill;
          return false;
        }
        k = static_cast<Real>(body.stiffness_N_per_m[e]);
        c = static_cast<Real>(body.damping_N_s_per_m[e]);
        rest = static_cast<Real>(body.rest_length_m[e]);
        damped_ = damped_ || c != Real(0);
      }
      if constexpr (std::is_same_v<Real, float>) {
        const Vec3 edge = rest_by_position_[planned.b0 + j] - rest_by_position_[planned.a0 + j];
        batch.ex[j] = e != mesh::kInvalidId ? static_cast<float>(edge.x()) : 1.0f;
        batch.ey[j] = e != mesh::kInvalidId ? static_cast<float>(edge.y()) : 0.0f;
        batch.ez[j] = e != mesh::kInvalidId ? static_cast<float>(edge.z()) : 0.0f;
        // L from the rounded edge: exactly zero force at rest.
        if (e != mesh::kInvalidId)
          rest = std::sqrt((batch.ex[j] * batch.ex[j] + batch.ey[j] * batch.ey[j]) + batch.ez[j] * batch.ez[j]);
      }
      batch.rest_m[j] = rest;
      batch.k_N_per_m[j] = k;
      batch.c_N_s_per_m[j] = c;
    }
  }
  for (auto* a : {&x_, &v_, &f_, &f_ext_}) a->assign(3 * stride_, Real(0));
  if constexpr (std::is_same_v<Real, float>) {
    x0_.assign(3 * stride_, 0.0f);
    v0_.assign(3 * stride_, 0.0f);
  } else {
    rest_.assign(3 * stride_, 0.0);
    for (std::size_t p = 0; p < node_at_.size(); ++p)
      for (int i = 0; i < 3; ++i) rest_[i * stride_ + p] = body.rest_m[node_at_[p]][i];
  }
  inv_mass_.assign(stride_, Real(0));
  for (std::size_t p = 0; p < node_at_.size(); ++p) inv_mass_[p] = static_cast<Real>(body.inv_mass_per_kg[node_at_[p]]);
  return true;
}

template <typename Real>
void ExplicitOffsetState<Real>::load(const Body& body, const std::vector<Vec3>& f_ext_N) {
  for (std::size_t p = 0; p < node_at_.size(); ++p) {
    const NodeId n = node_at_[p];
    // Float keeps displacements from rest (integrator_explicit_float.cpp).
    const Vec3 x = std::is_same_v<Real, float> ? Vec3(body.x_m[n] - body.rest_m[n]) : body.x_m[n];
    for (int i = 0; i < 3; ++i) {
      x_[i * stride_ + p] = static_cast<Real>(x[i]);
      v_[i * stride_ + p] = static_cast<Real>(body.v_m_per_s[n][i]);
      f_[i * stride_ + p] = f_ext_[i * stride_ + p] = static_cast<Real>(f_ext_N[n][i]);
    }
  }
  if constexpr (std::is_same_v<Real, float>) {
    x0_ = x_;  // same size: copies, no allocation
    v0_ = v_;
  }
}

template <typename Real>
void ExplicitOffsetState<Real>::substeps(Simd simd, double h_s, double alpha_per_s, int count,
                                         double* end_displacement_ratio) {
  h_s_ = h_s;
  count_ = count;
  const auto h = static_cast<Real>(h_s);
  // Double divides every sub-step; float on FloatMassDamping's schedule, the
  // rest left to store().
  int every = 1;
  auto divisor = static_cast<Real>(1.0 + h_s * alpha_per_s);
  if constexpr (std::is_same_v<Real, float>) {
    const FloatMassDamping damping(h_s, alpha_per_s);
    every = damping.every;
    divisor = damping.divisor;
    leftover_divisor_ = damping.leftover_divisor(count);
  }
  const Real* rest = std::is_same_v<Real, double> ? rest_.data() : nullptr;
  Real worst = 0;
  int since_division = 0;
  for (int s = 0; s < count; ++s) {
    const bool measure = end_displacement_ratio != nullptr && s + 1 == count;
    offset_spring_forces<Real>(simd, batches_.data(), groups_.data(), groups_.size(), stride_, x_.data(),
                               damped_ ? v_.data() : nullptr, rest_by_position_.data(), f_.data(), rest,
                               measure ? &worst : nullptr);
    const bool divide = ++since_division == every;
    if (divide) since_division = 0;
    offset_update<Real>(simd, h, divide ? divisor : Real(1), inv_mass_.data(), stride_, f_ext_.data(), x_.data(),
                        v_.data(), f_.data());
  }
  if (end_displacement_ratio) *end_displacement_ratio = std::sqrt(static_cast<double>(worst));
}

template <typename Real>
bool ExplicitOffsetState<Real>::finite() const {
  // As state_is_finite (double) and ExplicitFloatState::finite (float).
  const Real limit = std::is_same_v<Real, float> ? Real(1e30f) : Real(1e100);
  // Branch-free over whole arrays (vectorised; the padding positions hold
  // zeros): the check was a tenth of a loaded R3 step with short-circuits.
  // NaN fails every comparison. The flag's form is what GCC 12 vectorises:
  // an int OR in float, a select in double (neither does both).
  if constexpr (std::is_same_v<Real, float>) {
    std::int32_t bad = 0;
    for (const std::vector<Real>* a : {&x_, &v_})
      for (const Real value : *a) bad |= !(std::abs(value) < limit);
    return bad == 0;
  } else {
    Real bad = 0;
    for (const std::vector<Real>* a : {&x_, &v_})
      for (const Real value : *a) bad = std::abs(value) < limit ? bad : Real(1);
    return bad == Real(0);
  }
}

template <typename Real>
double ExplicitOffsetState<Real>::end_displacement_ratio(Simd simd) const {
  const Real* rest = std::is_same_v<Real, double> ? rest_.data() : nullptr;
  Real worst;
#if defined(__x86_64__)
  using K = std::conditional_t<std::is_same_v<Real, float>, AvxFloat, AvxDouble>;
  if (simd == Simd::kAvx2)
    worst = end_ratio2_avx2<K>(batches_.data(), batches_.size(), stride_, x_.data(), rest);
  else
#endif
    worst = end_ratio2_scalar<Real>(batches_.data(), batches_.size(), stride_, x_.data(), rest);
  return std::sqrt(static_cast<double>(worst));
}

template <typename Real>
void ExplicitOffsetState<Real>::store(Body& body) const {
  for (std::size_t p = 0; p < node_at_.size(); ++p) {
    const NodeId n = node_at_[p];
    if constexpr (std::is_same_v<Real, double>) {
      for (int i = 0; i < 3; ++i) {
        body.x_m[n][i] = x_[i * stride_ + p];
        body.v_m_per_s[n][i] = v_[i * stride_ + p];
      }
    } else {
      const float u[3] = {x_[p], x_[stride_ + p], x_[2 * stride_ + p]};
      const float v[3] = {v_[p], v_[stride_ + p], v_[2 * stride_ + p]};
      const float u0[3] = {x0_[p], x0_[stride_ + p], x0_[2 * stride_ + p]};
      const float v0[3] = {v0_[p], v0_[stride_ + p], v0_[2 * stride_ + p]};
      store_float_stepped_node(body, n, inv_mass_[p] == 0.0f, u, v, u0, v0, h_s_, count_, leftover_divisor_);
    }
  }
}

template <typename Real>
double ExplicitOffsetState<Real>::stream_bytes_per_spring() const {
  constexpr int W = Batch::kLanes;
  std::size_t springs = 0;
  for (const Batch& b : batches_)
    for (int j = 0; j < W; ++j) springs += b.k_N_per_m[j] > Real(0) ? 1 : 0;
  if (springs == 0) return 0.0;
  // Per lane: rest length, stiffness (float: and the rest edge vector), and
  // with dampers the damping coefficient.
  const std::size_t lane_reals = (std::is_same_v<Real, float> ? 5 : 2) + (damped_ ? 1 : 0);
  const std::size_t bytes = batches_.size() * (2 * sizeof(std::uint32_t) + W * lane_reals * sizeof(Real)) +
                            groups_.size() * sizeof(OffsetGroup);
  return static_cast<double>(bytes) / static_cast<double>(springs);
}

template void offset_update<double>(Simd, double, double, const double*, std::size_t, const double*, double*, double*,
                                    double*);
template void offset_update<float>(Simd, float, float, const float*, std::size_t, const float*, float*, float*, float*);

template class ExplicitOffsetState<double>;
template class ExplicitOffsetState<float>;

}  // namespace tissue::physics
