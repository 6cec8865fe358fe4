// Backward Euler (Baraff & Witkin 1998) with the clamped spring Hessian (Choi
// & Ko 2002): solve (M' − h D − h² K) Δv = h (f + h K v), M' = (1 + h α) M, by
// preconditioned CG (Jacobi; or two-level, integrator_implicit_two_level.cpp,
// which cg_preconditioner: auto picks from 1,000 free nodes) warm-started
// from the last step's Δv where that start is nearer the solution than zero.
//
// Cost is the CG matvec: per spring per iteration two gathers, two scatters
// and ~20 flops. Measured with bench/physics_bench (Release, 2-core Debian 12
// box shared with builds, so median thread-CPU time per step; exact-geometry
// beam stand-ins for PERFORMANCE.md's R2 = 7,056 / R3 = 52,344 springs, cg20,
// dt = 1 ms): before 1.04 / 7.80 ms, after 0.82 / 6.3 ms (117–125 ns per
// spring per step, was 150–190; ~11x an explicit sub-step, was 15–19x).
// What the numbers supported:
//  - Compact blocks: B = along d̂d̂ᵀ + iso I stored as d̂ and two scalars in
//    one 48 B record with the two unknown ids, streamed in edge order (was
//    ids, stiffness and a 72 B Matrix3d from four arrays, 15 flops/product).
//  - Dead and fully kinematic springs dropped once when the list is built;
//    unknowns numbered compactly (free nodes only, kinematic ends point at a
//    sink slot whose p stays zero): no per-matvec stiffness test or masking.
//  - Forces, K v, the blocks and the Jacobi diagonal in one pass over edges.
//  - CG fused: p = z + βp with ap = M'p in one node pass; dv, r, z and both
//    dots in one; scratch resized only, never re-zeroed. pᵀAp from a node
//    pass after the spring loop: accumulating dpᵀB dp inside the spring loop
//    was 10% slower (6.3 vs 7.2 ms at R3); with AVX2 (a 4-lane accumulator,
//    pᵀM'p in the node pass) it measured R2 +2 %, R3 ±1 %, 4x10^5 springs
//    −4 % (load 4.5): not kept. Again on single-precision records with two
//    accumulators (even and odd springs; 2026-11-25, idle machine, three
//    rounds alternating, BM_Step/implicit_cg20 ns per spring): 7x10^3
//    71.4-72.9 vs 69.6-71.7, 5x10^4 74.6-75.3 vs 72.8-75.6, 4x10^5 88-93 vs
//    89-110, 1.6x10^6 138-152 vs 133-139; ImplicitVsExplicitSubstep/9
//    24.0-24.9 vs 23.5-25.4: within noise, not kept.
//  - The spring loop is instruction-bound (~50 scalar SSE2 instructions, ~4 ns
//    per spring per matvec, IPC ~3.5); hand-written scalar code ran the same
//    as Eigen's.
//  - AVX2 (chosen at run time, integrator_simd.hpp): node vectors padded to
//    4 doubles, one 256-bit load/store per gather/scatter, B = eeᵀ + iso I
//    with e = √along d̂ (one multiply fewer per product), ~25 instructions
//    per spring; the node passes in AVX2 too; the setup pass through raw
//    pointers with one division per spring instead of four. Same session,
//    load 2-4 (median thread CPU per cg20 step, dt = 1 ms): R2 0.65 -> 0.47-
//    0.52 ms, R3 5.3 -> 4.3-4.6 ms. Split at R2: matvec ~50 %, setup pass
//    ~23 %, node passes ~20 %. The matvec runs ~1.5 ns (~4 cycles) per spring:
//    issue-bound on its shuffles and loads, not on memory order (see
//    build_layout). FMA would save one instruction but break bit-identity
//    with the scalar kernel.
//  - Assembled block-CSR (full symmetric 3x3 blocks, row-wise gather, no
//    scatter) lost at both sizes: 0.97 / 8.6 ms vs 0.82 / 6.5 ms matrix-free
//    (BM_ImplicitMatvec): the assembly is an extra pass and each edge is read
//    twice as a 76 B entry. Kept as an option; a test checks they agree.
//  - Block-Jacobi (3x3 per node) needed more iterations than Jacobi at the
//    1e-6 tolerance (R2 38.8 -> 42.5, R3 77.5 -> 80.3), so Jacobi stays.
//  - Two-level preconditioner (an option): integrator_implicit_two_level.cpp.
//  - Tried and dropped (2026-11-25): the matvec on the explicit sub-steps'
//    offset layout (integrator_explicit_offset.cpp; blocks four to a batch
//    between lattice positions, written into the lanes after the setup pass),
//    with p and the springs' part of ap transposed to and from structure of
//    arrays by position around each product. A benchmark alternating it with
//    this matvec on copies of one body (cg20, not kept) ran 1.07-1.20x
//    slower per step, Jacobi and two-level, 10^3-4x10^5 springs: on its own
//    the offset product is ~1.4-1.6 ns per spring (issue-bound like this one
//    at cache-resident sizes, ahead only where this one waits on memory), and
//    the transposes eat the rest. It would need the CG vectors, the setup
//    pass and the coarse correction in the layout's order throughout.
//  - Records in single precision (2026-11-25, later): e and iso as floats
//    scaled by a power of two per step (ImplicitIntegrator::step), widened
//    by one vcvtps2pd, products in double; 24 instead of 40 B per spring.
//    Where the data fits in cache it changes nothing (BM_ImplicitMatvec, R2
//    66-67 vs 66-67, R3 72-79 vs 71-73 ns per spring per cg20 step, the
//    other core busy): the matvec does not wait on its record stream there.
//    At 4x10^5 springs, where records and CG vectors outgrew L3, a cg20 step
//    took 99-110 instead of 138-147 ns per spring, at 1.6x10^6 149-163
//    instead of 167-179 (BM_Step/implicit_cg20, three rounds alternating).
//    Tried and dropped the same day: a non-temporal prefetch of the records
//    24 ahead (to keep p and ap in L2), 1-4 % slower. A perf profile of a
//    cg20 step at 4x10^5 springs after the change: matvec 63 %, setup pass
//    13 %, node passes (update, prepare, dot) 20 %, the rest 4 %; at 5x10^4
//    before it 62 / 14 / 18 / 6 %. With a product costing about one explicit
//    sub-step, 21 products are ~21 sub-steps: the 25x target leaves little
//    around them.
//  - Tried and dropped (2026-11-26, Intel Xeon with AVX-512): two springs
//    per 512-bit register (the same operations per spring, no FMA, the
//    scatters still one 256-bit read-modify-write per end). Env-switched,
//    two rounds alternating, BM_ImplicitVsExplicitSubstep, Jacobi cg20 over
//    the offset sub-step: 10^3 springs 22.9-23.1 vs 19.5-20.5 without, 7x10^3
//    26.1-27.8 vs 25.5-25.7, 5x10^4 28.6-29.2 vs 29.2, 4x10^5 27.0-27.1 vs
//    26.0-27.9, 1.6x10^6 26.7-26.9 vs 26.2-30.5: no gain.
// Everything is sequential in a fixed order: bit-identical reruns.
#include <algorithm>
#include <cmath>
#include <limits>

#include "physics/forces.hpp"
#include "physics/integrator_impl.hpp"

namespace tissue::physics {

namespace {

// --- Kernels over the padded unknown vectors -------------------------------
// Scalar and AVX2 versions do the same operations in the same order (lanes
// summed as ((x + y) + z) + w, no FMA): bit-identical results.

void matvec_scalar(const ImplicitSpring* springs, std::size_t count, const Pad3* p_pad, Pad3* ap_pad) {
  const double* p = p_pad[0].v;
  double* ap = ap_pad[0].v;
  for (std::size_t i = 0; i < count; ++i) {
    const ImplicitSpring& s = springs[i];
    const std::uint32_t a4 = s.a4, b4 = s.b4;
    const double dp[3] = {p[a4] - p[b4], p[a4 + 1] - p[b4 + 1], p[a4 + 2] - p[b4 + 2]};
    const double e[3] = {s.e[0], s.e[1], s.e[2]};
    const double dot = (e[0] * dp[0] + e[1] * dp[1]) + (e[2] * dp[2] + 0.0);
    const double iso = s.iso;
    for (int k = 0; k < 3; ++k) {
      const double q = dot * e[k] + iso * dp[k];
      ap[a4 + k] += q;
      ap[b4 + k] -= q;
    }
  }
}

// p = z + beta p (when update_p), ap = m p; lane 3 stays 0.
void prepare_scalar(bool update_p, double beta, const double* mass, const Pad3* z, Pad3* p, Pad3* ap, std::size_t n) {
  for (std::size_t i = 0; i < n; ++i)
    for (int k = 0; k < 4; ++k) {
      if (update_p) p[i].v[k] = z[i].v[k] + beta * p[i].v[k];
      ap[i].v[k] = mass[i] * p[i].v[k];
    }
}

double dot_scalar(const Pad3* a, const Pad3* b, std::size_t n) {
  double acc[4] = {0.0, 0.0, 0.0, 0.0};
  for (std::size_t i = 0; i < n; ++i)
    for (int k = 0; k < 4; ++k) acc[k] += a[i].v[k] * b[i].v[k];
  return ((acc[0] + acc[1]) + acc[2]) + acc[3];
}

// dv += step p, r −= step_ap ap (ap in the records' scale: step_ap is
// step times it), z = D⁻¹ r; returns rᵀz and rᵀr.
void update_scalar(double step, double step_ap, const Pad3* p, const Pad3* ap, const Pad3* diag_inv, Pad3* dv, Pad3* r,
                   Pad3* z, std::size_t n, double* rz, double* rr) {
  double acc_rz[4] = {0.0, 0.0, 0.0, 0.0}, acc_rr[4] = {0.0, 0.0, 0.0, 0.0};
  for (std::size_t i = 0; i < n; ++i)
    for (int k = 0; k < 4; ++k) {
      dv[i].v[k] += step * p[i].v[k];
      r[i].v[k] -= step_ap * ap[i].v[k];
      z[i].v[k] = diag_inv[i].v[k] * r[i].v[k];
      acc_rz[k] += r[i].v[k] * z[i].v[k];
      acc_rr[k] += r[i].v[k] * r[i].v[k];
    }
  *rz = ((acc_rz[0] + acc_rz[1]) + acc_rz[2]) + acc_rz[3];
  *rr = ((acc_rr[0] + acc_rr[1]) + acc_rr[2]) + acc_rr[3];
}

#if defined(__x86_64__)
TISSUE_AVX2 void matvec_avx2(const ImplicitSpring* springs, std::size_t count, const Pad3* p_pad, Pad3* ap_pad) {
  const double* p = p_pad[0].v;
  double* ap = ap_pad[0].v;
  const __m256d xyz = _mm256_castsi256_pd(_mm256_setr_epi64x(-1, -1, -1, 0));
  for (std::size_t i = 0; i < count; ++i) {
    const ImplicitSpring& s = springs[i];
    const std::uint32_t a4 = s.a4, b4 = s.b4;  // read before the stores: no reload
    const __m256d dp = _mm256_sub_pd(_mm256_load_pd(p + a4), _mm256_load_pd(p + b4));
    const __m256d e_iso = _mm256_cvtps_pd(_mm_loadu_ps(s.e));
    const __m256d e = _mm256_and_pd(e_iso, xyz);  // drops iso from lane 3
    const __m256d prod = _mm256_mul_pd(e, dp);
    const __m256d pairs = _mm256_add_pd(prod, _mm256_permute_pd(prod, 0b0101));         // x+y, y+x, z+w, w+z
    const __m256d dot = _mm256_add_pd(pairs, _mm256_permute2f128_pd(pairs, pairs, 1));  // (x+y)+(z+w) in all
    const __m256d q = _mm256_add_pd(_mm256_mul_pd(dot, e), _mm256_mul_pd(_mm256_permute4x64_pd(e_iso, 0xFF), dp));
    _mm256_store_pd(ap + a4, _mm256_add_pd(_mm256_load_pd(ap + a4), q));
    _mm256_store_pd(ap + b4, _mm256_sub_pd(_mm256_load_pd(ap + b4), q));
  }
}

TISSUE_AVX2 void prepare_avx2(bool update_p, double beta, const double* mass, const Pad3* z, Pad3* p, Pad3* ap,
                              std::size_t n) {
  const __m256d b = _mm256_set1_pd(beta);
  for (std::size_t i = 0; i < n; ++i) {
    __m256d pi = _mm256_load_pd(p[i].v);
    if (update_p) {
      pi = _mm256_add_pd(_mm256_load_pd(z[i].v), _mm256_mul_pd(b, pi));
      _mm256_store_pd(p[i].v, pi);
    }
    _mm256_store_pd(ap[i].v, _mm256_mul_pd(_mm256_broadcast_sd(mass + i), pi));
  }
}

TISSUE_AVX2 double dot_avx2(const Pad3* a, const Pad3* b, std::size_t n) {
  __m256d acc = _mm256_setzero_pd();
  for (std::size_t i = 0; i < n; ++i)
    acc = _mm256_add_pd(acc, _mm256_mul_pd(_mm256_load_pd(a[i].v), _mm256_load_pd(b[i].v)));
  return sum_lanes_avx2(acc);
}

TISSUE_AVX2 void update_avx2(double step, double step_ap, const Pad3* p, const Pad3* ap, const Pad3* diag_inv, Pad3* dv,
                             Pad3* r, Pad3* z, std::size_t n, double* rz, double* rr) {
  const __m256d a = _mm256_set1_pd(step), a_ap = _mm256_set1_pd(step_ap);
  __m256d acc_rz = _mm256_setzero_pd(), acc_rr = _mm256_setzero_pd();
  for (std::size_t i = 0; i < n; ++i) {
    _mm256_store_pd(dv[i].v, _mm256_add_pd(_mm256_load_pd(dv[i].v), _mm256_mul_pd(a, _mm256_load_pd(p[i].v))));
    const __m256d ri = _mm256_sub_pd(_mm256_load_pd(r[i].v), _mm256_mul_pd(a_ap, _mm256_load_pd(ap[i].v)));
    const __m256d zi = _mm256_mul_pd(_mm256_load_pd(diag_inv[i].v), ri);
    _mm256_store_pd(r[i].v, ri);
    _mm256_store_pd(z[i].v, zi);
    acc_rz = _mm256_add_pd(acc_rz, _mm256_mul_pd(ri, zi));
    acc_rr = _mm256_add_pd(acc_rr, _mm256_mul_pd(ri, ri));
  }
  *rz = sum_lanes_avx2(acc_rz);
  *rr = sum_lanes_avx2(acc_rr);
}
#endif

// --- The setup pass: one pass over the springs per step ---------------------
// Per spring: its force and damper force, K v (clamped Hessian), into
// rhs += ±h (f − h K v); the Jacobi diagonal; the compact record. Both
// instruction sets in the same order (vector lanes only where the scalar
// code repeats an operation per component): bit-identical.
struct SetupInput {
  const double* stiffness;
  const double* damping;
  const double* rest_length;
  const NodeId* edge_a;
  const NodeId* edge_b;
  const Vec3* x;
  const Vec3* v;
  const Vec3* rest_position;
  const std::uint32_t* unknown_of_node;
  double h;
  // The records' power-of-two scale (ImplicitIntegrator::step): e times
  // record_scale, iso times its square.
  double record_scale, record_scale2;
};

// The scalars of one spring after its direction and relative velocity.
struct SpringScalars {
  double f_mag, kad, k_iso, along, iso, root_along;
};

inline SpringScalars spring_scalars(double k, double c, double rest, double length, double inv_length, double dvd,
                                    double h) {
  // Clamped Hessian: the transverse term only while stretched keeps the
  // system positive definite (Choi & Ko 2002).
  const double transverse = length > rest ? 1.0 - rest * inv_length : 0.0;
  const double k_along = k * (1.0 - transverse), k_iso = k * transverse;
  const double along = h * c + (h * h) * k_along;
  return {k * (length - rest) - c * dvd, k_along * dvd, k_iso, along, (h * h) * k_iso, std::sqrt(along)};
}

void setup_spring_scalar(const SetupInput& in, EdgeId e, Pad3* rhs, Pad3* diag, ImplicitSpring* record) {
  const NodeId na = in.edge_a[e], nb = in.edge_b[e];
  const std::uint32_t a = in.unknown_of_node[na], b = in.unknown_of_node[nb];
  const double k = in.stiffness[e], c = in.damping[e], rest = in.rest_length[e], h = in.h;
  const Vec3& xa = in.x[na];
  const Vec3& xb = in.x[nb];
  const double d[3] = {xb[0] - xa[0], xb[1] - xa[1], xb[2] - xa[2]};
  const double length = std::sqrt((d[0] * d[0] + d[1] * d[1]) + (d[2] * d[2] + 0.0));
  const double inv_length = 1.0 / length;
  double dir[3];
  if (length > kCollapsedSpringRatio * rest) {
    for (int i = 0; i < 3; ++i) dir[i] = d[i] * inv_length;
  } else {  // collapsed: the rest direction stands in (as spring_frame)
    const Vec3 r = in.rest_position[nb] - in.rest_position[na];
    const double rn = r.norm();
    for (int i = 0; i < 3; ++i) dir[i] = rn > 0.0 ? r[i] / rn : 0.0;
  }
  const Vec3& va = in.v[na];
  const Vec3& vb = in.v[nb];
  const double dv[3] = {va[0] - vb[0], va[1] - vb[1], va[2] - vb[2]};
  const double dvd = (dv[0] * dir[0] + dv[1] * dir[1]) + (dv[2] * dir[2] + 0.0);
  const SpringScalars s = spring_scalars(k, c, rest, length, inv_length, dvd, h);
  for (int i = 0; i < 3; ++i) {
    const double q = s.kad * dir[i] + s.k_iso * dv[i];
    const double contribution = h * (s.f_mag * dir[i] - h * q);
    rhs[a].v[i] += contribution;
    rhs[b].v[i] -= contribution;
    const double block_diag = s.along * (dir[i] * dir[i]) + s.iso;
    diag[a].v[i] += block_diag;
    diag[b].v[i] += block_diag;
  }
  const double root_along_scaled = s.root_along * in.record_scale;
  for (int i = 0; i < 3; ++i) record->e[i] = static_cast<float>(root_along_scaled * dir[i]);
  record->iso = static_cast<float>(s.iso * in.record_scale2);
  record->a4 = 4 * a;
  record->b4 = 4 * b;
}

void setup_scalar(const SetupInput& in, const EdgeId* live, std::size_t count, Pad3* rhs, Pad3* diag,
                  ImplicitSpring* records) {
  for (std::size_t i = 0; i < count; ++i) setup_spring_scalar(in, live[i], rhs, diag, records + i);
}

#if defined(__x86_64__)
// Four springs at a time: lengths, square roots, divisions and the spring
// scalars in one vector each (the scalar-per-spring version spent ~35 cycles
// per spring, mostly waiting on its sqrt → div → sqrt chain).
TISSUE_AVX2 void setup_avx2(const SetupInput& in, const EdgeId* live, std::size_t count, Pad3* rhs_pad, Pad3* diag_pad,
                            ImplicitSpring* records) {
  const __m256i xyz_i = _mm256_setr_epi64x(-1, -1, -1, 0);
  const __m256d xyz = _mm256_castsi256_pd(xyz_i);
  const double h = in.h;
  const __m256d hv = _mm256_set1_pd(h), hh = _mm256_set1_pd(h * h), one = _mm256_set1_pd(1.0);
  double* const rhs = rhs_pad[0].v;
  double* const diag = diag_pad[0].v;
  std::size_t i = 0;
  for (; i + 4 <= count; i += 4) {
    EdgeId e[4];
    NodeId na[4], nb[4];
    __m256d d[4], dir[4], dv[4];
    for (int j = 0; j < 4; ++j) {
      e[j] = live[i + j];
      na[j] = in.edge_a[e[j]];
      nb[j] = in.edge_b[e[j]];
      // Masked loads: a Vec3 is 24 B, the fourth lane would read the next node.
      d[j] =
          _mm256_sub_pd(_mm256_maskload_pd(in.x[nb[j]].data(), xyz_i), _mm256_maskload_pd(in.x[na[j]].data(), xyz_i));
    }
    const __m256d rest =
        _mm256_setr_pd(in.rest_length[e[0]], in.rest_length[e[1]], in.rest_length[e[2]], in.rest_length[e[3]]);
    const __m256d length = _mm256_sqrt_pd(lane_sums_avx2(_mm256_mul_pd(d[0], d[0]), _mm256_mul_pd(d[1], d[1]),
                                                         _mm256_mul_pd(d[2], d[2]), _mm256_mul_pd(d[3], d[3])));
    if (_mm256_movemask_pd(
            _mm256_cmp_pd(length, _mm256_mul_pd(_mm256_set1_pd(kCollapsedSpringRatio), rest), _CMP_GT_OQ)) != 0xF) {
      for (int j = 0; j < 4; ++j) setup_spring_scalar(in, e[j], rhs_pad, diag_pad, records + i + j);  // collapsed: rare
      continue;
    }
    const __m256d inv_length = _mm256_div_pd(one, length);
    alignas(32) double inv[4];
    _mm256_store_pd(inv, inv_length);
    for (int j = 0; j < 4; ++j) {
      dir[j] = _mm256_mul_pd(d[j], _mm256_broadcast_sd(inv + j));
      dv[j] =
          _mm256_sub_pd(_mm256_maskload_pd(in.v[na[j]].data(), xyz_i), _mm256_maskload_pd(in.v[nb[j]].data(), xyz_i));
    }
    const __m256d dvd = lane_sums_avx2(_mm256_mul_pd(dv[0], dir[0]), _mm256_mul_pd(dv[1], dir[1]),
                                       _mm256_mul_pd(dv[2], dir[2]), _mm256_mul_pd(dv[3], dir[3]));
    const __m256d k = _mm256_setr_pd(in.stiffness[e[0]], in.stiffness[e[1]], in.stiffness[e[2]], in.stiffness[e[3]]);
    const __m256d c = _mm256_setr_pd(in.damping[e[0]], in.damping[e[1]], in.damping[e[2]], in.damping[e[3]]);
    // spring_scalars(), lane-wise.
    const __m256d transverse =
        _mm256_and_pd(_mm256_cmp_pd(length, rest, _CMP_GT_OQ), _mm256_sub_pd(one, _mm256_mul_pd(rest, inv_length)));
    const __m256d k_along = _mm256_mul_pd(k, _mm256_sub_pd(one, transverse));
    const __m256d k_iso = _mm256_mul_pd(k, transverse);
    const __m256d along = _mm256_add_pd(_mm256_mul_pd(hv, c), _mm256_mul_pd(hh, k_along));
    alignas(32) double f_mag[4], kad[4], k_iso_s[4], along_s[4], iso[4], root_along_scaled[4], iso_scaled[4];
    _mm256_store_pd(f_mag, _mm256_sub_pd(_mm256_mul_pd(k, _mm256_sub_pd(length, rest)), _mm256_mul_pd(c, dvd)));
    _mm256_store_pd(kad, _mm256_mul_pd(k_along, dvd));
    _mm256_store_pd(k_iso_s, k_iso);
    _mm256_store_pd(along_s, along);
    const __m256d iso_v = _mm256_mul_pd(hh, k_iso);
    _mm256_store_pd(iso, iso_v);
    _mm256_store_pd(root_along_scaled, _mm256_mul_pd(_mm256_sqrt_pd(along), _mm256_set1_pd(in.record_scale)));
    _mm256_store_pd(iso_scaled, _mm256_mul_pd(iso_v, _mm256_set1_pd(in.record_scale2)));
    for (int j = 0; j < 4; ++j) {
      const __m256d q = _mm256_add_pd(_mm256_mul_pd(_mm256_broadcast_sd(kad + j), dir[j]),
                                      _mm256_mul_pd(_mm256_broadcast_sd(k_iso_s + j), dv[j]));
      const __m256d contribution =
          _mm256_mul_pd(hv, _mm256_sub_pd(_mm256_mul_pd(_mm256_broadcast_sd(f_mag + j), dir[j]), _mm256_mul_pd(hv, q)));
      const __m256d block_diag =
          _mm256_and_pd(_mm256_add_pd(_mm256_mul_pd(_mm256_broadcast_sd(along_s + j), _mm256_mul_pd(dir[j], dir[j])),
                                      _mm256_broadcast_sd(iso + j)),
                        xyz);
      const std::uint32_t a4 = 4 * in.unknown_of_node[na[j]], b4 = 4 * in.unknown_of_node[nb[j]];
      _mm256_store_pd(rhs + a4, _mm256_add_pd(_mm256_load_pd(rhs + a4), contribution));
      _mm256_store_pd(rhs + b4, _mm256_sub_pd(_mm256_load_pd(rhs + b4), contribution));
      _mm256_store_pd(diag + a4, _mm256_add_pd(_mm256_load_pd(diag + a4), block_diag));
      _mm256_store_pd(diag + b4, _mm256_add_pd(_mm256_load_pd(diag + b4), block_diag));
      // e = √along d̂ in lanes 0-2 and iso in lane 3, scaled and rounded to
      // floats: the record's first 16 B.
      ImplicitSpring& record = records[i + j];
      _mm_storeu_ps(record.e,
                    _mm256_cvtpd_ps(_mm256_blend_pd(_mm256_mul_pd(_mm256_broadcast_sd(root_along_scaled + j), dir[j]),
                                                    _mm256_broadcast_sd(iso_scaled + j), 0b1000)));
      record.a4 = a4;
      record.b4 = b4;
    }
  }
  for (; i < count; ++i) setup_spring_scalar(in, live[i], rhs_pad, diag_pad, records + i);
}
#endif

void setup_springs(Simd simd, const SetupInput& in, const EdgeId* live, std::size_t count, Pad3* rhs, Pad3* diag,
                   ImplicitSpring* records) {
#if defined(__x86_64__)
  if (simd == Simd::kAvx2) return setup_avx2(in, live, count, rhs, diag, records);
#endif
  setup_scalar(in, live, count, rhs, diag, records);
}

void prepare(Simd simd, bool update_p, double beta, const double* mass, const Pad3* z, Pad3* p, Pad3* ap,
             std::size_t n) {
#if defined(__x86_64__)
  if (simd == Simd::kAvx2) return prepare_avx2(update_p, beta, mass, z, p, ap, n);
#endif
  prepare_scalar(update_p, beta, mass, z, p, ap, n);
}

double dot(Simd simd, const Pad3* a, const Pad3* b, std::size_t n) {
#if defined(__x86_64__)
  if (simd == Simd::kAvx2) return dot_avx2(a, b, n);
#endif
  return dot_scalar(a, b, n);
}

void update(Simd simd, double step, double step_ap, const Pad3* p, const Pad3* ap, const Pad3* diag_inv, Pad3* dv,
            Pad3* r, Pad3* z, std::size_t n, double* rz, double* rr) {
#if defined(__x86_64__)
  if (simd == Simd::kAvx2) return update_avx2(step, step_ap, p, ap, diag_inv, dv, r, z, n, rz, rr);
#endif
  update_scalar(step, step_ap, p, ap, diag_inv, dv, r, z, n, rz, rr);
}

Vec3 to_vec3(const Pad3& p) { return Vec3(p.v[0], p.v[1], p.v[2]); }
Pad3 to_pad3(const Vec3& v) { return Pad3{{v.x(), v.y(), v.z(), 0.0}}; }

}  // namespace

void implicit_spring_matvec(Simd simd, const ImplicitSpring* springs, std::size_t count, const Pad3* p, Pad3* ap) {
#if defined(__x86_64__)
  if (simd == Simd::kAvx2) return matvec_avx2(springs, count, p, ap);
#endif
  matvec_scalar(springs, count, p, ap);
}

ImplicitIntegrator::Preconditioner implicit_preconditioner(scene::CgPreconditioner choice) {
  switch (choice) {
    case scene::CgPreconditioner::kJacobi:
      return ImplicitIntegrator::Preconditioner::kJacobi;
    case scene::CgPreconditioner::kTwoLevel:
      return ImplicitIntegrator::Preconditioner::kTwoLevel;
    case scene::CgPreconditioner::kAuto:
      break;
  }
  return ImplicitIntegrator::Preconditioner::kAuto;
}

ImplicitIntegrator::ImplicitIntegrator(const scene::IntegratorSpec& spec, const scene::MaterialSpec& material,
                                       Matvec matvec, Simd simd, Preconditioner preconditioner)
    : spec_(spec),
      alpha_per_s_(material.rayleigh_alpha_per_s),
      matvec_(matvec),
      preconditioner_(preconditioner),
      simd_(simd) {}

double ImplicitIntegrator::apply_assembled() {
  for (std::uint32_t i = 0; i < unknowns_; ++i) {
    Vec3 y = diag_block_[i] * to_vec3(p_[i]);
    for (std::uint32_t k = row_start_[i]; k < row_start_[i + 1]; ++k)
      y.noalias() += off_block_[k] * to_vec3(p_[col_[k]]);
    ap_[i] = to_pad3(y);
  }
  ap_[unknowns_] = Pad3{};
  return dot(simd_, p_.data(), ap_.data(), unknowns_);
}

double ImplicitIntegrator::apply(bool update_p, double beta) {
  if (matvec_ == Matvec::kAssembledBlockCsr) {
    if (update_p)
      for (std::uint32_t i = 0; i < unknowns_; ++i)
        for (int k = 0; k < 4; ++k) p_[i].v[k] = z_[i].v[k] + beta * p_[i].v[k];
    return record_scale2_ * apply_assembled();
  }
  prepare(simd_, update_p, beta, mass_.data(), z_.data(), p_.data(), ap_.data(), unknowns_);
  ap_[unknowns_] = Pad3{};  // the sink collects kinematic ends' shares; never read
  implicit_spring_matvec(simd_, springs_.data(), springs_.size(), p_.data(), ap_.data());
  return record_scale2_ * dot(simd_, p_.data(), ap_.data(), unknowns_);
}

void ImplicitIntegrator::assemble() {
  const std::uint32_t sink = unknowns_;
  row_start_.assign(unknowns_ + 2, 0);
  for (const ImplicitSpring& s : springs_) {
    const std::uint32_t a = s.a4 / 4, b = s.b4 / 4;
    if (a != sink && b != sink) {
      ++row_start_[a + 2];
      ++row_start_[b + 2];
    }
  }
  for (std::uint32_t i = 0; i < unknowns_; ++i) row_start_[i + 2] += row_start_[i + 1];
  col_.resize(row_start_[unknowns_ + 1]);
  off_block_.resize(row_start_[unknowns_ + 1]);
  diag_block_.resize(unknowns_ + 1);
  for (std::uint32_t i = 0; i < unknowns_; ++i) diag_block_[i] = mass_[i] * Eigen::Matrix3d::Identity();
  diag_block_[sink].setZero();  // collects kinematic ends' shares; never read
  // row_start_[i + 1] is the fill cursor of row i; it ends at row i + 1's start.
  for (const ImplicitSpring& s : springs_) {
    const std::uint32_t a = s.a4 / 4, b = s.b4 / 4;
    const Vec3 e(s.e[0], s.e[1], s.e[2]);
    const Eigen::Matrix3d block = e * e.transpose() + double(s.iso) * Eigen::Matrix3d::Identity();
    diag_block_[a] += block;
    diag_block_[b] += block;
    if (a != sink && b != sink) {
      col_[row_start_[a + 1]] = b;
      off_block_[row_start_[a + 1]++] = -block;
      col_[row_start_[b + 1]] = a;
      off_block_[row_start_[b + 1]++] = -block;
    }
  }
}

void ImplicitIntegrator::system_product(const std::vector<Vec3>& p_by_node, std::vector<Vec3>& y_by_node) {
  y_by_node.assign(p_by_node.size(), Vec3::Zero());
  if (p_.empty()) return;  // no step yet: no system
  for (std::uint32_t i = 0; i < unknowns_; ++i) p_[i] = to_pad3(p_by_node[node_of_unknown_[i]]);
  p_[unknowns_] = Pad3{};
  apply(false, 0.0);
  for (std::uint32_t i = 0; i < unknowns_; ++i) y_by_node[node_of_unknown_[i]] = record_scale2_ * to_vec3(ap_[i]);
}

void ImplicitIntegrator::build_layout(const Body& body) {
  const std::size_t nodes = body.x_m.size(), edges = body.stiffness_N_per_m.size();
  // Unknowns: the free nodes, numbered in node order; the rest share the sink.
  constexpr std::uint32_t kNone = std::numeric_limits<std::uint32_t>::max();
  unknown_of_node_.resize(nodes);
  node_of_unknown_.clear();
  for (NodeId n = 0; n < nodes; ++n) {
    unknown_of_node_[n] = body.inv_mass_per_kg[n] != 0.0 ? static_cast<std::uint32_t>(node_of_unknown_.size()) : kNone;
    if (unknown_of_node_[n] != kNone) node_of_unknown_.push_back(n);
  }
  unknowns_ = static_cast<std::uint32_t>(node_of_unknown_.size());
  const std::uint32_t sink = unknowns_;
  for (auto& u : unknown_of_node_)
    if (u == kNone) u = sink;
  // The warm start is kept by node id, and the mesh reuses a merged node's id
  // for a later split's node: without this, that node started CG from the Δv
  // of the dead one, somewhere else on the body. A node starts from zero
  // unless it is free and stands where it stood at the last layout (the
  // lattice holds one node per point); a kinematic or dead one holds zero.
  dv_by_node_.resize(nodes, Vec3::Zero());
  warm_start_rest_m_.resize(nodes, Vec3::Zero());
  for (NodeId n = 0; n < nodes; ++n) {
    if (unknown_of_node_[n] == sink || body.rest_m[n] != warm_start_rest_m_[n]) dv_by_node_[n].setZero();
    warm_start_rest_m_[n] = body.rest_m[n];
  }

  // The springs the system needs, in edge order. Visiting them sorted by
  // node, or dealt round-robin from 8 node-sorted chunks so consecutive
  // springs never share a node (no store-to-load chain through ap[]),
  // measured the same within noise (R2 0.49-0.55 ms, R3 4.3-4.7 ms per cg20
  // step all three): the AVX2 matvec is bound by its ~25 instructions per
  // spring, not by memory order, so the simplest order stays. Numbering the
  // unknowns along a Morton curve of their lattice position (springs still
  // in edge order) did not help either (4x10^5 springs 61 vs 50-58 ms).
  // Morton-numbered unknowns with the springs sorted by their lower unknown
  // (2026-11-25, float records; BM_Step/implicit_cg20, two rounds
  // alternating): 5x10^4 springs 82-83 vs 73-74, 4x10^5 112-115 vs 91-97,
  // 1.6x10^6 179-216 vs 139-141 ns per spring per step: sorted, consecutive
  // springs share an end and chain their read-modify-writes of ap. Two more
  // orders, same benchmark, two rounds alternating on an idle machine
  // (2026-11-25): Morton unknowns with the sorted springs dealt round-robin
  // from 8 chunks (no chain) 5x10^4 85-100 vs 75-77, 4x10^5 125-137 vs
  // 104-109, 1.6x10^6 284-286 vs 143-146 (4 chunks: 78, 113-119, 230-253);
  // unknowns numbered as the edge stream first touches them (springs in
  // edge order) 75-76 vs 74-88, 94-98 vs 94-102, 193-201 vs 138-147. Both
  // lose the streams this order keeps: the setup pass reads the body's edge
  // arrays, and the node passes its node arrays, in the order given here.
  live_edges_.clear();
  stiffness_max_ = damping_max_ = 0.0;
  for (EdgeId e = 0; e < edges; ++e) {
    if (body.stiffness_N_per_m[e] == 0.0) continue;  // dead edge slot
    if (unknown_of_node_[body.edge_a[e]] == sink && unknown_of_node_[body.edge_b[e]] == sink) continue;  // no unknown
    live_edges_.push_back(e);
    stiffness_max_ = std::max(stiffness_max_, body.stiffness_N_per_m[e]);
    damping_max_ = std::max(damping_max_, body.damping_N_s_per_m[e]);
  }
  springs_.resize(live_edges_.size());
  two_level_ = preconditioner_ == Preconditioner::kTwoLevel ||
               (preconditioner_ == Preconditioner::kAuto && unknowns_ >= kAutoTwoLevelUnknowns);
  if (two_level_) build_aggregates(body);
  layout_version_ = body.parameters_version();
}

void ImplicitIntegrator::precondition(const std::vector<Vec3>& r_by_node, std::vector<Vec3>& z_by_node,
                                      bool coarse_only) {
  z_by_node.assign(r_by_node.size(), Vec3::Zero());
  if (p_.empty()) return;  // no step yet: no preconditioner
  for (std::uint32_t i = 0; i < unknowns_; ++i) {
    r_[i] = to_pad3(r_by_node[node_of_unknown_[i]]);
    for (int k = 0; k < 4; ++k) z_[i].v[k] = coarse_only ? 0.0 : diag_inv_[i].v[k] * r_[i].v[k];
  }
  if (coarse_ok_) coarse_correct();
  for (std::uint32_t i = 0; i < unknowns_; ++i) z_by_node[node_of_unknown_[i]] = to_vec3(z_[i]);
}

std::uint32_t ImplicitIntegrator::aggregate_of_node(NodeId n) const {
  if (!coarse_ok_ || n >= unknown_of_node_.size()) return kNoAggregate;
  return aggregate_of_unknown_[unknown_of_node_[n]];
}

StepOutcome ImplicitIntegrator::step(Body& body, const std::vector<Vec3>& f_ext_N, double dt_s) {
  StepOutcome out;
  h_ = dt_s;
  const double h = h_;
  const std::size_t nodes = body.x_m.size();
  save_.save(body);

  if (body.parameters_version() != layout_version_) build_layout(body);
  const std::uint32_t sink = unknowns_;
  const std::size_t slots = unknowns_ + 1u;
  for (auto* v : {&diag_inv_, &rhs_, &dv_, &r_, &z_, &p_, &ap_}) v->resize(slots);
  mass_.resize(slots);
  dv_by_node_.resize(nodes, Vec3::Zero());  // warm start, by node id across mesh changes

  // The records hold each block B = S B̃ as B̃ in single precision, S = 2^2e
  // chosen from the stiffest and most damped spring so that no entry of B̃
  // exceeds 1 (h c + h² k bounds every block's along and iso): the records
  // neither overflow nor lose their range whatever the units. ap holds
  // (M'/S + Σ B̃) p; the CG takes S in its scalars (pᵀAp, the residual
  // update). Powers of two scale exactly: only the rounding of B̃ to floats
  // (~6e-8 relative) differs from double records.
  int exponent = 0;
  const double bound = h * damping_max_ + h * h * stiffness_max_;
  if (bound > 0.0 && std::isfinite(bound)) std::frexp(std::sqrt(bound), &exponent);  // √bound < 2^exponent
  exponent = std::clamp(exponent, -500, 500);
  record_scale2_ = std::ldexp(1.0, 2 * exponent);
  const double inv_record_scale2 = std::ldexp(1.0, -2 * exponent);
  const double mass_scale = 1.0 + h * alpha_per_s_;
  for (std::uint32_t i = 0; i < unknowns_; ++i) {
    const NodeId n = node_of_unknown_[i];
    const double mass = body.mass_kg[n] * mass_scale;
    mass_[i] = mass * inv_record_scale2;
    rhs_[i] = to_pad3(h * (f_ext_N[n] - alpha_per_s_ * body.mass_kg[n] * body.v_m_per_s[n]));
    diag_inv_[i] = Pad3{{mass, mass, mass, 0.0}};  // the diagonal, inverted below
  }
  rhs_[sink] = diag_inv_[sink] = Pad3{};
  // One pass over the edges: rhs = h (f − h K v) with the spring and damper
  // forces, the compact blocks and the diagonal. The sink slot collects
  // shares nobody reads.
  const SetupInput input{body.stiffness_N_per_m.data(),
                         body.damping_N_s_per_m.data(),
                         body.rest_length_m.data(),
                         body.edge_a.data(),
                         body.edge_b.data(),
                         body.x_m.data(),
                         body.v_m_per_s.data(),
                         body.rest_m.data(),
                         unknown_of_node_.data(),
                         h,
                         std::ldexp(1.0, -exponent),
                         inv_record_scale2};
  setup_springs(simd_, input, live_edges_.data(), live_edges_.size(), rhs_.data(), diag_inv_.data(), springs_.data());
  for (std::uint32_t i = 0; i < unknowns_; ++i) {
    for (int k = 0; k < 3; ++k) diag_inv_[i].v[k] = 1.0 / diag_inv_[i].v[k];
    diag_inv_[i].v[3] = 0.0;
    dv_[i] = to_pad3(dv_by_node_[node_of_unknown_[i]]);
  }
  for (auto* v : {&diag_inv_, &rhs_, &dv_, &r_, &z_, &p_, &ap_}) (*v)[sink] = Pad3{};
  mass_[sink] = 0.0;
  if (matvec_ == Matvec::kAssembledBlockCsr) assemble();
  coarse_ok_ = two_level_ && factor_coarse();

  const double rhs_norm = std::sqrt(dot(simd_, rhs_.data(), rhs_.data(), unknowns_));
  if (!std::isfinite(rhs_norm)) {
    // Overflowing forces would otherwise read as "already converged".
    save_.restore(body);
    out.ok = false;
    out.error =
        "implicit integrator: forces are non-finite or beyond floating-point range; step rejected, "
        "previous state kept";
    return out;
  }

  // Jacobi-preconditioned CG from the previous step's Δv.
  std::copy(dv_.begin(), dv_.begin() + unknowns_, p_.begin());
  apply(false, 0.0);
  double rz = 0.0, rr = 0.0;
  for (std::uint32_t i = 0; i < unknowns_; ++i)
    for (int k = 0; k < 3; ++k) {
      r_[i].v[k] = rhs_[i].v[k] - record_scale2_ * ap_[i].v[k];
      z_[i].v[k] = diag_inv_[i].v[k] * r_[i].v[k];
      rz += r_[i].v[k] * z_[i].v[k];
      rr += r_[i].v[k] * r_[i].v[k];
    }
  // The warm start only where it beats a cold one. CG minimises
  // φ(Δv) = ½ Δvᵀ A Δv − bᵀ Δv, and φ(Δv) − φ(Δv*) is half the squared A-norm
  // error, so φ(warm) ≥ φ(0) = 0 means the last step's Δv is further from
  // this step's solution than zero is (a release, a reversal). With the
  // iterations capped short of the tolerance, starting there fed a wrong
  // guess forward step after step: cg_max_iterations 5 at dt 10 ms took the
  // cantilever from 0.3 J to 1e17 J in 2 s. From zero, a capped CG returns
  // the A-projection of the solution onto its Krylov space, never longer in
  // the A-norm than the solution itself. φ(warm) = −½ Δvᵀ (b + r): one pass.
  double phi_warm = 0.0;
  for (std::uint32_t i = 0; i < unknowns_; ++i)
    for (int k = 0; k < 3; ++k) phi_warm -= 0.5 * dv_[i].v[k] * (rhs_[i].v[k] + r_[i].v[k]);
  if (!(phi_warm < 0.0)) {
    rz = rr = 0.0;
    for (std::uint32_t i = 0; i < unknowns_; ++i) {
      dv_[i] = Pad3{};
      r_[i] = rhs_[i];
      for (int k = 0; k < 3; ++k) {
        z_[i].v[k] = diag_inv_[i].v[k] * r_[i].v[k];
        rz += r_[i].v[k] * z_[i].v[k];
        rr += r_[i].v[k] * r_[i].v[k];
      }
    }
  }
  if (coarse_ok_) rz = coarse_correct();
  std::copy(z_.begin(), z_.begin() + unknowns_, p_.begin());
  double residual = rhs_norm > 0.0 ? std::sqrt(rr) / rhs_norm : 0.0;
  double beta = 0.0;
  int it = 0;
  while (residual > spec_.cg_tolerance && it < spec_.cg_max_iterations) {
    const double pap = apply(it > 0, beta);  // p = z + βp fused into the matvec's node pass
    if (!(pap > 0.0)) break;                 // cannot happen for an SPD system; guards NaN
    const double step = rz / pap;
    double rz_next = 0.0;
    update(simd_, step, step * record_scale2_, p_.data(), ap_.data(), diag_inv_.data(), dv_.data(), r_.data(),
           z_.data(), unknowns_, &rz_next, &rr);
    if (coarse_ok_) rz_next = coarse_correct();
    ++it;
    residual = std::sqrt(rr) / rhs_norm;
    beta = rz_next / rz;
    rz = rz_next;
  }
  out.solver_iterations = it;
  out.solver_residual = residual;
  out.solver_converged = residual <= spec_.cg_tolerance;

  for (std::uint32_t i = 0; i < unknowns_; ++i) {
    const NodeId n = node_of_unknown_[i];
    dv_by_node_[n] = to_vec3(dv_[i]);
    body.v_m_per_s[n] += dv_by_node_[n];
  }
  for (std::size_t n = 0; n < nodes; ++n) body.x_m[n] += h * body.v_m_per_s[n];  // kinematic: own velocity
  if (!state_is_finite(body)) {
    save_.restore(body);
    std::fill(dv_by_node_.begin(), dv_by_node_.end(), Vec3::Zero());
    out.ok = false;
    out.error = "implicit integrator: state became non-finite; step rejected, previous state kept";
  }
  return out;
}

}  // namespace tissue::physics
