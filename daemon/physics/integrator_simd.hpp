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
#endif

}  // namespace tissue::physics
