// Data layout and instruction-set choice for the integrators' hot loops
// (internal to physics/).
//
// A node's 3-vector is kept padded to four doubles (the fourth always 0), 32 B
// aligned, so one AVX register holds it: a spring's two gathers and two
// scatters become four 256-bit loads and two 256-bit stores instead of twelve
// scalar loads and six read-modify-writes.
//
// The AVX2 kernels are compiled with a per-function target attribute and
// picked at run time (cpuid), so the default x86-64 build stays portable. They
// use no FMA and sum in the same order as the scalar kernels, so both give
// bit-identical results (a test checks it): a batch report does not depend on
// the machine's instruction set.
#pragma once

#include <cstddef>
#include <cstdint>

#if defined(__x86_64__)
#include <immintrin.h>
// Marks a function compiled for AVX2 (called only after detected_simd()).
#define TISSUE_AVX2 __attribute__((target("avx2")))
#endif

namespace tissue::physics {

struct alignas(32) Pad3 {
  double v[4] = {0.0, 0.0, 0.0, 0.0};
};

enum class Simd : std::uint8_t { kScalar, kAvx2 };

// kAvx2 when the CPU has AVX2 (x86-64 only), else kScalar. Cached.
Simd detected_simd();

#if defined(__x86_64__)
// ((a0 + a1) + a2) + a3: the scalar kernels' summation order.
TISSUE_AVX2 inline double sum_lanes_avx2(__m256d acc) {
  alignas(32) double a[4];
  _mm256_store_pd(a, acc);
  return ((a[0] + a[1]) + a[2]) + a[3];
}

// Lane j of the result is mj's lanes summed as ((x + y) + (z + w)): four
// springs' dot products in one vector (lane 3 of a padded vector is 0, so
// this is the scalar kernels' ((x + y) + (z + 0))).
TISSUE_AVX2 inline __m256d lane_sums_avx2(__m256d m0, __m256d m1, __m256d m2, __m256d m3) {
  const __m256d t0 = _mm256_hadd_pd(m0, m1);  // m0.x+y, m1.x+y, m0.z+w, m1.z+w
  const __m256d t1 = _mm256_hadd_pd(m2, m3);
  const __m256d low = _mm256_blend_pd(t0, t1, 0b1100);        // m0.xy, m1.xy, m2.zw, m3.zw
  const __m256d high = _mm256_permute2f128_pd(t0, t1, 0x21);  // m0.zw, m1.zw, m2.xy, m3.xy
  return _mm256_add_pd(low, high);
}
#endif

}  // namespace tissue::physics
