#pragma once
/// @file cubic.h
/// @brief Along a ray, the trilinear interpolant of a cell is a cubic in the ray parameter
/// (Marmitt et al.; Neubauer et al.). These routines build that cubic and isolate its roots
/// robustly: the interval is split at the roots of the derivative, so that each piece is
/// monotone, holds at most one root, and a tangent (double) root shows up as an extremum that
/// touches zero. The crossing so isolated is refined by bisection (first_root) or by
/// Neubauer's repeated linear interpolation in its Illinois variant (first_root_falsi), which
/// takes a fifth of the evaluations for the same bracket.

#include <algorithm>
#include <cmath>
#include <optional>

#include "core/math.h"

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

/// @brief Where the first root of g on [0, length] lies, as first_root() and first_root_falsi()
/// both decide it, so that they agree on whether there is one by construction. The interval is
/// split at the roots of g' into pieces on which g is monotone; walking them in order, a knot
/// (0, an extremum or length) where |g| is within a relative `tolerance` of zero is the root
/// (`at`), and otherwise the first piece whose ends differ in sign holds exactly one crossing
/// (`crossing`): only that case is left to refine, and the two finders differ only there.
struct RootBracket {
  enum Kind { none, at, crossing } kind = none;
  double s = 0;                             ///< at: the root
  double lo = 0, hi = 0, glo = 0, ghi = 0;  ///< crossing: g(lo) and g(hi), of opposite signs, neither 0
};

/// @brief The first root's knot or bracket on [0, length] (see RootBracket); `none` for a
/// negative or NaN length, and for NaN coefficients.
inline RootBracket first_root_bracket(const Cubic& g, double length, double tolerance) {
  RootBracket out;
  auto at = [&out](double s) {
    out.kind = RootBracket::at;
    out.s = s;
    return out;
  };
  if (!(length >= 0)) return out;
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
  if (std::fabs(g0) <= eps) return at(s0);
  for (int i = 1; i < n; ++i) {
    const double s1 = knots[i], g1 = g(s1);
    if ((g0 < 0) != (g1 < 0) && g1 != 0) {
      // Monotone between knots: exactly one crossing.
      out.kind = RootBracket::crossing;
      out.lo = s0, out.hi = s1, out.glo = g0, out.ghi = g1;
      return out;
    }
    // An extremum touching zero, or the end point.
    if (std::fabs(g1) <= eps) return at(s1);
    s0 = s1;
    g0 = g1;
  }
  return out;
}

/// @brief The first s in [0, length] where g(s) = 0, counting a tangent touch (|g| within a
/// relative `tolerance` at an extremum) as a root; nullopt when there is none. Sign changes are
/// refined by bisection to full double precision.
inline std::optional<double> first_root(const Cubic& g, double length, double tolerance = 1e-12) {
  const RootBracket b = first_root_bracket(g, length, tolerance);
  if (b.kind == RootBracket::none) return std::nullopt;
  if (b.kind == RootBracket::at) return b.s;
  double lo = b.lo, hi = b.hi, glo = b.glo;
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

/// @brief The crossing of a monotone function between a < b, where g(a) = ga and g(b) = gb are
/// of opposite signs and neither is zero, by regula falsi with the Illinois modification: the
/// next point is where the line through the bracket's ends crosses zero, and the half with the
/// sign change is kept, for at most `steps` evaluations of g or until the bracket is at most
/// `width` wide. Each point keeps width / 2 from both ends, so that the step that lands next
/// to the root also closes the bracket. The answer is the falsi point of the last bracket,
/// through its true values.
///
/// Plain regula falsi converges only linearly where g is convex or concave over the bracket:
/// one end never moves. Halving the value used for an end kept twice in a row moves the next
/// point past the root and makes the convergence superlinear (order about 1.44 per evaluation).
/// On the cubics of random trilinear cells that is about 8 evaluations to a bracket 1e-12 of
/// the segment wide, 16 at most in 10^5 cells, where bisection takes 40; crossings that barely
/// pass an extremum (isovalues within 1e-4 to 1e-16 of its value) take up to 46.
template <typename G>
double falsi_crossing(G&& g, double a, double b, double ga, double gb, int steps, double width) {
  // The falsi point is drawn through weighted values; the true ones are kept for the answer.
  double wa = ga, wb = gb;
  int kept = 0;  // which end the last step kept: -1 a, +1 b
  // Where the line through (x0, y0) and (x1, y1), of opposite signs, crosses zero: 1 / (1 -
  // y1 / y0) of the way from x0, as y1 - y0 would overflow for values near the largest double.
  auto falsi = [](double x0, double x1, double y0, double y1) { return x0 + (x1 - x0) / (1 - y1 / y0); };
  for (int it = 0; it < steps && b - a > width; ++it) {
    // At least half the target width from either end. A falsi point next to the root (the
    // step that finds it) is then still far enough from that end that the root falls between
    // them, and the bracket closes on the next step; otherwise the far end would stay put for
    // dozens of halvings of its value.
    double s = falsi(a, b, wa, wb);
    if (s < a + 0.5 * width) s = a + 0.5 * width;
    if (s > b - 0.5 * width) s = b - 0.5 * width;
    if (!(s > a && s < b)) {
      s = 0.5 * (a + b);             // rounding on a bracket a few ulps wide, or NaN values
      if (!(s > a && s < b)) break;  // a and b are adjacent doubles
    }
    const double gs = g(s);
    if (gs == 0) return s;
    if ((gs < 0) == (ga < 0)) {
      a = s, ga = wa = gs;
      if (kept == +1) wb *= 0.5;
      kept = +1;
    } else {
      b = s, gb = wb = gs;
      if (kept == -1) wa *= 0.5;
      kept = -1;
    }
  }
  const double s = falsi(a, b, ga, gb);
  return s >= a && s <= b ? s : 0.5 * (a + b);
}

/// @brief first_root() with the crossing refined by repeated linear interpolation instead of
/// bisection, as Neubauer et al. (2002) and Marmitt et al. (2004) do, in the Illinois variant
/// (falsi_crossing) so that it converges. The bracket between the cell's entry, the extrema
/// of g and its exit is the one first_root() finds (first_root_bracket), so the two agree on
/// whether there is a root, and give the same answer exactly where it is decided at a knot (a
/// zero at the entry or exit, a tangent or a triple root whose extremum touches zero) or
/// there is none (NaN coefficients, a zero, negative or NaN length included). They differ
/// only in where inside a crossing's bracket they stop: within 1e-9 of length wherever g' at
/// the root is not tiny; a flatter crossing is where rounding puts it, for either.
///
/// @param g the cubic along the ray (trilinear_cubic), s in [0, length]
/// @param length the parameter's range; a root returned lies in [0, length]
/// @param steps most evaluations of g in the refinement. The default is above what even the
///        flattest crossings took (46), so that the tolerance ends it; fewer trade accuracy
///        for time, as bisect_crossing()'s do
/// @param tolerance relative: |g| at a knot within tolerance * (the sum of |c_i| length^i) is
///        a root, as in first_root(); and the refinement stops at a bracket this fraction of
///        length wide
inline std::optional<double> first_root_falsi(const Cubic& g, double length, int steps = 64, double tolerance = 1e-12) {
  const RootBracket b = first_root_bracket(g, length, tolerance);
  if (b.kind == RootBracket::none) return std::nullopt;
  if (b.kind == RootBracket::at) return b.s;
  return falsi_crossing(g, b.lo, b.hi, b.glo, b.ghi, steps, tolerance * length);
}

/// @brief The last bracket bisect_crossing() narrowed a crossing to: g(a) = ga and g(b) = gb on
/// either side of it (b alone where gb is exactly zero).
struct CrossingBracket {
  double a = 0, b = 0, ga = 0, gb = 0;
};

/// @brief The crossing of a function between two samples that bracket it: g(a) = ga and
/// g(b) = gb differ in sign, or gb is exactly zero (then b is the crossing). `steps` bisections
/// (each one evaluation of g) narrow the bracket; the result is where the secant through its
/// ends crosses zero: on a field smooth inside the last bracket the error falls with the
/// bracket's square rather than its width, for no evaluation more. The marching back ends
/// refine their isosurface hits with it. `last`, if given, receives the last bracket (for
/// crossing_gradient()).
template <typename G>
double bisect_crossing(G&& g, double a, double b, double ga, double gb, int steps, CrossingBracket* last = nullptr) {
  auto result = [&](double t) {
    if (last) *last = {a, b, ga, gb};
    return t;
  };
  if (gb == 0) return result(b);
  for (int it = 0; it < steps; ++it) {
    const double mid = 0.5 * (a + b);
    const double gm = g(mid);
    if ((gm < 0) == (ga < 0)) a = mid, ga = gm;
    else b = mid, gb = gm;
  }
  if (gb == 0) return result(b);
  // ga / (ga - gb) without forming ga - gb, which overflows where the samples are of opposite
  // signs and near the largest float.
  const double w = std::fabs(ga) / (std::fabs(ga) + std::fabs(gb));
  const double t = a + (b - a) * (std::isfinite(w) ? w : 0.5);
  return result(t >= std::min(a, b) && t <= std::max(a, b) ? t : 0.5 * (a + b));  // NaN samples: the midpoint
}

/// @brief The gradient to shade a crossing bisect_crossing() found at t with: gradient_at(t),
/// unless the field there does not change along `dir` the way it does across the crossing
/// (the secant or rounding put t across a kink, on a plateau's side, where the gradient
/// vanishes or belongs to the flat cell: a 0/1 mask at an isovalue just above 0); then the
/// gradient at whichever end of the last bracket does, the far end first. gradient_at returns
/// the gradient per unit of the coordinates `dir` is the ray's direction in.
template <typename GradientAt>
Vec3d crossing_gradient(GradientAt&& gradient_at, double t, const CrossingBracket& bracket, const Vec3d& dir) {
  const double rising = bracket.gb > bracket.ga ? 1.0 : -1.0;
  const Vec3d g = gradient_at(t);
  if (rising * dot(g, dir) > 0 || bracket.a == bracket.b) return g;
  for (double end : {bracket.b, bracket.a}) {
    if (end == t) continue;
    const Vec3d ge = gradient_at(end);
    if (rising * dot(ge, dir) > 0) return ge;
  }
  return g;
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
