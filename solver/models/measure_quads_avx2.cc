// The measure's quadrilateral kernels for the build's baseline instruction
// set (AVX2 and FMA with the project's -march=x86-64-v3; none without AVX2).
#define DYNSOLID_QUADS_NS avx2
#include "solver/models/measure_quads.inc"
