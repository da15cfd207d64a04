// The Gram kernels for AVX-512 (F): this file alone is compiled with
// AVX-512 flags (solver/models/CMakeLists.txt), and gram.cc calls it only
// on a CPU that has them.
#if !defined(__AVX512F__)
#error "gram_avx512.cc must be compiled with -mavx512f"
#endif
// GCC 12's AVX-512 intrinsics warn of their own "undefined" merge operand
// (GCC bug 105593; measure_quads_avx512.cc).
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wuninitialized"
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#define DYNSOLID_GRAM_NS avx512
#include "solver/models/gram_kernels.inc"
#pragma GCC diagnostic pop
