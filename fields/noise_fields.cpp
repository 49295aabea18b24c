// Fractal Brownian motion over gradient noise.

#include <algorithm>
#include <array>
#include <cmath>

#include "core/error.h"
#include "fields/field_types.h"
#include "fields/gradient_noise.h"
#include "fields/random.h"

namespace brickyard {
namespace {

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
