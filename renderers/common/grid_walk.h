#pragma once
/// @file grid_walk.h
/// @brief 3D DDA (Amanatides and Woo) over a regular grid of unit cells: the cells of a level,
/// or, scaled by the brick size, its bricks.

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

#include "core/math.h"

namespace brickyard {

/// Visits the cells of a grid of n cells per axis that the ray o + t d crosses for t in
/// [t0, t1], in order: visit(cell, ta, tb) returns false to stop. Exact in the sense that
/// each boundary crossing is recomputed from the origin, not accumulated.
template <typename Visit>
void walk_cells(const Vec3d& o, const Vec3d& d, double t0, double t1, const Vec3s& n, Visit&& visit) {
  if (!(t0 <= t1)) return;
  const Vec3d p = o + d * t0;
  int64_t cell[3];
  int step[3];
  double next[3];
  for (int a = 0; a < 3; ++a) {
    cell[a] = std::clamp<int64_t>(int64_t(std::floor(p[a])), 0, n[a] - 1);
    step[a] = d[a] > 0 ? 1 : (d[a] < 0 ? -1 : 0);
    next[a] = step[a] > 0 ? (double(cell[a] + 1) - o[a]) / d[a] : step[a] < 0 ? (double(cell[a]) - o[a]) / d[a] : std::numeric_limits<double>::infinity();
  }
  double ta = t0;
  for (int64_t guard = n.x + n.y + n.z + 8; guard > 0; --guard) {
    int axis = next[0] <= next[1] ? (next[0] <= next[2] ? 0 : 2) : (next[1] <= next[2] ? 1 : 2);
    const double tb = std::max(ta, std::min(next[axis], t1));
    if (!visit(cell, ta, tb) || tb >= t1) return;
    cell[axis] += step[axis];
    if (cell[axis] < 0 || cell[axis] >= n[axis]) return;
    next[axis] = step[axis] > 0 ? (double(cell[axis] + 1) - o[axis]) / d[axis] : (double(cell[axis]) - o[axis]) / d[axis];
    ta = tb;
  }
}

}  // namespace brickyard
