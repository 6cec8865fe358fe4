// The two-level preconditioner of the implicit integrator (scene key
// integrator.cg_preconditioner: two_level, or auto on meshes from
// ImplicitIntegrator::kAutoTwoLevelUnknowns free nodes):
// Jacobi plus an additive coarse correction, M⁻¹ = D⁻¹ + P (Pᵀ A P)⁻¹ Pᵀ,
// P the translations of aggregates of ~27 free nodes (cells of a grid over
// the rest box), the Galerkin Pᵀ A P summed per aggregate pair from the
// springs that cross aggregates and band-Cholesky factored each step.
//
// Why: Jacobi leaves the smooth low modes (the bending) to many CG
// iterations; the coarse correction removes them, the residual left is in
// high modes, and a few iterations suffice. Measured with physics_bench
// BM_ImplicitPreconditioner (load 2-4.5), tip error against the run solved to 1e-10: dt = 10 ms cg20 R2 203 % (Jacobi)
// -> 0.00014 % (0.56 ms), R3 diverged (tip -0.79 m) -> 0.0007 % (6.1 ms per
// 10 ms step); dt = 1 ms two-level cg5 R2 0.00019 % in 0.25 ms vs Jacobi
// cg20 0.0016 % in 0.49 ms, R3 0.0057 % in 2.9 ms vs 0.020 % in 4.2 ms. To a
// 1e-6 residual: R2 38.8 -> 33.1 iterations, R3 77.5 -> 36.6 (13.3 -> 9.8
// ms). Cost (from cg5 vs cg20): per iteration +18 % at R2, +30 % at R3
// (restriction, band solve, prolongation); per step +0.04 ms at R2, +1 ms
// at R3 (assembling and factoring the coarse matrix).
#include <algorithm>
#include <cmath>

#include "physics/integrator_impl.hpp"

namespace tissue::physics {

namespace {

// y[agg[i]] += r[i] (Pᵀ r), then z[i] += y[agg[i]] (P y) with rᵀz.
void restrict_scalar(const Pad3* r, const std::uint32_t* aggregate, Pad3* y, std::size_t n) {
  for (std::size_t i = 0; i < n; ++i)
    for (int k = 0; k < 4; ++k) y[aggregate[i]].v[k] += r[i].v[k];
}

double prolong_scalar(const Pad3* r, const Pad3* y, const std::uint32_t* aggregate, Pad3* z, std::size_t n) {
  double acc[4] = {0.0, 0.0, 0.0, 0.0};
  for (std::size_t i = 0; i < n; ++i)
    for (int k = 0; k < 4; ++k) {
      z[i].v[k] += y[aggregate[i]].v[k];
      acc[k] += r[i].v[k] * z[i].v[k];
    }
  return ((acc[0] + acc[1]) + acc[2]) + acc[3];
}

#if defined(__x86_64__)
TISSUE_AVX2 void restrict_avx2(const Pad3* r, const std::uint32_t* aggregate, Pad3* y, std::size_t n) {
  for (std::size_t i = 0; i < n; ++i) {
    double* yi = y[aggregate[i]].v;
    _mm256_store_pd(yi, _mm256_add_pd(_mm256_load_pd(yi), _mm256_load_pd(r[i].v)));
  }
}

TISSUE_AVX2 double prolong_avx2(const Pad3* r, const Pad3* y, const std::uint32_t* aggregate, Pad3* z, std::size_t n) {
  __m256d acc = _mm256_setzero_pd();
  for (std::size_t i = 0; i < n; ++i) {
    const __m256d zi = _mm256_add_pd(_mm256_load_pd(z[i].v), _mm256_load_pd(y[aggregate[i]].v));
    _mm256_store_pd(z[i].v, zi);
    acc = _mm256_add_pd(acc, _mm256_mul_pd(_mm256_load_pd(r[i].v), zi));
  }
  return sum_lanes_avx2(acc);
}
#endif

void restrict_to_aggregates(Simd simd, const Pad3* r, const std::uint32_t* aggregate, Pad3* y, std::size_t n) {
#if defined(__x86_64__)
  if (simd == Simd::kAvx2) return restrict_avx2(r, aggregate, y, n);
#endif
  restrict_scalar(r, aggregate, y, n);
}

double prolong_from_aggregates(Simd simd, const Pad3* r, const Pad3* y, const std::uint32_t* aggregate, Pad3* z,
                               std::size_t n) {
#if defined(__x86_64__)
  if (simd == Simd::kAvx2) return prolong_avx2(r, y, aggregate, z, n);
#endif
  return prolong_scalar(r, y, aggregate, z, n);
}

}  // namespace

void ImplicitIntegrator::build_aggregates(const Body& body) {
  // Cells of a coarse grid over the object's box, sized for ~27 free nodes
  // each (3 per axis on a uniform mesh), at most ~300 cells (the band
  // Cholesky grows as cells x band²); numbered with the box's longest axis
  // slowest, so coupled cells (neighbours) are close in number and the
  // coarse matrix is banded. Measured (BM_ImplicitPreconditioner, tip error
  // vs the 1e-10 solve): 27 nodes per aggregate against 64, R2 dt 1 ms cg5
  // 0.0002 % vs 0.0037 % at the same 0.27 ms; R3 dt 10 ms cg20 0.0007 % vs
  // 0.0025 % at 6.5 vs 5.2 ms; 125 was worse still (0.076 % at R2 cg5).
  constexpr double kNodesPerAggregate = 27.0, kMaxAggregates = 300.0;
  const auto& object = body.scene().object;
  double extent[3];
  for (int i = 0; i < 3; ++i) extent[i] = object.cubes[i] * object.cube_size_m;
  const double volume = extent[0] * extent[1] * extent[2];
  const double nodes_per_aggregate = std::max(kNodesPerAggregate, unknowns_ / kMaxAggregates);
  const double cell = std::cbrt(volume * nodes_per_aggregate / std::max<double>(1.0, unknowns_));
  int cells[3];
  for (int i = 0; i < 3; ++i) cells[i] = std::max(1, static_cast<int>(std::lround(extent[i] / cell)));
  int order[3] = {0, 1, 2};  // slowest first
  std::sort(order, order + 3, [&](int a, int b) { return extent[a] > extent[b] || (extent[a] == extent[b] && a < b); });
  std::vector<std::uint32_t> compact(static_cast<std::size_t>(cells[0]) * cells[1] * cells[2], kNoAggregate);
  aggregate_of_unknown_.assign(unknowns_ + 1, kNoAggregate);
  std::vector<std::size_t> cell_of_unknown(unknowns_);
  for (std::uint32_t u = 0; u < unknowns_; ++u) {
    const Vec3& r = body.rest_m[node_of_unknown_[u]];
    std::size_t index = 0;
    for (int axis : order) {
      const int c = std::clamp(static_cast<int>(r[axis] / extent[axis] * cells[axis]), 0, cells[axis] - 1);
      index = index * static_cast<std::size_t>(cells[axis]) + static_cast<std::size_t>(c);
    }
    cell_of_unknown[u] = index;
    compact[index] = 0;  // occupied
  }
  std::uint32_t aggregates = 0;
  for (auto& c : compact)
    if (c == 0) c = aggregates++;
  for (std::uint32_t u = 0; u < unknowns_; ++u) aggregate_of_unknown_[u] = compact[cell_of_unknown[u]];
  coarse_dofs_ = 3 * aggregates;
  coarse_pad_.assign(aggregates, Pad3{});
  band_ = 2;  // within a 3x3 diagonal block
  coarse_springs_.clear();
  coarse_pairs_.clear();
  std::vector<std::pair<std::uint64_t, std::uint32_t>> pair_keys;  // (hi, lo) → spring
  for (std::size_t s = 0; s < live_edges_.size(); ++s) {
    const EdgeId e = live_edges_[s];
    const std::uint32_t i = aggregate_of_unknown_[unknown_of_node_[body.edge_a[e]]];
    const std::uint32_t j = aggregate_of_unknown_[unknown_of_node_[body.edge_b[e]]];
    if (i == j) continue;  // inside one aggregate: cancels in Pᵀ A P
    // A kinematic end has no aggregate (kNoAggregate sorts as the largest):
    // its pair is (aggregate, none) and only feeds that diagonal block.
    const std::uint32_t lo = std::min(i, j), hi = std::max(i, j);
    pair_keys.push_back({static_cast<std::uint64_t>(hi) << 32 | lo, static_cast<std::uint32_t>(s)});
    if (hi != kNoAggregate) band_ = std::max(band_, 3 * hi + 2 - 3 * lo);
  }
  std::sort(pair_keys.begin(), pair_keys.end());
  for (const auto& [key, spring] : pair_keys) {
    const std::uint32_t hi = static_cast<std::uint32_t>(key >> 32), lo = static_cast<std::uint32_t>(key);
    if (coarse_pairs_.empty() || coarse_pairs_.back().hi != hi || coarse_pairs_.back().lo != lo)
      coarse_pairs_.push_back({hi, lo});
    coarse_springs_.push_back({spring, static_cast<std::uint32_t>(coarse_pairs_.size() - 1)});
  }
  pair_blocks_.assign(coarse_pairs_.size() * 6, 0.0);
  coarse_factor_.assign(static_cast<std::size_t>(coarse_dofs_) * (band_ + 1), 0.0);
  coarse_rhs_.assign(coarse_dofs_, 0.0);
}

bool ImplicitIntegrator::factor_coarse() {
  const std::size_t width = band_ + 1;
  double* const band = coarse_factor_.data();
  // Lower band: entry (row, col), col in [row − band_, row], at
  // band[row * width + col − row + band_].
  auto at = [&](std::uint32_t row, std::uint32_t col) -> double& { return band[row * width + col + band_ - row]; };
  std::fill(coarse_factor_.begin(), coarse_factor_.end(), 0.0);
  for (std::uint32_t u = 0; u < unknowns_; ++u) {
    const std::uint32_t base = 3 * aggregate_of_unknown_[u];
    for (int k = 0; k < 3; ++k) at(base + k, base + k) += mass_[u] * record_scale2_;  // true units
  }
  // Pᵀ B P per spring: B on both diagonal blocks, −B on the coupling block;
  // springs inside one aggregate cancel. Summed per aggregate pair first
  // (6 entries of the symmetric B, springs in pair order), then spread:
  // straight into the band this was 21 scattered updates per crossing spring,
  // ~1 ms of a 6.4 ms two-level step at R3.
  std::fill(pair_blocks_.begin(), pair_blocks_.end(), 0.0);
  for (const CoarseSpring& coarse : coarse_springs_) {
    const ImplicitSpring& s = springs_[coarse.spring];
    const double e[3] = {s.e[0], s.e[1], s.e[2]}, iso = s.iso;  // in the records' scale
    double* const sum = pair_blocks_.data() + 6 * coarse.pair;
    sum[0] += e[0] * e[0] + iso;  // xx
    sum[1] += e[1] * e[0];        // yx
    sum[2] += e[1] * e[1] + iso;  // yy
    sum[3] += e[2] * e[0];        // zx
    sum[4] += e[2] * e[1];        // zy
    sum[5] += e[2] * e[2] + iso;  // zz
  }
  constexpr int kRow[6] = {0, 1, 1, 2, 2, 2}, kCol[6] = {0, 0, 1, 0, 1, 2};
  for (std::size_t p = 0; p < coarse_pairs_.size(); ++p) {
    const std::uint32_t hi = coarse_pairs_[p].hi, lo = coarse_pairs_[p].lo;
    double sum[6];  // true units (S times the records')
    for (int t = 0; t < 6; ++t) sum[t] = pair_blocks_[6 * p + t] * record_scale2_;
    for (const std::uint32_t end : {hi, lo}) {
      if (end == kNoAggregate) continue;  // a kinematic end
      for (int t = 0; t < 6; ++t) at(3 * end + kRow[t], 3 * end + kCol[t]) += sum[t];
    }
    if (hi != kNoAggregate)  // both ends free: the coupling block (hi, lo), full 3x3
      for (int t = 0; t < 6; ++t) {
        at(3 * hi + kRow[t], 3 * lo + kCol[t]) -= sum[t];
        if (kRow[t] != kCol[t]) at(3 * hi + kCol[t], 3 * lo + kRow[t]) -= sum[t];
      }
  }
  // In-place band Cholesky, A = L Lᵀ, by rows. The inner products run on
  // four partial sums (a single sum is one dependent add per term: the
  // factorisation took ~1 ms of a 6.4 ms two-level step at R3).
  for (std::uint32_t row = 0; row < coarse_dofs_; ++row) {
    const std::uint32_t first = row > band_ ? row - band_ : 0;
    const double* const row_entries = &at(row, 0);
    for (std::uint32_t col = first; col <= row; ++col) {
      const double* const col_entries = &at(col, 0);
      const std::uint32_t k0 = std::max(first, col > band_ ? col - band_ : 0);
      double partial[4] = {at(row, col), 0.0, 0.0, 0.0};
      std::uint32_t k = k0;
      for (; k + 4 <= col; k += 4)
        for (int j = 0; j < 4; ++j) partial[j] -= row_entries[k + j] * col_entries[k + j];
      for (; k < col; ++k) partial[0] -= row_entries[k] * col_entries[k];
      const double sum = (partial[0] + partial[1]) + (partial[2] + partial[3]);
      if (col == row) {
        if (!(sum > 0.0)) return false;
        at(row, row) = std::sqrt(sum);
      } else {
        at(row, col) = sum / at(col, col);
      }
    }
  }
  return true;
}

double ImplicitIntegrator::coarse_correct() {
  const std::size_t width = band_ + 1;
  const double* const band = coarse_factor_.data();
  auto at = [&](std::uint32_t row, std::uint32_t col) { return band[row * width + col + band_ - row]; };
  std::fill(coarse_pad_.begin(), coarse_pad_.end(), Pad3{});
  restrict_to_aggregates(simd_, r_.data(), aggregate_of_unknown_.data(), coarse_pad_.data(), unknowns_);  // Pᵀ r
  double* const y = coarse_rhs_.data();
  for (std::uint32_t i = 0; i < coarse_dofs_; ++i) y[i] = coarse_pad_[i / 3].v[i % 3];
  for (std::uint32_t row = 0; row < coarse_dofs_; ++row) {  // L y' = y, by rows of L
    // Four partial sums: the band's dot products are latency-bound otherwise.
    const std::uint32_t first = row > band_ ? row - band_ : 0;
    double sum[4] = {y[row], 0.0, 0.0, 0.0};
    std::uint32_t k = first;
    for (; k + 4 <= row; k += 4)
      for (int j = 0; j < 4; ++j) sum[j] -= at(row, k + j) * y[k + j];
    for (; k < row; ++k) sum[0] -= at(row, k) * y[k];
    y[row] = ((sum[0] + sum[1]) + (sum[2] + sum[3])) / at(row, row);
  }
  for (std::uint32_t row = coarse_dofs_; row-- > 0;) {  // Lᵀ x = y', by rows of L too
    y[row] /= at(row, row);
    const std::uint32_t first = row > band_ ? row - band_ : 0;
    for (std::uint32_t k = first; k < row; ++k) y[k] -= at(row, k) * y[row];
  }
  for (std::uint32_t i = 0; i < coarse_dofs_; ++i) coarse_pad_[i / 3].v[i % 3] = y[i];
  return prolong_from_aggregates(simd_, r_.data(), coarse_pad_.data(), aggregate_of_unknown_.data(), z_.data(),
                                 unknowns_);  // z += P x, rᵀz
}

}  // namespace tissue::physics
