#pragma once
/// @file field_bounds.h
/// @brief Bounds on a brick's trilinear field along a ray, from differences of its voxels:
/// how fast the field can change (first order), and how far it can stray from the chord
/// between two of its values (second order). The isosurface search between samples uses them
/// to rule out crossing pairs a step could hide.

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <type_traits>

namespace brickyard::gigavoxels {

/// A brick's differences that bound its trilinear field along a ray: per
/// axis the largest first difference D (bounds the partial derivative), second difference S
/// (bounds the jump of that derivative across a cell face), and per pair of axes the largest
/// mixed difference C (bounds the mixed second derivative inside a cell; the pure ones are 0).
struct BrickDifferences {
  float first[3], second[3], mixed[3];  // mixed: xy, xz, yz
};

/// The largest |sum_k w_k v[p + o_k]| over the positions p of an e^3 brick where every tap lies
/// inside it. Row by row into independent lanes (a max reduction in floats does not vectorise;
/// in integers, for 8- and 16-bit voxels, it does): 5 to 8 times faster than a test per voxel,
/// which mattered for the loader of produced bricks.
struct Tap {
  int dx, dy, dz, w;
};
template <typename Voxel, size_t K>
float stencil_max(const Voxel* v, size_t e, const std::array<Tap, K>& taps) {
  constexpr bool small_integers = std::is_integral_v<Voxel> && sizeof(Voxel) <= 2;
  using Acc = std::conditional_t<small_integers, int, float>;
  size_t ex = 0, ey = 0, ez = 0;
  std::array<size_t, K> offset;
  for (size_t k = 0; k < K; ++k) {
    ex = std::max(ex, size_t(taps[k].dx)), ey = std::max(ey, size_t(taps[k].dy)), ez = std::max(ez, size_t(taps[k].dz));
    offset[k] = (size_t(taps[k].dz) * e + size_t(taps[k].dy)) * e + size_t(taps[k].dx);
  }
  Acc lanes[4] = {};
  const size_t n = e - ex;
  for (size_t z = 0; z + ez < e; ++z)
    for (size_t y = 0; y + ey < e; ++y) {
      const Voxel* row = v + (z * e + y) * e;
      const auto at = [&](size_t x) {
        Acc d = 0;
        for (size_t k = 0; k < K; ++k) d += Acc(taps[k].w) * Acc(row[x + offset[k]]);
        return d < 0 ? -d : d;
      };
      size_t x = 0;
      for (; x + 4 <= n; x += 4)
        for (size_t l = 0; l < 4; ++l) lanes[l] = std::max(lanes[l], at(x + l));
      for (; x < n; ++x) lanes[0] = std::max(lanes[0], at(x));
    }
  return float(std::max(std::max(lanes[0], lanes[1]), std::max(lanes[2], lanes[3])));
}

template <typename Voxel>
BrickDifferences brick_differences(const Voxel* v, size_t e) {
  BrickDifferences d;
  const int u[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  for (int a = 0; a < 3; ++a) {
    const int* o = u[a];
    d.first[a] = stencil_max(v, e, std::array<Tap, 2>{{{o[0], o[1], o[2], 1}, {0, 0, 0, -1}}});
    d.second[a] = stencil_max(v, e, std::array<Tap, 3>{{{0, 0, 0, 1}, {o[0], o[1], o[2], -2}, {2 * o[0], 2 * o[1], 2 * o[2], 1}}});
  }
  const int pairs[3][2] = {{0, 1}, {0, 2}, {1, 2}};
  for (int p = 0; p < 3; ++p) {
    const int* i = u[pairs[p][0]];
    const int* j = u[pairs[p][1]];
    d.mixed[p] = stencil_max(v, e, std::array<Tap, 4>{{{i[0] + j[0], i[1] + j[1], i[2] + j[2], 1},
                                                      {i[0], i[1], i[2], -1},
                                                      {j[0], j[1], j[2], -1},
                                                      {0, 0, 0, 1}}});
  }
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
