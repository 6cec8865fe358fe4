// The explicit sub-steps in single precision (integrator.explicit_precision:
// float): the same symplectic Euler as integrator_explicit.cpp on half the
// bytes and twice the lanes.
//
// Positions are kept as displacements from rest, u = x − X, not as x: a
// float x carries ~3e-8 m of rounding at 0.4 m, which is 2e-6 of a 12 mm
// spring and swamps a strain of 1e-3 by 0.2 %; u is carried to 6e-8 of
// itself. Each spring keeps its rest edge vector e = X_b − X_a and rest
// length L (floats: L = |e| as rounded, so a spring at rest has exactly zero
// force), and its length change comes without cancellation:
//   s = l² − L² = 2 e·Δu + Δu·Δu,   k (l − L) = k s / (l + L),
// with l = √(L² + s) and the current edge d = e + Δu. The force on a is
//   ((k s / (l + L) + c (Δv·d) / l) / l) d.
// Springs whose length fell below 1 % of rest take the scalar path, which
// forms d directly (and, below 1e-6 of rest, the rest direction), as the
// cancellation in L² + s would otherwise grow.
//
// Scalar and AVX2 kernels do the same float operations in the same order
// (no FMA, correctly rounded sqrt and division): bit-identical results. The
// node pass is one plain loop (elementwise: the same bits however the
// compiler vectorises it).
#include <algorithm>
#include <cmath>

#include "physics/integrator_impl.hpp"

namespace tissue::physics {

namespace {

// The scalar path for one spring: the reference the AVX2 kernel matches
// bit for bit, plus the near-collapse fallback.
template <bool kDamped>
void spring_float_scalar(const ExplicitSpringBatchF& s, int j, const float* u, const float* v, float* f) {
  const std::uint32_t a4 = s.a4[j], b4 = s.b4[j];
  const float e[3] = {s.ex[j], s.ey[j], s.ez[j]};
  const float rest = s.rest_m[j], k = s.k_N_per_m[j];
  const float du[3] = {u[b4] - u[a4], u[b4 + 1] - u[a4 + 1], u[b4 + 2] - u[a4 + 2]};
  const float ed = (e[0] * du[0] + e[1] * du[1]) + e[2] * du[2];
  const float dd = (du[0] * du[0] + du[1] * du[1]) + du[2] * du[2];
  const float stretch = (ed + ed) + dd;  // l² − L²
  const float l2 = rest * rest + stretch;
  const float d[3] = {e[0] + du[0], e[1] + du[1], e[2] + du[2]};
  float force[3];
  const float near_collapse = 0.01f * rest;
  if (l2 > near_collapse * near_collapse) {
    const float l = std::sqrt(l2);
    float along = (k * stretch) / (l + rest);
    if constexpr (kDamped) {
      const float dv[3] = {v[b4] - v[a4], v[b4 + 1] - v[a4 + 1], v[b4 + 2] - v[a4 + 2]};
      const float vd = (dv[0] * d[0] + dv[1] * d[1]) + dv[2] * d[2];
      along = along + s.c_N_s_per_m[j] * (vd / l);
    }
    const float coef = along / l;
    for (int i = 0; i < 3; ++i) force[i] = coef * d[i];
  } else {
    // Near collapse: the length from d itself; below 1e-6 of rest, the rest
    // direction stands in (as the double kernels do below 1e-9 of rest: a
    // float length has no digits left beneath 1e-6 of it).
    const float l = std::sqrt((d[0] * d[0] + d[1] * d[1]) + d[2] * d[2]);
    const bool collapsed = !(l > 1e-6f * rest);
    float dir[3];
    for (int i = 0; i < 3; ++i) dir[i] = collapsed ? e[i] / rest : d[i] / l;
    float magnitude = k * (l - rest);
    if constexpr (kDamped) {
      const float dv[3] = {v[b4] - v[a4], v[b4 + 1] - v[a4 + 1], v[b4 + 2] - v[a4 + 2]};
      magnitude = magnitude + s.c_N_s_per_m[j] * ((dv[0] * dir[0] + dv[1] * dir[1]) + dv[2] * dir[2]);
    }
    for (int i = 0; i < 3; ++i) force[i] = magnitude * dir[i];
  }
  for (int i = 0; i < 3; ++i) {
    f[a4 + i] += force[i];
    f[b4 + i] -= force[i];
  }
}

template <bool kDamped>
void forces_float_scalar(const ExplicitSpringBatchF* batches, std::size_t count, const Pad3f* u, const Pad3f* v,
                         Pad3f* f) {
  for (std::size_t i = 0; i < count; ++i)
    for (int j = 0; j < 8; ++j) spring_float_scalar<kDamped>(batches[i], j, u[0].v, kDamped ? v[0].v : nullptr, f[0].v);
}

#if defined(__x86_64__)
// Eight padded 3-vectors (lane 3 zero) to x, y, z rows of eight lanes.
TISSUE_AVX2 inline void transpose_in(const __m128 (&p)[8], __m256& x, __m256& y, __m256& z) {
  const __m256 r0 = _mm256_set_m128(p[4], p[0]), r1 = _mm256_set_m128(p[5], p[1]);
  const __m256 r2 = _mm256_set_m128(p[6], p[2]), r3 = _mm256_set_m128(p[7], p[3]);
  const __m256 t0 = _mm256_unpacklo_ps(r0, r1);  // x0 x1 y0 y1 | x4 x5 y4 y5
  const __m256 t1 = _mm256_unpackhi_ps(r0, r1);  // z0 z1 w0 w1 | z4 z5 w4 w5
  const __m256 t2 = _mm256_unpacklo_ps(r2, r3);  // x2 x3 y2 y3 | x6 x7 y6 y7
  const __m256 t3 = _mm256_unpackhi_ps(r2, r3);
  x = _mm256_shuffle_ps(t0, t2, _MM_SHUFFLE(1, 0, 1, 0));  // x0 x1 x2 x3 | x4 x5 x6 x7
  y = _mm256_shuffle_ps(t0, t2, _MM_SHUFFLE(3, 2, 3, 2));
  z = _mm256_shuffle_ps(t1, t3, _MM_SHUFFLE(1, 0, 1, 0));
}

template <bool kDamped>
TISSUE_AVX2 void forces_float_avx2(const ExplicitSpringBatchF* batches, std::size_t count, const Pad3f* u_pad,
                                   const Pad3f* v_pad, Pad3f* f_pad) {
  const float* u = u_pad[0].v;
  const float* v = kDamped ? v_pad[0].v : nullptr;
  float* f = f_pad[0].v;
  const __m256 near_collapse = _mm256_set1_ps(0.01f);
  for (std::size_t i = 0; i < count; ++i) {
    const ExplicitSpringBatchF& s = batches[i];
    __m128 dup[8], dvp[8];
    for (int j = 0; j < 8; ++j) {
      const std::uint32_t a4 = s.a4[j], b4 = s.b4[j];
      dup[j] = _mm_sub_ps(_mm_load_ps(u + b4), _mm_load_ps(u + a4));
      if constexpr (kDamped) dvp[j] = _mm_sub_ps(_mm_load_ps(v + b4), _mm_load_ps(v + a4));
    }
    __m256 dux, duy, duz;
    transpose_in(dup, dux, duy, duz);
    const __m256 ex = _mm256_loadu_ps(s.ex), ey = _mm256_loadu_ps(s.ey), ez = _mm256_loadu_ps(s.ez);
    const __m256 rest = _mm256_loadu_ps(s.rest_m);
    const __m256 ed =
        _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(ex, dux), _mm256_mul_ps(ey, duy)), _mm256_mul_ps(ez, duz));
    const __m256 dd =
        _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(dux, dux), _mm256_mul_ps(duy, duy)), _mm256_mul_ps(duz, duz));
    const __m256 stretch = _mm256_add_ps(_mm256_add_ps(ed, ed), dd);
    const __m256 l2 = _mm256_add_ps(_mm256_mul_ps(rest, rest), stretch);
    const __m256 limit = _mm256_mul_ps(near_collapse, rest);
    if (_mm256_movemask_ps(_mm256_cmp_ps(l2, _mm256_mul_ps(limit, limit), _CMP_GT_OQ)) != 0xFF) {
      forces_float_scalar<kDamped>(&s, 1, u_pad, v_pad, f_pad);  // near collapse (or non-finite): rare
      continue;
    }
    const __m256 l = _mm256_sqrt_ps(l2);
    const __m256 dx = _mm256_add_ps(ex, dux), dy = _mm256_add_ps(ey, duy), dz = _mm256_add_ps(ez, duz);
    __m256 along = _mm256_div_ps(_mm256_mul_ps(_mm256_loadu_ps(s.k_N_per_m), stretch), _mm256_add_ps(l, rest));
    if constexpr (kDamped) {
      __m256 dvx, dvy, dvz;
      transpose_in(dvp, dvx, dvy, dvz);
      const __m256 vd =
          _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(dvx, dx), _mm256_mul_ps(dvy, dy)), _mm256_mul_ps(dvz, dz));
      along = _mm256_add_ps(along, _mm256_mul_ps(_mm256_loadu_ps(s.c_N_s_per_m), _mm256_div_ps(vd, l)));
    }
    const __m256 coef = _mm256_div_ps(along, l);
    const __m256 fx = _mm256_mul_ps(coef, dx), fy = _mm256_mul_ps(coef, dy), fz = _mm256_mul_ps(coef, dz);
    // Back to one padded vector per spring.
    const __m256 zero = _mm256_setzero_ps();
    const __m256 t0 = _mm256_unpacklo_ps(fx, fy);    // x0 y0 x1 y1 | x4 y4 x5 y5
    const __m256 t1 = _mm256_unpackhi_ps(fx, fy);    // x2 y2 x3 y3 | x6 y6 x7 y7
    const __m256 t2 = _mm256_unpacklo_ps(fz, zero);  // z0 0 z1 0 | z4 0 z5 0
    const __m256 t3 = _mm256_unpackhi_ps(fz, zero);
    const __m256 r[4] = {
        _mm256_shuffle_ps(t0, t2, _MM_SHUFFLE(1, 0, 1, 0)), _mm256_shuffle_ps(t0, t2, _MM_SHUFFLE(3, 2, 3, 2)),
        _mm256_shuffle_ps(t1, t3, _MM_SHUFFLE(1, 0, 1, 0)), _mm256_shuffle_ps(t1, t3, _MM_SHUFFLE(3, 2, 3, 2))};
    for (int j = 0; j < 8; ++j) {
      const __m128 force = j < 4 ? _mm256_castps256_ps128(r[j]) : _mm256_extractf128_ps(r[j - 4], 1);
      const std::uint32_t a4 = s.a4[j], b4 = s.b4[j];
      _mm_store_ps(f + a4, _mm_add_ps(_mm_load_ps(f + a4), force));
      _mm_store_ps(f + b4, _mm_sub_ps(_mm_load_ps(f + b4), force));
    }
  }
}
#endif

// v += h w f (then / (1 + h α)), u += h v, f = f_ext: one pass. SSE (part of
// every x86-64 CPU, so no dispatch) or the same elementwise operations in
// plain floats: the same bits either way.
void update_float(float h, float divisor, const float* inv_mass, const Pad3f* f_ext, Pad3f* u, Pad3f* v, Pad3f* f,
                  std::size_t n) {
#if defined(__x86_64__)
  const __m128 hv = _mm_set1_ps(h), divisor_v = _mm_set1_ps(divisor);
  for (std::size_t i = 0; i < n; ++i) {
    __m128 vi = _mm_load_ps(v[i].v);
    const float w = inv_mass[i];
    if (w != 0.0f) {
      vi = _mm_add_ps(vi, _mm_mul_ps(_mm_set1_ps(h * w), _mm_load_ps(f[i].v)));
      if (divisor != 1.0f) vi = _mm_div_ps(vi, divisor_v);
      _mm_store_ps(v[i].v, vi);
    }
    _mm_store_ps(u[i].v, _mm_add_ps(_mm_load_ps(u[i].v), _mm_mul_ps(hv, vi)));
    _mm_store_ps(f[i].v, _mm_load_ps(f_ext[i].v));
  }
#else
  for (std::size_t i = 0; i < n; ++i) {
    const float w = inv_mass[i];
    if (w != 0.0f) {
      const float hw = h * w;
      for (int k = 0; k < 3; ++k) v[i].v[k] = v[i].v[k] + hw * f[i].v[k];
      if (divisor != 1.0f)
        for (int k = 0; k < 3; ++k) v[i].v[k] = v[i].v[k] / divisor;
    }
    for (int k = 0; k < 3; ++k) u[i].v[k] = u[i].v[k] + h * v[i].v[k];
    f[i] = f_ext[i];
  }
#endif
}

Pad3f padded_float(const Vec3& v) {
  return Pad3f{{static_cast<float>(v.x()), static_cast<float>(v.y()), static_cast<float>(v.z()), 0.0f}};
}

}  // namespace

void explicit_spring_forces_float(Simd simd, const ExplicitSpringBatchF* batches, std::size_t count, const Pad3f* u,
                                  const Pad3f* v, Pad3f* f) {
#if defined(__x86_64__)
  if (simd == Simd::kAvx2)
    return v ? forces_float_avx2<true>(batches, count, u, v, f) : forces_float_avx2<false>(batches, count, u, v, f);
#endif
  if (v)
    forces_float_scalar<true>(batches, count, u, v, f);
  else
    forces_float_scalar<false>(batches, count, u, v, f);
}

void ExplicitFloatState::build(const Body& body) {
  const std::size_t nodes = body.x_m.size();
  const auto pad0 = static_cast<std::uint32_t>(4 * nodes), pad1 = pad0 + 4;
  batches_.clear();
  std::size_t filled = 0;
  for (const EdgeId e : moving_springs(body)) {
    const NodeId a = body.edge_a[e], b = body.edge_b[e];
    if (filled % 8 == 0) {
      // Fillers join the two pad nodes (u = 0) along e = (1, 0, 0) at rest
      // length 1 with no stiffness: an exactly zero force.
      ExplicitSpringBatchF filler{};
      std::fill(std::begin(filler.a4), std::end(filler.a4), pad0);
      std::fill(std::begin(filler.b4), std::end(filler.b4), pad1);
      std::fill(std::begin(filler.ex), std::end(filler.ex), 1.0f);
      std::fill(std::begin(filler.rest_m), std::end(filler.rest_m), 1.0f);
      batches_.push_back(filler);
    }
    ExplicitSpringBatchF& batch = batches_.back();
    const std::size_t j = filled++ % 8;
    const Vec3 edge = body.rest_m[b] - body.rest_m[a];
    batch.a4[j] = static_cast<std::uint32_t>(4 * a);
    batch.b4[j] = static_cast<std::uint32_t>(4 * b);
    batch.ex[j] = static_cast<float>(edge.x());
    batch.ey[j] = static_cast<float>(edge.y());
    batch.ez[j] = static_cast<float>(edge.z());
    // L from the rounded edge: exactly zero force at rest. (|e| differs from
    // the body's rest length by float rounding only, ~6e-8 relative.)
    batch.rest_m[j] = std::sqrt((batch.ex[j] * batch.ex[j] + batch.ey[j] * batch.ey[j]) + batch.ez[j] * batch.ez[j]);
    batch.k_N_per_m[j] = static_cast<float>(body.stiffness_N_per_m[e]);
    batch.c_N_s_per_m[j] = static_cast<float>(body.damping_N_s_per_m[e]);
  }
  damped_ = std::any_of(batches_.begin(), batches_.end(), [](const ExplicitSpringBatchF& b) {
    return std::any_of(std::begin(b.c_N_s_per_m), std::end(b.c_N_s_per_m), [](float c) { return c != 0.0f; });
  });
  for (auto* p : {&u_, &v_, &f_, &f_ext_, &u0_, &v0_}) p->assign(nodes + 2, Pad3f{});
  inv_mass_.assign(nodes + 2, 0.0f);
  for (std::size_t n = 0; n < nodes; ++n) inv_mass_[n] = static_cast<float>(body.inv_mass_per_kg[n]);
}

void ExplicitFloatState::load(const Body& body, const std::vector<Vec3>& f_ext_N) {
  for (std::size_t n = 0; n < body.x_m.size(); ++n) {
    u0_[n] = u_[n] = padded_float(body.x_m[n] - body.rest_m[n]);
    v0_[n] = v_[n] = padded_float(body.v_m_per_s[n]);
    f_ext_[n] = f_[n] = padded_float(f_ext_N[n]);
  }
}

FloatMassDamping::FloatMassDamping(double h_s, double alpha_per_s) {
  const double h_alpha = h_s * alpha_per_s;
  if (!(h_alpha > 0.0)) return;  // no mass damping: divisor 1, nothing left over
  log_factor = std::log1p(h_alpha);
  // Capped far beyond any sub-step count (max_substeps): the whole step's
  // share is then left to store().
  every = h_alpha >= kMinDecay ? 1 : static_cast<int>(std::min(std::ceil(kMinDecay / h_alpha), 1e9));
  divisor = static_cast<float>(std::exp(every * log_factor));
}

void ExplicitFloatState::substeps(Simd simd, double h_s, double alpha_per_s, int count) {
  h_s_ = h_s;
  count_ = count;
  const float h = static_cast<float>(h_s);
  const FloatMassDamping damping(h_s, alpha_per_s);
  leftover_divisor_ = damping.leftover_divisor(count);
  const std::size_t nodes = u_.size();
  int since_division = 0;
  for (int s = 0; s < count; ++s) {
    explicit_spring_forces_float(simd, batches_.data(), batches_.size(), u_.data(), damped_ ? v_.data() : nullptr,
                                 f_.data());
    const bool divide = ++since_division == damping.every;
    if (divide) since_division = 0;
    update_float(h, divide ? damping.divisor : 1.0f, inv_mass_.data(), f_ext_.data(), u_.data(), v_.data(), f_.data(),
                 nodes);
  }
}

bool ExplicitFloatState::finite(const Body& body) const {
  constexpr float kLimit = 1e30f;  // float overflows at 3.4e38; squared lengths well before
  bool ok = true;
  body.mesh().for_each_node([&](NodeId n, const mesh::Node&) {
    for (int k = 0; k < 3; ++k) ok = ok && std::abs(u_[n].v[k]) < kLimit && std::abs(v_[n].v[k]) < kLimit;
  });
  return ok;  // NaN fails every comparison
}

double ExplicitFloatState::end_displacement_ratio() const {
  const float* u = u_[0].v;
  float worst = 0.0f;  // (|Δu| / L)²
  for (const ExplicitSpringBatchF& s : batches_)
    for (int j = 0; j < 8; ++j) {
      if (!(s.k_N_per_m[j] > 0.0f)) continue;  // filler
      const std::uint32_t a4 = s.a4[j], b4 = s.b4[j];
      const float du[3] = {u[b4] - u[a4], u[b4 + 1] - u[a4 + 1], u[b4 + 2] - u[a4 + 2]};
      worst = std::max(worst, (du[0] * du[0] + du[1] * du[1] + du[2] * du[2]) / (s.rest_m[j] * s.rest_m[j]));
    }
  return std::sqrt(static_cast<double>(worst));
}

void ExplicitFloatState::store(Body& body) const {
  for (std::size_t n = 0; n < body.x_m.size(); ++n) {
    const float u[3] = {u_[n].v[0], u_[n].v[1], u_[n].v[2]}, v[3] = {v_[n].v[0], v_[n].v[1], v_[n].v[2]};
    const float u0[3] = {u0_[n].v[0], u0_[n].v[1], u0_[n].v[2]}, v0[3] = {v0_[n].v[0], v0_[n].v[1], v0_[n].v[2]};
    store_float_stepped_node(body, static_cast<NodeId>(n), inv_mass_[n] == 0.0f, u, v, u0, v0, h_s_, count_,
                             leftover_divisor_);
  }
}

}  // namespace tissue::physics
