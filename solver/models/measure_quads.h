// The deformation measure's quadrilateral kernels (measure.h): four corners
// of a face in SIMD lanes, two faces (AVX2) or four (AVX-512) at a time.
// One copy per instruction set, each compiled from measure_quads.inc in its own translation unit
// and namespace (measure_quads_avx2.cc, measure_quads_avx512.cc); measure.cc
// picks one at run time. Internal to solver/models.
#pragma once

#include <cstdint>

namespace dynsolid::models::measure_detail {

// A quadrilateral's row of the measure's rest table: cos0[4], sin0[4], l0[4].
constexpr int kQuadRestRow = 12;

// nq quadrilaterals: their nodes qv (4 each, in loop order), rows rest_id
// of the rest table `rest`, and owns bytes (bit k: node k is the part's;
// bit 4 + k: side k carries its edge's stretch term). Forward adds each
// owned node's share of delta(pd) to `out`; transpose its share of
// (d delta / d d)^T py at pd.
using QuadsForwardFn = void (*)(const int32_t* qv, const double* rest, const uint32_t* rest_id,
                                const uint8_t* owns, int64_t nq, const double* pd, double* out);
using QuadsTransposeFn = void (*)(const int32_t* qv, const double* rest,
                                  const uint32_t* rest_id, const uint8_t* owns, int64_t nq,
                                  const double* pd, const double* py, double* out);
struct QuadKernels {
  QuadsForwardFn forward = nullptr;
  QuadsTransposeFn transpose = nullptr;
};

// Each instruction set's kernels; null functions where the build has none
// (no AVX2 at all, or a compiler without AVX-512). Whether the CPU runs
// them is the caller's question (measure.cc).
namespace avx2 {
QuadKernels Kernels();
}
namespace avx512 {
QuadKernels Kernels();
}

}  // namespace dynsolid::models::measure_detail
