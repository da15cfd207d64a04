// The deformation measure's corner formulas (measure.h), written once for a
// value type T and shared by the per-corner loops (measure.cc, T = double)
// and the quadrilateral kernels (measure_quads.inc, T = a SIMD lanes type
// of the kernel's own namespace, one per instruction set). Internal to
// solver/models: include it only from the measure's .cc files.
//
// Nothing here may be emitted out of line under one instruction set and
// linked into another's caller: the templates are instantiated with each
// kernel's own Lanes type (distinct symbols per instruction set), and the
// double helpers are only used by measure.cc.
#pragma once

#include <algorithm>
#include <cmath>

namespace dynsolid::models::measure_detail {

// Conditions are masks of T: 0 or 1 for double (bool lanes keep GCC from
// vectorizing), all bits for the SIMD lanes types.
inline double Sqrt(double a) { return std::sqrt(a); }
inline double Min(double a, double b) { return std::min(a, b); }
inline double Max(double a, double b) { return std::max(a, b); }
inline double Greater(double a, double b) { return a > b ? 1.0 : 0.0; }
inline double NotLess(double a, double b) { return a >= b ? 1.0 : 0.0; }
inline double And(double m, double n) { return m > 0 ? n : 0.0; }
inline double Select(double m, double a, double b) { return m > 0 ? a : b; }

// Corner geometry (n; a, b) from ra = a - n and rb = b - n: with
// phi = (theta - theta0) / 2, C = cos(phi), S = sin(phi), rotating a by
// +phi and b by -phi about n gives delta_a = alpha ra - beta la b^ and
// delta_b = alpha rb - beta lb a^, alpha = 1 - C + c S / s, beta = S / s
// (c, s the cosine and sine of the current angle). A degenerate corner (a
// zero side, collinear sides, or an angle half a turn from its rest value)
// contributes nothing: its alpha, beta and their derivatives in theta are
// zero and its other values finite.
template <typename T>
struct CornerGeometry {
  T ax, ay, az, bx, by, bz;  // unit sides a^, b^
  T la, lb;                  // side lengths (1 for a zero side)
  T ia, ib;                  // their inverses (0 for a zero side)
  T c, inv_s;                // cos theta, 1 / sin theta
  T al, bt, dal, dbt;        // alpha, beta and their theta derivatives
};

// A side's length and inverse: l = |r| and 1 / l (1 for a zero side).
template <typename T>
struct Side {
  T l, inv;
};
template <typename T>
[[gnu::always_inline]] inline Side<T> MeasureSide(T rx, T ry, T rz) {
  const T l = Sqrt(rx * rx + ry * ry + rz * rz);
  return {l, T(1.0) / Select(Greater(l, T(0.0)), l, T(1.0))};
}

// The corner's geometry from its sides ra, rb, their lengths and inverses
// (MeasureSide), and its rest angle's cosine and sine.
template <typename T>
[[gnu::always_inline]] inline CornerGeometry<T> MeasureCorner(T rax, T ray, T raz, T rbx, T rby,
                                                              T rbz, Side<T> sa, Side<T> sb,
                                                              T cos0, T sin0) {
  CornerGeometry<T> g;
  const T lra = sa.l, lrb = sb.l;
  const T sides = Greater(Min(lra, lrb), T(0.0));
  const T ia = Select(sides, sa.inv, T(0.0)), ib = Select(sides, sb.inv, T(0.0));
  g.ax = rax * ia, g.ay = ray * ia, g.az = raz * ia;
  g.bx = rbx * ib, g.by = rby * ib, g.bz = rbz * ib;
  const T c = g.ax * g.bx + g.ay * g.by + g.az * g.bz;
  const T x0 = g.ay * g.bz - g.az * g.by, x1 = g.az * g.bx - g.ax * g.bz,
          x2 = g.ax * g.by - g.ay * g.bx;
  const T sn = Sqrt(x0 * x0 + x1 * x1 + x2 * x2);
  // phi in (-pi/2, pi/2) by half-angle formulas.
  const T cos_d = c * cos0 + sn * sin0;
  const T sin_d = sn * cos0 - c * sin0;
  const T cap_c = Sqrt(Max(T(0.0), T(0.5) * (T(1.0) + cos_d)));
  const T ok_s = And(Greater(sn, T(1e-300)), sides);
  const T okf = And(NotLess(cap_c, T(1e-12)), ok_s);
  const T s_safe = Select(okf, sn, T(1.0)), c_safe = Select(okf, cap_c, T(1.0));
  const T is = T(1.0) / s_safe;
  const T cap_s = sin_d / (T(2.0) * c_safe);
  const T bt_any = cap_s * is;
  const T al_any = T(1.0) - c_safe + c * bt_any;
  const T dal_any = T(-0.5) * cap_s + c * c_safe * T(0.5) * is - c * c * cap_s * is * is;
  const T dbt_any = c_safe * T(0.5) * is - cap_s * c * is * is;
  g.bt = Select(okf, bt_any, T(0.0));
  g.al = Select(okf, al_any, T(0.0));
  g.dal = Select(okf, dal_any, T(0.0));
  g.dbt = Select(okf, dbt_any, T(0.0));
  g.la = Select(sides, lra, T(1.0));
  g.lb = Select(sides, lrb, T(1.0));
  g.ia = ia;
  g.ib = ib;
  g.c = c;
  g.inv_s = is;
  return g;
}

// A corner's terms on a and b.
template <typename T>
struct CornerTerms {
  T ax, ay, az, bx, by, bz;
};

// Forward: delta_a = alpha ra - beta la b^, delta_b = alpha rb - beta lb a^.
template <typename T>
[[gnu::always_inline]] inline CornerTerms<T> ForwardTerms(T rax, T ray, T raz, T rbx, T rby,
                                                          T rbz, const CornerGeometry<T>& g) {
  // With a zero side, la/lb hold 1 but alpha = beta = 0: the true lengths
  // times beta are zero either way.
  const T bla = g.bt * g.la, blb = g.bt * g.lb;
  return {g.al * rax - bla * g.bx, g.al * ray - bla * g.by, g.al * raz - bla * g.bz,
          g.al * rbx - blb * g.ax, g.al * rby - blb * g.ay, g.al * rbz - blb * g.az};
}

// Transpose: dF/dra and dF/drb for F = ya.delta_a + yb.delta_b (derivation
// at CornerTranspose below).
template <typename T>
[[gnu::always_inline]] inline CornerTerms<T> TransposeTerms(T yax, T yay, T yaz, T ybx, T yby,
                                                            T ybz, const CornerGeometry<T>& g) {
  const T ax = g.ax, ay = g.ay, az = g.az, bx = g.bx, by = g.by, bz = g.bz;
  const T lra = g.la, lrb = g.lb, c = g.c;
  const T al = g.al, bt = g.bt;
  const T yab = yax * bx + yay * by + yaz * bz;
  const T yba = ybx * ax + yby * ay + ybz * az;
  const T pp = lra * (yax * ax + yay * ay + yaz * az) + lrb * (ybx * bx + yby * by + ybz * bz);
  const T qq = lra * yab + lrb * yba;
  const T coef = pp * g.dal - qq * g.dbt;
  // (With a zero side ia and ib are 0, and so are alpha, beta and their
  // derivatives: the terms are zero either way.)
  const T ka = -coef * g.inv_s * g.ia, kb = -coef * g.inv_s * g.ib;
  const T lba = lrb * g.ia, lab = lra * g.ib;
  return {ka * (bx - c * ax) + al * yax - bt * (yab * ax + lba * (ybx - yba * ax)),
          ka * (by - c * ay) + al * yay - bt * (yab * ay + lba * (yby - yba * ay)),
          ka * (bz - c * az) + al * yaz - bt * (yab * az + lba * (ybz - yba * az)),
          kb * (ax - c * bx) + al * ybx - bt * (yba * bx + lab * (yax - yab * bx)),
          kb * (ay - c * by) + al * yby - bt * (yba * by + lab * (yay - yab * by)),
          kb * (az - c * bz) + al * ybz - bt * (yba * bz + lab * (yaz - yab * bz))};
}

}  // namespace dynsolid::models::measure_detail
