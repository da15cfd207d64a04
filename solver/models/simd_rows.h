// AVX2 helpers for node rows (x, y, z in three consecutive doubles), shared
// by the models' element kernels (local_frame.cc, corotational.cc). Only
// included where __AVX2__ and __FMA__ are defined.
#pragma once

#include <cstdint>

#include <immintrin.h>

namespace dynsolid::models::simd {

// Row `id` of a #nodes x 3 row-major array as (x, y, z, 0); reads nothing
// past the row.
inline __m256d LoadRow(const double* base, int32_t id) {
  return _mm256_maskload_pd(base + 3 * static_cast<int64_t>(id),
                            _mm256_setr_epi64x(-1, -1, -1, 0));
}

}  // namespace dynsolid::models::simd
