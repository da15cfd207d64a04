// The Gram kernels for AVX2 and FMA, the build's baseline (x86-64-v3);
// nothing where the build is not for them (gram.cc then runs the portable
// path).
#if defined(__AVX2__) && defined(__FMA__)
#define DYNSOLID_GRAM_NS avx2
#include "solver/models/gram_kernels.inc"
#endif
