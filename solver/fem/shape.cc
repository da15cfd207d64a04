#include "solver/fem/shape.h"

#include "solver/fem/basis.h"

namespace dynsolid::fem {
namespace {

constexpr int kCorner[8][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0},
                               {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};

}  // namespace

void CubicShape(double u, double v, double w, double* n, double* dn) {
  const auto bu = CubicBSpline(u), bv = CubicBSpline(v), bw = CubicBSpline(w);
  const auto du = CubicBSplineDerivative(u), dv = CubicBSplineDerivative(v),
             dw = CubicBSplineDerivative(w);
  for (int i = 0; i < 4; ++i) {
    for (int j = 0; j < 4; ++j) {
      for (int k = 0; k < 4; ++k) {
        const int m = 16 * i + 4 * j + k;
        n[m] = bu[i] * bv[j] * bw[k];
        dn[3 * m + 0] = du[i] * bv[j] * bw[k];
        dn[3 * m + 1] = bu[i] * dv[j] * bw[k];
        dn[3 * m + 2] = bu[i] * bv[j] * dw[k];
      }
    }
  }
}

void LinearShape(double u, double v, double w, double* n, double* dn) {
  const double p[3] = {u, v, w};
  for (int a = 0; a < 8; ++a) {
    double f[3], d[3];
    for (int k = 0; k < 3; ++k) {
      f[k] = kCorner[a][k] ? p[k] : 1.0 - p[k];
      d[k] = kCorner[a][k] ? 1.0 : -1.0;
    }
    n[a] = f[0] * f[1] * f[2];
    dn[3 * a + 0] = d[0] * f[1] * f[2];
    dn[3 * a + 1] = f[0] * d[1] * f[2];
    dn[3 * a + 2] = f[0] * f[1] * d[2];
  }
}

void PyramidShape(double u, double v, double w, double* n, double* dn) {
  double hn[8], hdn[24];
  LinearShape(u, v, w, hn, hdn);
  for (int a = 0; a < 4; ++a) {
    n[a] = hn[a];
    for (int k = 0; k < 3; ++k) dn[3 * a + k] = hdn[3 * a + k];
  }
  n[4] = hn[4] + hn[5] + hn[6] + hn[7];
  for (int k = 0; k < 3; ++k) dn[12 + k] = hdn[12 + k] + hdn[15 + k] + hdn[18 + k] + hdn[21 + k];
}

void Shape(ElementKind kind, double u, double v, double w, double* n, double* dn) {
  switch (kind) {
    case ElementKind::kCubic: CubicShape(u, v, w, n, dn); return;
    case ElementKind::kLinear: LinearShape(u, v, w, n, dn); return;
    case ElementKind::kPyramid: PyramidShape(u, v, w, n, dn); return;
  }
}

}  // namespace dynsolid::fem
