// AVX2 helpers for node rows (x, y, z in three consecutive doubles), shared
// by the models' element kernels (local_frame.cc, corotational.cc) and the
// deformation measure's quadrilateral kernels (measure_quads.inc). Only
// included where __AVX2__ and __FMA__ are defined. Always inlined: the
// kernels are compiled once more with AVX-512 flags, and an out-of-line
// copy from that translation unit must never be the one the linker keeps
// for the others.
#pragma once

#include <cstdint>

#include <immintrin.h>

namespace dynsolid::models::simd {

// Row `id` of a #nodes x 3 row-major array as (x, y, z, 0); reads nothing
// past the row.
[[gnu::always_inline]] inline __m256d LoadRow(const double* base, int32_t id) {
  return _mm256_maskload_pd(base + 3 * static_cast<int64_t>(id),
                            _mm256_setr_epi64x(-1, -1, -1, 0));
}

// Rows r0..r3 (x, y, z, any) to columns x, y, z over the four rows.
[[gnu::always_inline]] inline void RowsToColumns(__m256d r0, __m256d r1, __m256d r2,
                                                 __m256d r3, __m256d& x, __m256d& y,
                                                 __m256d& z) {
  const __m256d t0 = _mm256_unpacklo_pd(r0, r1);  // x0 x1 z0 z1
  const __m256d t1 = _mm256_unpackhi_pd(r0, r1);  // y0 y1 . .
  const __m256d t2 = _mm256_unpacklo_pd(r2, r3);  // x2 x3 z2 z3
  const __m256d t3 = _mm256_unpackhi_pd(r2, r3);  // y2 y3 . .
  x = _mm256_permute2f128_pd(t0, t2, 0x20);
  y = _mm256_permute2f128_pd(t1, t3, 0x20);
  z = _mm256_permute2f128_pd(t0, t2, 0x31);
}

// Columns x, y, z over four rows to the rows (x_k, y_k, z_k, 0).
[[gnu::always_inline]] inline void ColumnsToRows(__m256d x, __m256d y, __m256d z,
                                                 __m256d row[4]) {
  const __m256d zero = _mm256_setzero_pd();
  const __m256d t0 = _mm256_unpacklo_pd(x, y);     // x0 y0 x2 y2
  const __m256d t1 = _mm256_unpackhi_pd(x, y);     // x1 y1 x3 y3
  const __m256d t2 = _mm256_unpacklo_pd(z, zero);  // z0 0 z2 0
  const __m256d t3 = _mm256_unpackhi_pd(z, zero);  // z1 0 z3 0
  row[0] = _mm256_permute2f128_pd(t0, t2, 0x20);
  row[1] = _mm256_permute2f128_pd(t1, t3, 0x20);
  row[2] = _mm256_permute2f128_pd(t0, t2, 0x31);
  row[3] = _mm256_permute2f128_pd(t1, t3, 0x31);
}

}  // namespace dynsolid::models::simd
