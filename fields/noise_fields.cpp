// Fractal Brownian motion over gradient noise.

#include <algorithm>
#include <array>
#include <cmath>

#include "core/error.h"
#include "fields/field_types.h"
#include "fields/random.h"

namespace brickyard {
namespace {

/// Perlin's improved gradient noise (2002): quintic fade, gradients along the 12 cube edge
/// directions chosen by a seeded permutation. Zero at lattice points, roughly in [-1, 1].
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

 private:
  static double fade(double t) { return t * t * t * (t * (t * 6 - 15) + 10); }
  static double lerp(double t, double a, double b) { return a + t * (b - a); }
  // The 12 cube-edge gradients of improved noise, indexed by the low 4 hash bits (4 of them
  // repeated). A table lookup instead of Perlin's bit tests: no unpredictable branches.
  static double grad(int hash, double x, double y, double z) {
    static constexpr int8_t g[16][3] = {{1, 1, 0},  {-1, 1, 0}, {1, -1, 0}, {-1, -1, 0}, {1, 0, 1},  {-1, 0, 1},
                                        {1, 0, -1}, {-1, 0, -1}, {0, 1, 1}, {0, -1, 1},  {0, 1, -1}, {0, -1, -1},
                                        {1, 1, 0},  {1, -1, 0}, {-1, 1, 0}, {0, -1, -1}};
    const int8_t* v = g[hash & 15];
    return v[0] * x + v[1] * y + v[2] * z;
  }

  std::array<int, 512> perm_{};
};

/// fBm: sum over octaves o of gain^o * noise(frequency * lacunarity^o * p + offset_o),
/// normalised by the sum of the amplitudes and clamped to [-1, 1] (a bound the normalised sum
/// practically never reaches; the clamp makes range() a guarantee).
class Fbm final : public FieldBase<Fbm> {
 public:
  explicit Fbm(FieldParamReader& p)
      : seed_(static_cast<uint64_t>(p.get_int("seed", 1, 0, int64_t(1) << 52, "noise seed"))),
        noise_(seed_),
        octaves_(static_cast<int>(p.get_int("octaves", 6, 1, 16, "number of octaves"))),
        frequency_(p.get("frequency", 4.0, "lattice cells across the unit cube at the first octave")),
        lacunarity_(p.get("lacunarity", 2.0, "frequency ratio between octaves")),
        gain_(p.get("gain", 0.5, "amplitude ratio between octaves")) {
    if (frequency_ <= 0 || lacunarity_ <= 0 || gain_ <= 0)
      throw Error(Errc::invalid_argument, "frequency, lacunarity and gain must be positive").with_field("frequency");
    SplitMix64 rng(~seed_);
    double amplitude = 1.0, sum = 0.0;
    for (int o = 0; o < octaves_; ++o) {
      // Offsets keep the octaves' lattices from aligning (noise is 0 on every lattice point).
      offsets_[size_t(o)] = {rng.uniform(0, 256), rng.uniform(0, 256), rng.uniform(0, 256)};
      sum += amplitude;
      amplitude *= gain_;
    }
    normalisation_ = 1.0 / sum;
    params_ = p.declared();
  }
  std::string_view name() const override { return "fbm"; }
  Box3d domain() const override { return {Vec3d(0.0), Vec3d(1.0)}; }
  ValueRange range() const override { return {-1.0, 1.0}; }

  double eval(const Vec3d& p) const {
    double f = frequency_, amplitude = 1.0, sum = 0.0;
    for (int o = 0; o < octaves_; ++o) {
      const Vec3d& off = offsets_[size_t(o)];
      sum += amplitude * noise_(p.x * f + off.x, p.y * f + off.y, p.z * f + off.z);
      f *= lacunarity_;
      amplitude *= gain_;
    }
    return std::clamp(sum * normalisation_, -1.0, 1.0);
  }

 private:
  uint64_t seed_;
  GradientNoise noise_;
  int octaves_;
  double frequency_, lacunarity_, gain_;
  double normalisation_ = 1.0;
  std::array<Vec3d, 16> offsets_{};
};

}  // namespace

std::unique_ptr<Field> make_fbm(FieldParamReader& p) { return std::make_unique<Fbm>(p); }

}  // namespace brickyard
