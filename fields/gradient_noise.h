#pragma once
/// @file gradient_noise.h
/// @brief Perlin's improved gradient noise (2002), shared by the `fbm` field and the
/// `gigavoxels` amplified bricks. Immutable after construction: safe from many threads.

#include <array>
#include <cmath>
#include <cstdint>
#include <utility>

#include "fields/random.h"

namespace brickyard {

/// @brief A bound of |GradientNoise| for every seed. Noise is a blend, with fade weights that
/// are non-negative and sum to 1, of the 8 corner terms g.d (g a cube-edge gradient, d the
/// offset from the corner), and |g.d| is at most the sum of the two largest |d| components.
/// The largest value of that weighted sum over the unit cell, with every corner choosing its
/// worst gradient, is 1.036354 (at about (0.3553, 0.4815, 0.5), found by a dense search and
/// local refinement; the test ProceduralNoise.StaysWithinItsBound re-checks both the envelope and
/// the noise). Divide by this to get noise bounded by 1.
inline constexpr double kGradientNoiseBound = 1.0364;

/// @brief Perlin's improved gradient noise (2002): quintic fade, gradients along the 12 cube edge
/// directions chosen by a seeded permutation. Zero at lattice points, in
/// [-kGradientNoiseBound, kGradientNoiseBound], periodic with period 256 along each axis.
class GradientNoise {
 public:
  explicit GradientNoise(uint64_t seed) {
    std::array<uint8_t, 256> p{};
    for (int i = 0; i < 256; ++i) p[size_t(i)] = static_cast<uint8_t>(i);
    SplitMix64 rng(seed);
    for (int i = 255; i > 0; --i) std::swap(p[size_t(i)], p[size_t(rng.next() % uint64_t(i + 1))]);
    for (int i = 0; i < 512; ++i) perm_[size_t(i)] = p[size_t(i & 255)];
  }

  double operator()(double x, double y, double z) const {
    const double fx = std::floor(x), fy = std::floor(y), fz = std::floor(z);
    const int X = static_cast<int>(static_cast<int64_t>(fx) & 255);
    const int Y = static_cast<int>(static_cast<int64_t>(fy) & 255);
    const int Z = static_cast<int>(static_cast<int64_t>(fz) & 255);
    x -= fx; y -= fy; z -= fz;
    const double u = fade(x), v = fade(y), w = fade(z);
    const int A = perm_[size_t(X)] + Y, AA = perm_[size_t(A)] + Z, AB = perm_[size_t(A + 1)] + Z;
    const int B = perm_[size_t(X + 1)] + Y, BA = perm_[size_t(B)] + Z, BB = perm_[size_t(B + 1)] + Z;
    const double x1 = x - 1, y1 = y - 1, z1 = z - 1;
    return lerp(w,
                lerp(v, lerp(u, grad(perm_[size_t(AA)], x, y, z), grad(perm_[size_t(BA)], x1, y, z)),
                     lerp(u, grad(perm_[size_t(AB)], x, y1, z), grad(perm_[size_t(BB)], x1, y1, z))),
                lerp(v, lerp(u, grad(perm_[size_t(AA + 1)], x, y, z1), grad(perm_[size_t(BA + 1)], x1, y, z1)),
                     lerp(u, grad(perm_[size_t(AB + 1)], x, y1, z1), grad(perm_[size_t(BB + 1)], x1, y1, z1))));
  }

  /// @brief The gradient operator() uses at lattice point (X, Y, Z), each in [0, 256] (the
  /// corners of cell (X, Y, Z), X in [0, 255]): for callers that evaluate many points of one
  /// cell and factor the blend themselves.
  const int8_t* gradient(int X, int Y, int Z) const {
    return kGradients[perm_[size_t(perm_[size_t(perm_[size_t(X)] + Y)] + Z)] & 15];
  }

  /// @brief Perlin's quintic fade 6t^5 - 15t^4 + 10t^3.
  static double fade(double t) { return t * t * t * (t * (t * 6 - 15) + 10); }

 private:
  // The 12 cube-edge gradients of improved noise, indexed by the low 4 hash bits (4 of them
  // repeated). A table lookup instead of Perlin's bit tests: no unpredictable branches.
  static constexpr int8_t kGradients[16][3] = {{1, 1, 0},  {-1, 1, 0}, {1, -1, 0}, {-1, -1, 0}, {1, 0, 1},  {-1, 0, 1},
                                               {1, 0, -1}, {-1, 0, -1}, {0, 1, 1}, {0, -1, 1},  {0, 1, -1}, {0, -1, -1},
                                               {1, 1, 0},  {1, -1, 0}, {-1, 1, 0}, {0, -1, -1}};
  static double lerp(double t, double a, double b) { return a + t * (b - a); }
  static double grad(int hash, double x, double y, double z) {
    const int8_t* v = kGradients[hash & 15];
    return v[0] * x + v[1] * y + v[2] * z;
  }

  std::array<int, 512> perm_{};
};

}  // namespace brickyard
