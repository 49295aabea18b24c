#pragma once
/// @file cubic.h
/// @brief Along a ray, the trilinear interpolant of a cell is a cubic in the ray parameter
/// (Marmitt et al.; Neubauer et al.). These routines build that cubic and isolate its roots
/// robustly: the interval is split at the roots of the derivative, so that each piece is
/// monotone, holds at most one root, and a tangent (double) root shows up as an extremum that
/// touches zero.

#include <algorithm>
#include <cmath>
#include <optional>

namespace brickyard {

/// @brief g(s) = c0 + c1 s + c2 s^2 + c3 s^3.
struct Cubic {
  double c0 = 0, c1 = 0, c2 = 0, c3 = 0;
  double operator()(double s) const { return ((c3 * s + c2) * s + c1) * s + c0; }
  double derivative(double s) const { return (3 * c3 * s + 2 * c2) * s + c1; }
};

/// @brief The cubic of the trilinear interpolant of corners c (index dx + 2 dy + 4 dz) minus
/// `offset`, along u(s) = u0 + s * du in the cell's local coordinates.
inline Cubic trilinear_cubic(const double c[8], double offset, const double u0[3], const double du[3]) {
  Cubic g;
  for (int n = 0; n < 8; ++n) {
    // Each weight is linear in s: w = a + b s, with w = u for the upper corner, 1 - u below.
    double a[3], b[3];
    for (int axis = 0; axis < 3; ++axis) {
      const bool upper = (n >> axis) & 1;
      a[axis] = upper ? u0[axis] : 1 - u0[axis];
      b[axis] = upper ? du[axis] : -du[axis];
    }
    const double v = c[n] - offset;
    g.c0 += v * a[0] * a[1] * a[2];
    g.c1 += v * (b[0] * a[1] * a[2] + a[0] * b[1] * a[2] + a[0] * a[1] * b[2]);
    g.c2 += v * (b[0] * b[1] * a[2] + b[0] * a[1] * b[2] + a[0] * b[1] * b[2]);
    g.c3 += v * b[0] * b[1] * b[2];
  }
  return g;
}

/// @brief The roots of c2 s^2 + c1 s + c0 in the open interval (lo, hi), ascending; returns
/// how many (0 to 2). Cancellation-free form of the quadratic formula.
inline int quadratic_roots_in(double c2, double c1, double c0, double lo, double hi, double out[2]) {
  // Past 2^500, c1^2 or 4 c2 c0 could overflow (the discriminant would be NaN, and the roots
  // lost): scaling all three by a power of two moves no root and rounds nothing.
  if (const double big = std::max({std::fabs(c2), std::fabs(c1), std::fabs(c0)}); big > 0x1p500 && std::isfinite(big)) {
    const int e = std::ilogb(big);
    c2 = std::ldexp(c2, -e), c1 = std::ldexp(c1, -e), c0 = std::ldexp(c0, -e);
  }
  double r[2];
  int n = 0;
  if (c2 == 0) {
    if (c1 != 0) r[n++] = -c0 / c1;
  } else {
    const double disc = c1 * c1 - 4 * c2 * c0;
    if (disc >= 0) {
      const double q = -0.5 * (c1 + std::copysign(std::sqrt(disc), c1));
      if (q != 0) {
        r[n++] = q / c2;
        r[n++] = c0 / q;
      } else {
        r[n++] = 0;  // c1 = c0 = 0: a double root at 0
      }
    }
  }
  int m = 0;
  for (int i = 0; i < n; ++i)
    if (r[i] > lo && r[i] < hi) out[m++] = r[i];
  if (m == 2 && out[0] > out[1]) std::swap(out[0], out[1]);
  return m;
}

/// @brief The first s in [0, length] where g(s) = 0, counting a tangent touch (|g| within a
/// relative `tolerance` at an extremum) as a root; nullopt when there is none. Sign changes are
/// refined by bisection to full double precision.
inline std::optional<double> first_root(const Cubic& g, double length, double tolerance = 1e-12) {
  if (!(length >= 0)) return std::nullopt;
  const double scale = std::fabs(g.c0) + std::fabs(g.c1) * length + std::fabs(g.c2) * length * length +
                       std::fabs(g.c3) * length * length * length;
  const double eps = tolerance * scale;
  double knots[4];
  int n = 0;
  knots[n++] = 0;
  double crit[2];
  const int nc = quadratic_roots_in(3 * g.c3, 2 * g.c2, g.c1, 0, length, crit);
  for (int i = 0; i < nc; ++i) knots[n++] = crit[i];
  knots[n++] = length;

  double s0 = knots[0], g0 = g(s0);
  if (std::fabs(g0) <= eps) return s0;
  for (int i = 1; i < n; ++i) {
    const double s1 = knots[i], g1 = g(s1);
    if ((g0 < 0) != (g1 < 0) && g1 != 0) {
      // Monotone between knots: exactly one crossing; bisect it.
      double lo = s0, hi = s1, glo = g0;
      for (int it = 0; it < 200 && hi - lo > 0; ++it) {
        const double mid = 0.5 * (lo + hi);
        if (mid <= lo || mid >= hi) break;
        const double gm = g(mid);
        if (gm == 0) return mid;
        if ((gm < 0) == (glo < 0)) {
          lo = mid;
          glo = gm;
        } else {
          hi = mid;
        }
      }
      return 0.5 * (lo + hi);
    }
    if (std::fabs(g1) <= eps) return s1;  // an extremum touching zero, or the end point
    s0 = s1;
    g0 = g1;
  }
  return std::nullopt;
}

/// @brief The crossing of a function between two samples that bracket it: g(a) = ga and
/// g(b) = gb differ in sign, or gb is exactly zero (then b is the crossing). `steps` bisections
/// (each one evaluation of g) narrow the bracket; the result is where the secant through its
/// ends crosses zero: on a field smooth inside the last bracket the error falls with the
/// bracket's square rather than its width, for no evaluation more. The marching back ends
/// refine their isosurface hits with it.
template <typename G>
double bisect_crossing(G&& g, double a, double b, double ga, double gb, int steps) {
  if (gb == 0) return b;
  for (int it = 0; it < steps; ++it) {
    const double mid = 0.5 * (a + b);
    const double gm = g(mid);
    if ((gm < 0) == (ga < 0)) a = mid, ga = gm;
    else b = mid, gb = gm;
  }
  if (gb == 0) return b;
  const double t = a + (b - a) * (ga / (ga - gb));
  return t >= std::min(a, b) && t <= std::max(a, b) ? t : 0.5 * (a + b);  // NaN samples: the midpoint
}

/// @brief Largest value of g on [0, length] and where it is (the first place, on ties).
inline double cubic_max(const Cubic& g, double length, double& where) {
  where = 0;
  double best = g(0);
  double crit[2];
  const int nc = quadratic_roots_in(3 * g.c3, 2 * g.c2, g.c1, 0, length, crit);
  for (int i = 0; i < nc; ++i)
    if (const double v = g(crit[i]); v > best) best = v, where = crit[i];
  if (const double v = g(length); v > best) best = v, where = length;
  return best;
}

}  // namespace brickyard
