#pragma once
/// @file tet_geometry.h
/// @brief A tet of a cluster page in double, as the tetrahedral back ends and the reference
/// see it: its linear field and gradient, and the closed interval a ray spends in it, computed
/// so that two tets sharing a face agree on it to the last bit (each face plane from its three
/// vertices in one canonical order, position_less()).

#include <algorithm>
#include <cstdint>

#include "core/math.h"
#include "dataset/tet.h"

namespace brickyard {

/// @brief The canonical order of points shared by neighbouring tets (lexicographic in x, y,
/// z): whatever two tets compute from the same points taken in this order agrees to the bit.
inline bool position_less(const Vec3d& u, const Vec3d& v) {
  return u.x < v.x || (u.x == v.x && (u.y < v.y || (u.y == v.y && u.z < v.z)));
}

/// @brief A tet in double: its corners and their values.
struct TetGeometry {
  Vec3d p[4];
  double f[4];

  /// Tet t of a cluster page, at time step `step`.
  TetGeometry(const TetClusterPage& page, uint32_t t, uint32_t step) {
    const uint32_t* q = page.corners + 4 * size_t(t);
    const float* pos = page.positions_at(step);
    const float* val = page.values_at(step);
    for (int i = 0; i < 4; ++i) {
      p[i] = Vec3d(pos[3 * q[i]], pos[3 * q[i] + 1], pos[3 * q[i] + 2]);
      f[i] = val[q[i]];
    }
  }
  TetGeometry(const Vec3d (&points)[4], const double (&values)[4]) {
    for (int i = 0; i < 4; ++i) p[i] = points[i], f[i] = values[i];
  }
  /// The gradient of the tet's linear field (computed on each call: most tets a ray's box
  /// test finds, it misses).
  Vec3d gradient() const {
    // Solve [b-a; c-a; d-a] g = (fb-fa, fc-fa, fd-fa) by Cramer's rule.
    const Vec3d e1 = p[1] - p[0], e2 = p[2] - p[0], e3 = p[3] - p[0];
    const double det = dot(e1, cross(e2, e3));
    const Vec3d df(f[1] - f[0], f[2] - f[0], f[3] - f[0]);
    const Vec3d c23 = cross(e2, e3), c31 = cross(e3, e1), c12 = cross(e1, e2);
    return (c23 * df.x + c31 * df.y + c12 * df.z) / det;
  }
  double value_at(const Vec3d& x, const Vec3d& gradient) const { return f[0] + dot(gradient, x - p[0]); }
  double size() const { return std::max({length(p[1] - p[0]), length(p[2] - p[0]), length(p[3] - p[0])}); }

  /// The closed interval [t_in, t_out] of o + t d inside the tet, clipped to [t0, t1]; empty
  /// when t_in > t_out.
  Interval<double> span(const Vec3d& o, const Vec3d& d, double t0, double t1) const {
    static constexpr int kFaces[4][3] = {{1, 2, 3}, {0, 2, 3}, {0, 1, 3}, {0, 1, 2}};  // face i lies opposite vertex i
    double a = t0, b = t1;
    for (int i = 0; i < 4; ++i) {
      Vec3d q[3] = {p[kFaces[i][0]], p[kFaces[i][1]], p[kFaces[i][2]]};
      // Canonical order: the neighbour across this face computes the identical plane.
      if (position_less(q[1], q[0])) std::swap(q[0], q[1]);
      if (position_less(q[2], q[1])) std::swap(q[1], q[2]);
      if (position_less(q[1], q[0])) std::swap(q[0], q[1]);
      const Vec3d n = cross(q[1] - q[0], q[2] - q[0]);
      const double outward = dot(n, p[i] - q[0]) > 0 ? -1.0 : 1.0;
      const double num = dot(n, q[0] - o), den = dot(n, d);
      if (den == 0) {
        if (outward * -num > 0) return {1, 0};  // parallel and outside
        continue;
      }
      const double t = num / den;
      if (outward * den < 0) a = std::max(a, t);
      else b = std::min(b, t);
    }
    return {a, b};
  }
};

}  // namespace brickyard
