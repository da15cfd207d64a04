// Shape functions of the three element kinds on the unit cube (u, v, w) in
// [0, 1]^3: values N (n) and parametric derivatives dN (n by 3, row-major:
// dN[3 i + k] = dN_i / du_k).
//  - cubic: the 64 tricubic B-spline products, node m = 16 i + 4 j + k has
//    N_m = B_i(u) B_j(v) B_k(w);
//  - linear: trilinear, nodes in VTK hexahedron order;
//  - pyramid: the trilinear hexahedron with its top face collapsed onto the
//    apex (node 4): N_apex = w, base nodes 0-3 bilinear times (1 - w).
// All three sum to 1 (partition of unity) and reproduce linear fields of
// their nodes' positions where the geometry is affine.
#pragma once

#include "solver/fem/element_set.h"

namespace dynsolid::fem {

inline constexpr int NodesOf(ElementKind kind) {
  return kind == ElementKind::kCubic ? kCubicNodes
         : kind == ElementKind::kLinear ? kLinearNodes
                                        : kPyramidNodes;
}

// Gauss-Legendre points per direction used for each kind (docs/model.md
// section 3: 4 on cubic elements, 2 on linear and pyramid elements).
inline constexpr int QuadratureOrder(ElementKind kind) {
  return kind == ElementKind::kCubic ? 4 : 2;
}

void CubicShape(double u, double v, double w, double* n, double* dn);
void LinearShape(double u, double v, double w, double* n, double* dn);
void PyramidShape(double u, double v, double w, double* n, double* dn);

// Dispatch on kind; n and dn must hold NodesOf(kind) (times 3) values.
void Shape(ElementKind kind, double u, double v, double w, double* n, double* dn);

}  // namespace dynsolid::fem
