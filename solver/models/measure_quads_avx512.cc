// The measure's quadrilateral kernels for AVX-512 (F, DQ, VL): this file
// alone is compiled with those flags (solver/models/CMakeLists.txt), and
// measure.cc calls it only on a CPU that has them.
#if !defined(__AVX512F__) || !defined(__AVX512DQ__) || !defined(__AVX512VL__)
#error "measure_quads_avx512.cc must be compiled with -mavx512f -mavx512dq -mavx512vl"
#endif
// GCC 12's AVX-512 intrinsics fill the unused merge operand of their
// unmasked forms with a self-initialized "undefined" vector, which
// -Wuninitialized reports at every use (GCC bug 105593, fixed in GCC 13).
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wuninitialized"
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#define DYNSOLID_QUADS_NS avx512
#include "solver/models/measure_quads.inc"
#pragma GCC diagnostic pop
