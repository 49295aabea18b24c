// Procedural brick producers of the `gigavoxels` back end: the instanced Menger sponge and
// Perlin-noise amplification of a coarse volume.

#include "renderers/gigavoxels/procedural.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <string>
#include <utility>

#include <fmt/format.h>

#include "core/error.h"
#include "fields/random.h"

namespace brickyard::gigavoxels {
namespace {

Error bad_parameter(std::string_view field, const std::string& message) {
  return std::move(Error(Errc::invalid_argument, message).with_field(field));
}

/// The number of nodes per axis at a depth: N^depth.
int64_t nodes_per_axis(int arity, int depth) {
  int64_t n = 1;
  for (int d = 0; d < depth; ++d) n *= arity;
  return n;
}

void check_address(const NodeAddress& node, int arity, int max_depth) {
  BY_CHECK(node.depth >= 0 && node.depth <= max_depth);
  const int64_t n = nodes_per_axis(arity, node.depth);
  BY_CHECK(node.x >= 0 && node.x < n && node.y >= 0 && node.y < n && node.z >= 0 && node.z < n);
}

/// The `menger` field's digit rule (fields/fractal_fields.cpp, Menger::eval): removed when two
/// or more of the base-3 digits at the same position are 1, over the `levels` lowest digits.
bool menger_removed(int64_t x, int64_t y, int64_t z, int levels) {
  for (int l = 0; l < levels; ++l) {
    if (int(x % 3 == 1) + int(y % 3 == 1) + int(z % 3 == 1) >= 2) return true;
    x /= 3; y /= 3; z /= 3;
  }
  return false;
}

/// Float nearest to v that is not above (below) it: float bounds of a double bound.
float float_below(double v) {
  float f = static_cast<float>(v);
  if (double(f) > v) f = std::nextafter(f, -std::numeric_limits<float>::infinity());
  return f;
}
float float_above(double v) {
  float f = static_cast<float>(v);
  if (double(f) < v) f = std::nextafter(f, std::numeric_limits<float>::infinity());
  return f;
}

}  // namespace

// --- Menger sponge ---------------------------------------------------------------------

MengerProducer::MengerProducer(int brick_size) : M_(brick_size) {
  if (M_ != 3 && M_ != 9 && M_ != 27 && M_ != 81)
    throw bad_parameter("brick_size", fmt::format("the Menger producer's brick_size must be 3, 9, 27 or 81 "
                                                  "(a power of 3, so voxels are sponge cells), not {}", M_));
  int levels = 0;  // M = 3^levels
  for (int m = 1; m < M_; m *= 3) ++levels;
  const int E = M_ + 2;
  brick_.resize(size_t(E) * size_t(E) * size_t(E));
  // The border clamps to the edge voxel. A non-empty neighbour holds this same brick, and
  // the sponge's cells are symmetric under the mirror t -> 1 - t along each axis (it swaps
  // digits 0 and 2 and keeps 1s), so the neighbour's first voxel across a face (edge,
  // corner) equals our own last voxel there: the border is exactly the neighbour's data.
  auto cell = [&](int i) { return std::clamp(i - 1, 0, M_ - 1); };
  for (int k = 0; k < E; ++k)
    for (int j = 0; j < E; ++j)
      for (int i = 0; i < E; ++i)
        brick_[(size_t(k) * size_t(E) + size_t(j)) * size_t(E) + size_t(i)] =
            menger_removed(cell(i), cell(j), cell(k), levels) ? 0.0f : 1.0f;
}

NodeContent MengerProducer::classify(const NodeAddress& node) const {
  check_address(node, 3, kMaxDepth);
  if (menger_removed(node.x, node.y, node.z, node.depth)) return {NodeContent::constant, 0.0f, 0.0f, 0.0f};
  return {NodeContent::brick, 0.0f, 0.0f, 1.0f};  // every brick (M >= 3) holds both 0 and 1
}

void MengerProducer::produce(const NodeAddress& node, float* out) const {
  check_address(node, 3, kMaxDepth);
  std::copy(brick_.begin(), brick_.end(), out);
}

uint64_t MengerProducer::brick_id(const NodeAddress&) const { return kSharedBrickId; }

// --- Noise amplification ---------------------------------------------------------------

AmplifiedProducer::AmplifiedProducer(CoarseSampler coarse, const AmplifiedParams& p)
    : coarse_(std::move(coarse)),
      M_(p.brick_size),
      stored_depth_(p.stored_depth),
      max_depth_(p.max_depth),
      lo_(p.lo),
      hi_(p.hi),
      noise_(p.seed) {
  if (!coarse_) throw bad_parameter("coarse", "the amplified producer needs a coarse sampler");
  if (M_ < 2 || M_ > 256)
    throw bad_parameter("brick_size", fmt::format("brick_size must be in [2, 256], not {}", M_));
  if (stored_depth_ < 0 || stored_depth_ > kMaxStoredDepth)
    throw bad_parameter("stored_depth",
                        fmt::format("stored_depth must be in [0, {}], not {}", kMaxStoredDepth, stored_depth_));
  if (max_depth_ == -1) max_depth_ = stored_depth_ + 3;
  if (max_depth_ < stored_depth_ || max_depth_ > stored_depth_ + kMaxAmplification)
    throw bad_parameter("max_depth", fmt::format("max_depth must be in [stored_depth, stored_depth + {}] = [{}, {}] "
                                                 "(or -1 for stored_depth + 3), not {}",
                                                 kMaxAmplification, stored_depth_, stored_depth_ + kMaxAmplification,
                                                 p.max_depth));
  if (!std::isfinite(p.amplitude))
    throw bad_parameter("amplitude", fmt::format("amplitude must be finite, not {}", p.amplitude));
  if (!std::isfinite(p.gain) || p.gain < 0)
    throw bad_parameter("gain", fmt::format("gain must be finite and non-negative, not {}", p.gain));
  if (!std::isfinite(p.lo) || !std::isfinite(p.hi) || p.lo > p.hi)
    throw bad_parameter("lo", fmt::format("the coarse bound [lo, hi] must be finite with lo <= hi, not [{}, {}]",
                                          p.lo, p.hi));

  const int octaves = max_depth_ - stored_depth_;
  SplitMix64 rng(~p.seed);  // as the fbm field: the permutation uses seed, the offsets ~seed
  double a = p.amplitude, sum = 0.0;
  detail_bound_.assign(size_t(max_depth_) + 1, 0.0);
  for (int o = 0; o < octaves; ++o) {
    scale_.push_back(a / kGradientNoiseBound);
    for (int axis = 0; axis < 3; ++axis) offset_.push_back(rng.uniform(0, 256));
    sum += std::abs(a);
    detail_bound_[size_t(stored_depth_ + 1 + o)] = sum;
    a *= p.gain;
  }
  if (!std::isfinite(sum))
    throw bad_parameter("amplitude", fmt::format("the detail's bound, amplitude {} times the sum of gain {} to the "
                                                 "powers 0 to {}, overflows",
                                                 p.amplitude, p.gain, octaves - 1));
}

NodeContent AmplifiedProducer::classify(const NodeAddress& node) const {
  check_address(node, 2, max_depth_);
  const double s = detail_bound_[size_t(node.depth)];
  if (s == 0.0 && lo_ == hi_) {
    const float v = static_cast<float>(lo_);
    return {NodeContent::constant, v, v, v};
  }
  return {NodeContent::brick, 0.0f, float_below(lo_ - s), float_above(hi_ + s)};
}

namespace {

/// Twice a voxel centre's position in voxels of the node's depth: 2 (c M + i) - 1, exact, and
/// the same for two bricks that see the same voxel (one as border, one as interior).
int64_t half_voxel(int64_t c, int M, int i) { return 2 * (c * M + i) - 1; }

/// The unit coordinate the coarse sampler gets, clamped to the cube (border voxels of edge
/// bricks lie half a voxel outside).
double coarse_coordinate(int64_t half, int M, int depth) {
  return std::clamp(std::ldexp(double(half) / double(2 * M), -depth), 0.0, 1.0);
}

/// Octave o's lattice coordinate of a voxel of depth d: half / 2^(d - o + 3) (p M 2^o / 4 with
/// p = half / (2 M 2^d)), reduced modulo the noise's period 256 in integers (so it is exact
/// at any depth), plus the octave's offset.
double lattice_coordinate(int64_t half, int depth, int octave_depth, double offset) {
  const int shift = depth - octave_depth + 3;
  const int64_t period = int64_t(256) << shift;
  const int64_t reduced = half & (period - 1);  // a non-negative remainder, also for half = -1
  return std::ldexp(double(reduced), -shift) + offset;
}

/// One axis of one octave at one voxel index: the noise's per-axis inputs.
struct AxisSample {
  int cell;       ///< lattice cell, in [0, 255]
  double t, f;    ///< offset in the cell and its fade
};

AxisSample axis_sample(double lattice) {
  const double fl = std::floor(lattice);
  const double t = lattice - fl;
  return {static_cast<int>(static_cast<int64_t>(fl) & 255), t, GradientNoise::fade(t)};
}

}  // namespace

double AmplifiedProducer::detail_at(const NodeAddress& node, int i, int j, int k) const {
  check_address(node, 2, max_depth_);
  const int64_t hx = half_voxel(node.x, M_, i), hy = half_voxel(node.y, M_, j), hz = half_voxel(node.z, M_, k);
  double sum = 0.0;
  for (int o = stored_depth_ + 1; o <= node.depth; ++o) {
    const size_t q = size_t(o - stored_depth_ - 1);
    sum += scale_[q] * noise_(lattice_coordinate(hx, node.depth, o, offset_[3 * q]),
                              lattice_coordinate(hy, node.depth, o, offset_[3 * q + 1]),
                              lattice_coordinate(hz, node.depth, o, offset_[3 * q + 2]));
  }
  return sum;
}

namespace {

/// One octave's noise along an x row of a lattice cell, y and z fixed, as a function of x:
///   noise = (a x + b) + u (c x + d),  u = fade(x),
/// which is operator()'s trilinear blend with its y and z weights and the 8 corners' y and z
/// terms gathered (equal up to rounding): 3 multiply-adds per voxel instead of a full noise.
struct RowCell {
  double a, b, c, d;
};

RowCell row_cell(const GradientNoise& noise, int X, const AxisSample& y, const AxisSample& z) {
  RowCell r{0, 0, 0, 0};
  for (int corner = 0; corner < 4; ++corner) {  // (dy, dz) of the corner pair along x
    const int dy = corner & 1, dz = corner >> 1;
    const double weight = (dy ? y.f : 1 - y.f) * (dz ? z.f : 1 - z.f);
    const int8_t* g0 = noise.gradient(X, y.cell + dy, z.cell + dz);
    const int8_t* g1 = noise.gradient(X + 1, y.cell + dy, z.cell + dz);
    // Corner terms g.(x - dx, y - dy, z - dz) = g.x x + e, with e the y and z part.
    const double e0 = g0[1] * (y.t - dy) + g0[2] * (z.t - dz), e1 = g1[1] * (y.t - dy) + g1[2] * (z.t - dz);
    r.a += weight * g0[0];
    r.b += weight * e0;
    r.c += weight * (g1[0] - g0[0]);
    r.d += weight * (e1 - g1[0] - e0);
  }
  return r;
}

}  // namespace

void AmplifiedProducer::produce(const NodeAddress& node, float* out) const {
  check_address(node, 2, max_depth_);
  const int E = M_ + 2, d = node.depth;
  const int octaves = std::max(0, d - stored_depth_);
  // Step 1: per axis, the coarse coordinates and each octave's noise inputs, so the voxel
  // loops below only blend (one allocation per brick).
  std::vector<double> unit(3 * size_t(E)), row(static_cast<size_t>(E));
  std::vector<AxisSample> lattice(3 * size_t(octaves) * size_t(E));
  const std::array<int64_t, 3> c = {node.x, node.y, node.z};
  for (int axis = 0; axis < 3; ++axis)
    for (int i = 0; i < E; ++i) {
      const int64_t half = half_voxel(c[size_t(axis)], M_, i);
      unit[size_t(axis * E + i)] = coarse_coordinate(half, M_, d);
      for (int q = 0; q < octaves; ++q)
        lattice[(size_t(q) * 3 + size_t(axis)) * size_t(E) + size_t(i)] =
            axis_sample(lattice_coordinate(half, d, stored_depth_ + 1 + q, offset_[3 * size_t(q) + size_t(axis)]));
    }
  // Step 2: per x row, the coarse values, then each octave, summed in double, stored once.
  // A row's lattice cells along x change every 4 2^(d - o) voxels; their blend coefficients
  // are computed once per cell.
  float* dst = out;
  for (int k = 0; k < E; ++k)
    for (int j = 0; j < E; ++j, dst += E) {
      for (int i = 0; i < E; ++i) row[size_t(i)] = coarse_(unit[size_t(i)], unit[size_t(E + j)], unit[size_t(2 * E + k)]);
      for (int q = 0; q < octaves; ++q) {
        const AxisSample* xs = &lattice[size_t(q) * 3 * size_t(E)];
        const AxisSample &ys = xs[E + j], &zs = xs[2 * E + k];
        const double scale = scale_[size_t(q)];
        int cell = -1;
        RowCell rc{};
        for (int i = 0; i < E; ++i) {
          const AxisSample& x = xs[i];
          if (x.cell != cell) rc = row_cell(noise_, cell = x.cell, ys, zs);
          row[size_t(i)] += scale * ((rc.a * x.t + rc.b) + x.f * (rc.c * x.t + rc.d));
        }
      }
      for (int i = 0; i < E; ++i) dst[i] = static_cast<float>(row[size_t(i)]);
    }
}

uint64_t AmplifiedProducer::brick_id(const NodeAddress& node) const {
  check_address(node, 2, max_depth_);
  const auto x = uint64_t(node.x), y = uint64_t(node.y), z = uint64_t(node.z);
  if (node.depth <= 20) {
    // Exact: the nodes of shallower depths come first ((8^d - 1) / 7 of them), then this
    // depth's Morton code (3 d <= 60 bits).
    uint64_t morton = 0;
    for (int b = 0; b < node.depth; ++b)
      morton |= (((x >> b) & 1) << (3 * b)) | (((y >> b) & 1) << (3 * b + 1)) | (((z >> b) & 1) << (3 * b + 2));
    return ((uint64_t(1) << (3 * node.depth)) - 1) / 7 + morton;
  }
  // Deeper: a mix of all 3 * 40 + 6 bits into 63, tagged with the top bit, which the exact
  // ids (below 2^61) never have.
  SplitMix64 mix(uint64_t(node.depth) * 0x9e3779b97f4a7c15ull ^ x);
  uint64_t h = mix.next();
  mix = SplitMix64(h ^ y);
  h = mix.next();
  mix = SplitMix64(h ^ z);
  return mix.next() | (uint64_t(1) << 63);
}

}  // namespace brickyard::gigavoxels
