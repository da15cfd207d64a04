#include "solver/integrators/reduced_cholesky.h"

#include <cholmod.h>

#include <algorithm>
#include <cstdlib>

namespace dynsolid::integrators {

struct ReducedCholesky::Impl {
  cholmod_common c;
  cholmod_factor* l = nullptr;
  // The right-hand side and CHOLMOD's solve workspace (cholmod_solve2
  // reuses them once allocated), for one column and for three.
  struct Work {
    cholmod_dense *b = nullptr, *x = nullptr, *y = nullptr, *e = nullptr;
  };
  Work work[2];
  std::vector<int32_t> free_rows;  // reduced index -> row of S
  bool ready = false;              // factored (or nothing free)
  int64_t rows = 0;                // of S

  Impl() {
    cholmod_start(&c);
    c.print = 0;  // a matrix that is not positive definite is an answer, not a message
    // The lower fill of two orders: METIS's nested dissection (the
    // B-spline mass of a 12^3 block: 0.8 M entries in L against AMD's 1.0 M)
    // and AMD (better on thin or small meshes).
    c.nmethods = 2;
    c.method[0].ordering = CHOLMOD_METIS;
    c.method[1].ordering = CHOLMOD_AMD;
    c.postorder = 1;
    c.supernodal = CHOLMOD_SUPERNODAL;
  }
  ~Impl() {
    Clear();
    cholmod_finish(&c);
  }
  void Clear() {
    ready = false;
    if (l != nullptr) cholmod_free_factor(&l, &c);
    for (Work& w : work) {
      for (cholmod_dense** d : {&w.b, &w.x, &w.y, &w.e}) {
        if (*d != nullptr) cholmod_free_dense(d, &c);
      }
    }
  }
};

ReducedCholesky::ReducedCholesky() = default;
ReducedCholesky::~ReducedCholesky() = default;
ReducedCholesky::ReducedCholesky(ReducedCholesky&&) noexcept = default;
ReducedCholesky& ReducedCholesky::operator=(ReducedCholesky&&) noexcept = default;

bool ReducedCholesky::factored() const { return impl_ != nullptr && impl_->ready; }

int64_t ReducedCholesky::factor_nonzeros() const {
  if (!factored() || impl_->l == nullptr) return 0;
  const cholmod_factor* l = impl_->l;
  if (l->is_super) return static_cast<int64_t>(l->xsize);
  int64_t nz = 0;
  const int* count = static_cast<const int*>(l->nz);
  for (size_t j = 0; j < l->n; ++j) nz += count[j];
  return nz;
}

bool ReducedCholesky::Factor(const SparseMatrix& s, const std::vector<uint8_t>& fixed,
                             Solves solves) {
  if (impl_ == nullptr) impl_ = std::make_unique<Impl>();
  Impl& im = *impl_;
  im.Clear();
  const int64_t n = s.rows();
  im.rows = n;
  auto is_fixed = [&](int64_t i) { return !fixed.empty() && fixed[i] != 0; };
  std::vector<int32_t> reduced(n, -1);
  im.free_rows.clear();
  for (int64_t i = 0; i < n; ++i) {
    if (is_fixed(i)) continue;
    reduced[i] = static_cast<int32_t>(im.free_rows.size());
    im.free_rows.push_back(static_cast<int32_t>(i));
  }
  const size_t nf = im.free_rows.size();
  if (nf == 0) return im.ready = true;  // nothing moves: Solve writes zeros
  // S is symmetric and row-major: row i's entries j >= i, read as a
  // compressed column, are column i of the lower triangle (stype -1).
  int64_t nnz = 0;
  for (int32_t i : im.free_rows) {
    for (SparseMatrix::InnerIterator it(s, i); it; ++it) {
      if (it.col() >= i && reduced[it.col()] >= 0) ++nnz;
    }
  }
  cholmod_sparse* a = cholmod_allocate_sparse(nf, nf, static_cast<size_t>(nnz), /*sorted=*/1,
                                              /*packed=*/1, /*stype=*/-1, CHOLMOD_REAL, &im.c);
  if (a == nullptr) return false;
  int* ap = static_cast<int*>(a->p);
  int* ai = static_cast<int*>(a->i);
  double* ax = static_cast<double*>(a->x);
  int32_t k = 0;
  for (size_t col = 0; col < nf; ++col) {
    ap[col] = k;
    const int32_t i = im.free_rows[col];
    for (SparseMatrix::InnerIterator it(s, i); it; ++it) {
      if (it.col() < i || reduced[it.col()] < 0) continue;
      ai[k] = reduced[it.col()];  // increasing with it.col(): sorted
      ax[k] = it.value();
      ++k;
    }
  }
  ap[nf] = k;
  im.l = cholmod_analyze(a, &im.c);
  bool ok = im.l != nullptr && cholmod_factorize(a, im.l, &im.c) != 0 &&
            im.c.status == CHOLMOD_OK && im.l->minor == nf;
  cholmod_free_sparse(&a, &im.c);
  // Simplicial LL^T for the solves (see Solves in the header).
  if (ok && solves == Solves::kSimplicial) {
    ok = cholmod_change_factor(CHOLMOD_REAL, /*to_ll=*/1, /*to_super=*/0, /*to_packed=*/1,
                               /*to_monotonic=*/1, im.l, &im.c) != 0;
  }
  if (ok) {
    im.work[0].b = cholmod_allocate_dense(nf, 1, nf, CHOLMOD_REAL, &im.c);
    im.work[1].b = cholmod_allocate_dense(nf, 3, nf, CHOLMOD_REAL, &im.c);
    ok = im.work[0].b != nullptr && im.work[1].b != nullptr;
  }
  if (!ok) im.Clear();
  im.ready = ok;
  return ok;
}

void ReducedCholesky::Solve(const Points& b, Points& x) {
  x.setZero(b.rows(), 3);
  SolveRows(b.data(), x.data(), 3);  // row-major: entry (i, c) at 3 i + c
}

void ReducedCholesky::SolveVector(const double* b, double* x) {
  if (impl_ != nullptr) std::fill(x, x + impl_->rows, 0.0);
  SolveRows(b, x, 1);
}

void ReducedCholesky::SolveRows(const double* b, double* x, int columns) {
  if (!factored()) return;
  Impl& im = *impl_;
  const size_t nf = im.free_rows.size();
  if (nf == 0) return;
  Impl::Work& w = im.work[columns == 1 ? 0 : 1];
  double* bx = static_cast<double*>(w.b->x);
  for (size_t k = 0; k < nf; ++k) {
    const double* row = b + static_cast<int64_t>(im.free_rows[k]) * columns;
    for (int c = 0; c < columns; ++c) bx[c * nf + k] = row[c];
  }
  cholmod_solve2(CHOLMOD_A, im.l, w.b, nullptr, &w.x, nullptr, &w.y, &w.e, &im.c);
  const double* xx = static_cast<const double*>(w.x->x);
  for (size_t k = 0; k < nf; ++k) {
    double* row = x + static_cast<int64_t>(im.free_rows[k]) * columns;
    for (int c = 0; c < columns; ++c) row[c] = xx[c * nf + k];
  }
}

}  // namespace dynsolid::integrators
