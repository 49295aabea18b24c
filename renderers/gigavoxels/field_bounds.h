#pragma once
/// @file field_bounds.h
/// @brief Bounds on a brick's trilinear field along a ray, from differences of its voxels:
/// how fast the field can change (first order), and how far it can stray from the chord
/// between two of its values (second order). The isosurface search between samples uses them
/// to rule out crossing pairs a step could hide.

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <type_traits>

namespace brickyard::gigavoxels {

/// A brick's differences that bound its trilinear field along a ray: per axis the largest
/// first difference D (bounds the partial derivative), second difference S (bounds the jump of
/// that derivative across a cell face), and per pair of axes the largest mixed difference C
/// (bounds the mixed second derivative inside a cell; the pure ones are 0).
struct BrickDifferences {
  float first[3], second[3], mixed[3];  // mixed: xy, xz, yz
};

/// An e^3 brick's differences (e >= 3), row by row: each a plain loop over x into independent
/// lanes, which the compiler vectorises for 8- and 16-bit voxels (in integers) and pipelines
/// for floats (a max reduction in floats does not vectorise).
template <typename Voxel>
BrickDifferences brick_differences(const Voxel* v, size_t e) {
  constexpr bool small_integers = std::is_integral_v<Voxel> && sizeof(Voxel) <= 2;
  using Acc = std::conditional_t<small_integers, int, float>;
  Acc m[9][4] = {};  // first x y z, second x y z, mixed xy xz yz; 4 lanes each
  const auto take = [](Acc* lanes, size_t n, const auto& diff) {
    const auto abs = [](Acc d) { return d < 0 ? -d : d; };
    size_t x = 0;
    for (; x + 4 <= n; x += 4)
      for (size_t l = 0; l < 4; ++l) lanes[l] = std::max(lanes[l], abs(diff(x + l)));
    for (; x < n; ++x) lanes[0] = std::max(lanes[0], abs(diff(x)));
  };
  const size_t plane = e * e;
  for (size_t z = 0; z < e; ++z)
    for (size_t y = 0; y < e; ++y) {
      const Voxel* r = v + z * plane + y * e;
      const bool y1 = y + 1 < e, y2 = y + 2 < e, z1 = z + 1 < e, z2 = z + 2 < e;
      const Voxel* ry = r + e;
      const Voxel* rz = r + plane;
      take(m[0], e - 1, [&](size_t x) { return Acc(r[x + 1]) - Acc(r[x]); });
      take(m[3], e - 2, [&](size_t x) { return Acc(r[x + 2]) - 2 * Acc(r[x + 1]) + Acc(r[x]); });
      if (y1) {
        take(m[1], e, [&](size_t x) { return Acc(ry[x]) - Acc(r[x]); });
        take(m[6], e - 1, [&](size_t x) { return Acc(ry[x + 1]) - Acc(ry[x]) - Acc(r[x + 1]) + Acc(r[x]); });
      }
      if (y2) take(m[4], e, [&](size_t x) { return Acc(r[x + 2 * e]) - 2 * Acc(ry[x]) + Acc(r[x]); });
      if (z1) {
        take(m[2], e, [&](size_t x) { return Acc(rz[x]) - Acc(r[x]); });
        take(m[7], e - 1, [&](size_t x) { return Acc(rz[x + 1]) - Acc(rz[x]) - Acc(r[x + 1]) + Acc(r[x]); });
      }
      if (z2) take(m[5], e, [&](size_t x) { return Acc(r[x + 2 * plane]) - 2 * Acc(rz[x]) + Acc(r[x]); });
      if (y1 && z1) take(m[8], e, [&](size_t x) { return Acc(rz[x + e]) - Acc(ry[x]) - Acc(rz[x]) + Acc(r[x]); });
    }
  const auto reduce = [](const Acc* l) { return float(std::max(std::max(l[0], l[1]), std::max(l[2], l[3]))); };
  BrickDifferences d;
  for (int a = 0; a < 3; ++a) d.first[a] = reduce(m[a]), d.second[a] = reduce(m[3 + a]), d.mixed[a] = reduce(m[6 + a]);
  return d;
}

/// What a brick's differences say about its field f along a ray that moves w[a] voxels per
/// unit t along each axis: |f'| <= slope; over dt, f' varies by at most curve * dt + kink (the
/// mixed second derivatives inside the cells, and the jumps of f' at the cell faces the ray
/// crosses, at most |w[a]| dt + 1 of them per axis, each at most |w[a]| second[a]); so f strays
/// from its chord over dt by at most dt / 4 times that variation.
struct FieldBounds {
  double slope = 0, curve = 0, kink = 0;
  double stray(double dt) const { return 0.25 * dt * (curve * dt + kink); }
};

inline FieldBounds field_bounds(const BrickDifferences& d, const double w[3]) {
  const double u[3] = {std::abs(w[0]), std::abs(w[1]), std::abs(w[2])};
  FieldBounds f;
  for (int a = 0; a < 3; ++a) {
    f.slope += u[a] * double(d.first[a]);
    f.curve += u[a] * u[a] * double(d.second[a]);
    f.kink += u[a] * double(d.second[a]);
  }
  f.curve += 2 * (u[0] * u[1] * double(d.mixed[0]) + u[0] * u[2] * double(d.mixed[1]) + u[1] * u[2] * double(d.mixed[2]));
  return f;
}

}  // namespace brickyard::gigavoxels
