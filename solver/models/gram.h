// G = W^T W for a tall W: the cell partials' one big product (a cell's
// stiffness and mass partials are the Gram matrices of its quadrature
// points' rows; solid/cell_partials.h).
//
// Eigen's rank update packs both copies of W on every call, and W is
// used once: where W is a couple of thousand rows by a hundred or two
// columns, the packing took a third of the product's time. Here W is
// read in place, column major, and the kernels are compiled for AVX2 (the
// build's baseline) and once more for AVX-512 (run where the CPU has it),
// like the deformation measure's (measure.h). Every entry of G is a dot
// product of two columns of W, in eight lanes.
//
// Every path gives the same bits, whatever the instruction set: the sum
// is defined, not left to a kernel's register blocking. W's rows are
// taken in panels of kGramPanelRows (the last one shorter); within a
// panel, row r goes to lane r mod 8, each lane one fused multiply-add
// chain over its rows in ascending order, from zero; a panel's eight
// lanes are added as ((l0 + l4) + (l2 + l6)) + ((l1 + l5) + (l3 + l7));
// and G(i, j) is the sum of the panels in order, from zero. An AVX-512
// register holds the eight lanes, two AVX2 registers hold four each, the
// portable path is scalar std::fma in the same order. G(i, j) and G(j, i)
// are the same chains (a b = b a), so G is symmetric to the bit.
#pragma once

#include <cstddef>
#include <cstdint>
#include <new>

namespace dynsolid::models {

// Rows per panel (a multiple of 8).
inline constexpr int64_t kGramPanelRows = 512;
static_assert(kGramPanelRows % 8 == 0 && kGramPanelRows <= 512,
              "a panel's 8-row chunks fit one 64-bit mask (GramAddPanel)");

// An allocator of 64-byte aligned T (Gram's W).
template <typename T>
struct AlignedAllocator64 {
  using value_type = T;
  AlignedAllocator64() = default;
  template <typename U>
  AlignedAllocator64(const AlignedAllocator64<U>&) {}
  T* allocate(size_t n) {
    return static_cast<T*>(::operator new(n * sizeof(T), std::align_val_t{64}));
  }
  void deallocate(T* p, size_t) { ::operator delete(p, std::align_val_t{64}); }
  template <typename U>
  bool operator==(const AlignedAllocator64<U>&) const {
    return true;
  }
};
using GramAllocator = AlignedAllocator64<double>;

enum class GramPath { kPortable, kAvx2, kAvx512 };

// W: rows x n column major, leading dimension ldw >= rows; rows a
// multiple of 8 (pad with zero rows: they add nothing). Fastest where W
// is 64-byte aligned (GramAllocator) and ldw a multiple of 8: every
// AVX-512 load of a column is then one cache line, not two. G: n x n
// column major, leading dimension ldg >= n, overwritten with W^T W (both
// triangles). The fastest path this CPU runs.
void Gram(const double* w, int64_t rows, int n, int64_t ldw, double* g, int64_t ldg);
// The same on a given path (tests compare them); false, and G untouched,
// where this CPU or build cannot run it.
bool Gram(GramPath path, const double* w, int64_t rows, int n, int64_t ldw, double* g,
          int64_t ldg);
// The same sum a panel at a time, for a caller that makes W's rows as it
// goes (and keeps only a panel of them): GramStart zeroes G's lower
// triangle; GramAddPanel adds the sums of one panel of rows (a multiple of
// 8; each panel but the last exactly kGramPanelRows rows, in order) to it;
// GramFinish copies the lower triangle to the upper. Gram is these three.
void GramStart(int n, double* g, int64_t ldg);
void GramAddPanel(const double* w, int64_t rows, int n, int64_t ldw, double* g, int64_t ldg);
bool GramAddPanel(GramPath path, const double* w, int64_t rows, int n, int64_t ldw, double* g,
                  int64_t ldg);
void GramFinish(int n, double* g, int64_t ldg);
// A panel where most of W is known zero (a cell's element rows are zero
// outside the element's support): chunks[c]'s bit b is set where rows
// [8 b, 8 b + 8) of column c may be nonzero (b < 64: a panel has at most
// kGramPanelRows rows). Rows outside a column's chunks must be zeros (a
// kernel's block of columns may still read them); the chunks no product
// of a block's columns is nonzero in, and blocks of G with none, are
// skipped. The same bits as the unmasked sum where those rows are zero:
// each skipped product is an exact zero, and a lane's sum (from +0, never
// -0 in round to nearest) plus zero is that sum.
void GramAddPanel(const double* w, int64_t rows, int n, int64_t ldw, const uint64_t* chunks,
                  double* g, int64_t ldg);
bool GramAddPanel(GramPath path, const double* w, int64_t rows, int n, int64_t ldw,
                  const uint64_t* chunks, double* g, int64_t ldg);
// The path Gram takes here, and a name for it ("avx512", "avx2", "portable").
GramPath FastestGramPath();
const char* GramPathName(GramPath path);

}  // namespace dynsolid::models
