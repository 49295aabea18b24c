// The `gigavoxels` procedural brick producers against analytic truth: the Menger producer
// against the `menger` field's point evaluation, closed-form node counts and solid fractions;
// the amplified producer against its coarse sampler, its documented formula evaluated
// directly with GradientNoise, its own classify() bound and its neighbours' bricks.

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <random>
#include <set>
#include <string>
#include <thread>
#include <unordered_set>
#include <vector>

#include "core/error.h"
#include "fields/field.h"
#include "fields/gradient_noise.h"
#include "fields/random.h"
#include "renderers/gigavoxels/procedural.h"

namespace brickyard::gigavoxels {
namespace {

int64_t ipow(int64_t base, int e) {
  int64_t r = 1;
  for (int i = 0; i < e; ++i) r *= base;
  return r;
}

size_t brick_index(int E, int i, int j, int k) { return (size_t(k) * size_t(E) + size_t(j)) * size_t(E) + size_t(i); }

std::vector<float> produce(const BrickProducer& p, const NodeAddress& n) {
  const size_t E = size_t(p.brick_size() + 2);
  std::vector<float> out(E * E * E, std::nanf(""));
  p.produce(n, out.data());
  return out;
}

/// Voxel i's centre along one axis, as the producers' contract states it.
double voxel_centre(int64_t c, int i, int M, int64_t nodes) { return (double(c) + (i - 0.5) / M) / double(nodes); }

std::unique_ptr<Field> menger_field(int levels) { return make_field("menger", {{"levels", double(levels)}}); }

// --- noise bound -------------------------------------------------------------------------

/// The envelope of |noise| over every choice of corner gradients (see gradient_noise.h).
double noise_envelope(double x, double y, double z) {
  const double u = GradientNoise::fade(x), v = GradientNoise::fade(y), w = GradientNoise::fade(z);
  double sum = 0;
  for (int c = 0; c < 8; ++c) {
    double d[3] = {std::abs(x - (c & 1)), std::abs(y - ((c >> 1) & 1)), std::abs(z - ((c >> 2) & 1))};
    std::sort(d, d + 3);
    const double weight = ((c & 1) ? u : 1 - u) * ((c & 2) ? v : 1 - v) * ((c & 4) ? w : 1 - w);
    sum += weight * (d[1] + d[2]);
  }
  return sum;
}

TEST(ProceduralNoise, StaysWithinItsBound) {
  // The envelope's maximum, found by a dense search, is tight: just under the constant.
  EXPECT_GT(noise_envelope(0.355257, 0.481492, 0.5), 1.03635);
  EXPECT_LE(noise_envelope(0.355257, 0.481492, 0.5), kGradientNoiseBound);
  constexpr int n = 80;
  double envelope_max = 0;
  for (int k = 0; k <= n; ++k)
    for (int j = 0; j <= n; ++j)
      for (int i = 0; i <= n; ++i) envelope_max = std::max(envelope_max, noise_envelope(i / double(n), j / double(n), k / double(n)));
  EXPECT_LE(envelope_max, kGradientNoiseBound);
  // And the noise itself, for several seeds, stays within and comes close to it.
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(-300.0, 300.0);
  double noise_max = 0;
  for (uint64_t seed : {1u, 2u, 99u}) {
    GradientNoise noise(seed);
    for (int s = 0; s < 300000; ++s) noise_max = std::max(noise_max, std::abs(noise(u(rng), u(rng), u(rng))));
  }
  EXPECT_LE(noise_max, kGradientNoiseBound);
  EXPECT_GT(noise_max, 0.85);
}

// --- Menger ------------------------------------------------------------------------------

TEST(ProceduralMenger, ClassifiesLikeTheMengerFieldAtNodeCentres) {
  MengerProducer menger;
  std::mt19937_64 rng(11);
  for (int d = 1; d <= 6; ++d) {
    auto field = menger_field(d);
    const int64_t n = ipow(3, d);
    std::uniform_int_distribution<int64_t> coord(0, n - 1);
    int empty = 0;
    for (int s = 0; s < 3000; ++s) {
      const NodeAddress a{d, coord(rng), coord(rng), coord(rng)};
      const double v = field->value({(a.x + 0.5) / double(n), (a.y + 0.5) / double(n), (a.z + 0.5) / double(n)});
      const NodeContent c = menger.classify(a);
      if (v == 0.0) {
        ++empty;
        ASSERT_EQ(c.kind, NodeContent::constant) << "depth " << d << " node " << a.x << "," << a.y << "," << a.z;
        EXPECT_EQ(c.value, 0.0f);
        EXPECT_EQ(c.lo, 0.0f);
        EXPECT_EQ(c.hi, 0.0f);
      } else {
        ASSERT_EQ(c.kind, NodeContent::brick) << "depth " << d << " node " << a.x << "," << a.y << "," << a.z;
        EXPECT_EQ(c.lo, 0.0f);
        EXPECT_EQ(c.hi, 1.0f);
      }
    }
    EXPECT_GT(empty, 0) << "depth " << d;  // both kinds were drawn
  }
}

TEST(ProceduralMenger, EmptyNodeCountIsTwentySevenToTheDMinusTwentyToTheD) {
  MengerProducer menger;
  for (int d = 0; d <= 4; ++d) {
    const int64_t n = ipow(3, d);
    int64_t empty = 0;
    for (int64_t z = 0; z < n; ++z)
      for (int64_t y = 0; y < n; ++y)
        for (int64_t x = 0; x < n; ++x) empty += menger.classify({d, x, y, z}).kind == NodeContent::constant;
    EXPECT_EQ(empty, ipow(27, d) - ipow(20, d)) << "depth " << d;
  }
}

TEST(ProceduralMenger, SharedBrickIsTheBoxFilteredOccupancyAtBrickResolution) {
  for (int M : {3, 9, 27}) {
    MengerProducer menger(M);
    const int levels = int(std::lround(std::log(M) / std::log(3)));
    auto field = menger_field(levels);  // the root node's sponge at brick resolution
    const std::vector<float> brick = produce(menger, {});
    EXPECT_EQ(brick, menger.shared_brick());
    const int E = M + 2;
    constexpr int s = 4;  // s^3 subsamples per voxel, none at its centre
    double sum = 0;
    for (int k = 1; k <= M; ++k)
      for (int j = 1; j <= M; ++j)
        for (int i = 1; i <= M; ++i) {
          double solid = 0;
          for (int c = 0; c < s * s * s; ++c) {
            const double ox = (c % s + 0.5) / s, oy = (c / s % s + 0.5) / s, oz = (c / (s * s) + 0.5) / s;
            solid += field->value({(i - 1 + ox) / M, (j - 1 + oy) / M, (k - 1 + oz) / M});
          }
          const float v = brick[brick_index(E, i, j, k)];
          ASSERT_NEAR(v, solid / (s * s * s), 1e-6) << "M " << M << " voxel " << i << "," << j << "," << k;
          sum += v;
        }
    // The interior mean is the sponge's exact solid fraction at this resolution.
    EXPECT_NEAR(sum / (double(M) * M * M), std::pow(20.0 / 27.0, levels), 1e-9) << "M " << M;
  }
  // 81 is too large to subsample here; its mean still has to come out exactly.
  MengerProducer m81(81);
  double sum = 0;
  for (int k = 1; k <= 81; ++k)
    for (int j = 1; j <= 81; ++j)
      for (int i = 1; i <= 81; ++i) sum += m81.shared_brick()[brick_index(83, i, j, k)];
  EXPECT_NEAR(sum / (81.0 * 81 * 81), std::pow(20.0 / 27.0, 4), 1e-9);
}

TEST(ProceduralMenger, BorderClampsToTheEdgeVoxel) {
  MengerProducer menger(9);
  const std::vector<float>& b = menger.shared_brick();
  const int E = 11;
  auto clamp = [](int i) { return std::clamp(i, 1, 9); };
  for (int k = 0; k < E; ++k)
    for (int j = 0; j < E; ++j)
      for (int i = 0; i < E; ++i)
        ASSERT_EQ(b[brick_index(E, i, j, k)], b[brick_index(E, clamp(i), clamp(j), clamp(k))]) << i << "," << j << "," << k;
}

TEST(ProceduralMenger, BorderEqualsTheNonEmptyNeighboursData) {
  for (int M : {9, 27}) {
    MengerProducer menger(M);
    const int levels = int(std::lround(std::log(M) / std::log(3))), E = M + 2;
    // A 2x2x1 block of non-empty depth-2 nodes, x in {2, 3}, y in {0, 1}: each brick's border
    // across an inner face (and the inner edge) equals the neighbour's first interior voxels,
    // and both equal the field of 2 + log3(M) levels at those voxel centres.
    auto field = menger_field(2 + levels);
    for (int64_t y = 0; y < 2; ++y)
      for (int64_t x = 2; x < 4; ++x) ASSERT_EQ(menger.classify({2, x, y, 0}).kind, NodeContent::brick);
    const std::vector<float> a = produce(menger, {2, 2, 0, 0}), bx = produce(menger, {2, 3, 0, 0}),
                             by = produce(menger, {2, 2, 1, 0}), bxy = produce(menger, {2, 3, 1, 0});
    for (int k = 0; k < E; ++k)
      for (int t = 0; t < E; ++t) {
        EXPECT_EQ(a[brick_index(E, E - 1, t, k)], bx[brick_index(E, 1, t, k)]);
        EXPECT_EQ(bx[brick_index(E, 0, t, k)], a[brick_index(E, M, t, k)]);
        EXPECT_EQ(a[brick_index(E, t, E - 1, k)], by[brick_index(E, t, 1, k)]);
        EXPECT_EQ(by[brick_index(E, t, 0, k)], a[brick_index(E, t, M, k)]);
      }
    for (int k = 0; k < E; ++k) EXPECT_EQ(a[brick_index(E, E - 1, E - 1, k)], bxy[brick_index(E, 1, 1, k)]);

    // Every border voxel of every non-empty node at depths 1 and 2 whose centre lies in a
    // non-empty node equals the field there.
    for (int d = 1; d <= 2; ++d) {
      auto f = menger_field(d + levels);
      const int64_t n = ipow(3, d);
      int checked = 0;
      for (int64_t z = 0; z < n; ++z)
        for (int64_t y = 0; y < n; ++y)
          for (int64_t x = 0; x < n; ++x) {
            if (menger.classify({d, x, y, z}).kind != NodeContent::brick) continue;
            const std::vector<float> b = produce(menger, {d, x, y, z});
            for (int k = 0; k < E; ++k)
              for (int j = 0; j < E; ++j)
                for (int i = 0; i < E; ++i) {
                  if (i != 0 && i != E - 1 && j != 0 && j != E - 1 && k != 0 && k != E - 1) continue;
                  const Vec3d p(voxel_centre(x, i, M, n), voxel_centre(y, j, M, n), voxel_centre(z, k, M, n));
                  if (p.x < 0 || p.y < 0 || p.z < 0 || p.x > 1 || p.y > 1 || p.z > 1) continue;
                  const NodeAddress holder{d, int64_t(p.x * double(n)), int64_t(p.y * double(n)), int64_t(p.z * double(n))};
                  if (menger.classify(holder).kind != NodeContent::brick) continue;
                  ASSERT_EQ(b[brick_index(E, i, j, k)], float(f->value(p)))
                      << "M " << M << " depth " << d << " node " << x << "," << y << "," << z << " voxel " << i << ","
                      << j << "," << k;
                  ++checked;
                }
          }
      EXPECT_GT(checked, 1000);
    }
  }
}

TEST(ProceduralMenger, DeepAddressesClassifyCorrectly) {
  MengerProducer menger;
  EXPECT_EQ(menger.max_depth(), 39);
  for (int d : {30, 35, 39}) {
    const int64_t last = ipow(3, d) - 1;             // digits all 2
    const int64_t ones = last / 2;                   // digits all 1
    const int64_t top = ipow(3, d - 1);              // a single 1, in the coarsest digit
    const int64_t middle = ipow(3, d / 2);           // a single 1, halfway down
    auto kind = [&](int64_t x, int64_t y, int64_t z) { return menger.classify({d, x, y, z}).kind; };
    EXPECT_EQ(kind(0, 0, 0), NodeContent::brick) << d;           // the corner path
    EXPECT_EQ(kind(last, last, last), NodeContent::brick) << d;  // the opposite corner
    EXPECT_EQ(kind(last, 0, last), NodeContent::brick) << d;
    EXPECT_EQ(kind(ones, ones, 0), NodeContent::constant) << d;  // the centre cross
    EXPECT_EQ(kind(ones, 0, 0), NodeContent::brick) << d;        // 1s along one axis only
    EXPECT_EQ(kind(top, top, 0), NodeContent::constant) << d;    // removed at depth 1
    EXPECT_EQ(kind(top, 0, top), NodeContent::constant) << d;
    EXPECT_EQ(kind(top, 1, 0), NodeContent::brick) << d;         // 1s at different depths
    EXPECT_EQ(kind(middle, middle + 2, 2), NodeContent::constant) << d;  // removed halfway down
    EXPECT_EQ(kind(1, 1, last), NodeContent::constant) << d;     // removed only at the finest digit
    EXPECT_EQ(kind(last - 1, last - 1, last), NodeContent::constant) << d;  // ...2221 twice
  }
  EXPECT_THROW(menger.classify({40, 0, 0, 0}), Error);
  EXPECT_THROW(menger.classify({2, 9, 0, 0}), Error);
  EXPECT_THROW(menger.classify({2, 0, -1, 0}), Error);
}

TEST(ProceduralMenger, EveryNodeSharesOneBrick) {
  MengerProducer menger(9);
  const std::vector<float> root = produce(menger, {});
  for (const NodeAddress& a : {NodeAddress{1, 0, 2, 2}, NodeAddress{3, 20, 0, 7}, NodeAddress{39, 5, 6, 7}}) {
    EXPECT_EQ(menger.brick_id(a), menger.brick_id({}));
    EXPECT_EQ(produce(menger, a), root);
  }
  EXPECT_EQ(menger.arity(), 3);
  EXPECT_EQ(menger.brick_size(), 9);
}

TEST(ProceduralMenger, RejectsUnsupportedBrickSizes) {
  for (int M : {0, 2, 8, 10, 32, 243}) {
    try {
      MengerProducer m(M);
      ADD_FAILURE() << "brick_size " << M << " accepted";
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), Errc::invalid_argument);
      EXPECT_EQ(e.field(), "brick_size");
      EXPECT_NE(std::string(e.what()).find("brick_size"), std::string::npos) << e.what();
    }
  }
}

// --- Amplified ---------------------------------------------------------------------------

/// A smooth stand-in for the stored volume's trilinear value, within [0.2, 0.8].
float coarse_value(double x, double y, double z) {
  return float(0.5 + 0.3 * std::sin(6.0 * x + 1.0) * std::cos(5.0 * y) * std::sin(4.0 * z + 0.5));
}

AmplifiedParams test_params() {
  AmplifiedParams p;
  p.brick_size = 16;
  p.stored_depth = 2;
  p.max_depth = 6;
  p.amplitude = 0.2;
  p.gain = 0.6;
  p.seed = 5;
  p.lo = 0.2;
  p.hi = 0.8;
  return p;
}

/// The coarse sampler's argument for voxel i of node coordinate c at depth d (the contract).
double coarse_coordinate(int64_t c, int i, int M, int d) {
  return std::clamp(std::ldexp(double(2 * (c * M + i) - 1) / double(2 * M), -d), 0.0, 1.0);
}

TEST(ProceduralAmplified, AtOrAboveStoredDepthBricksAreTheCoarseSampler) {
  const AmplifiedParams p = test_params();
  AmplifiedProducer amp(coarse_value, p);
  const int M = p.brick_size, E = M + 2;
  for (const NodeAddress& a : {NodeAddress{0, 0, 0, 0}, NodeAddress{1, 1, 0, 1}, NodeAddress{2, 3, 2, 0},
                               NodeAddress{2, 0, 3, 3}}) {
    const NodeContent c = amp.classify(a);
    EXPECT_EQ(c.kind, NodeContent::brick);
    EXPECT_LE(c.lo, 0.2);  // the float bound of the double bound [0.2, 0.8], rounded outward
    EXPECT_GE(c.hi, 0.8);
    EXPECT_NEAR(c.lo, 0.2, 1e-7);
    EXPECT_NEAR(c.hi, 0.8, 1e-7);
    const std::vector<float> b = produce(amp, a);
    for (int k = 0; k < E; ++k)
      for (int j = 0; j < E; ++j)
        for (int i = 0; i < E; ++i)
          ASSERT_EQ(b[brick_index(E, i, j, k)],
                    coarse_value(coarse_coordinate(a.x, i, M, a.depth), coarse_coordinate(a.y, j, M, a.depth),
                                 coarse_coordinate(a.z, k, M, a.depth)))
              << "depth " << a.depth << " voxel " << i << "," << j << "," << k;
  }
}

TEST(ProceduralAmplified, ValuesFollowTheDocumentedFormula) {
  // value = coarse(p) + sum_{o=s+1}^{d} amplitude gain^(o-s-1) noise(p M 2^o / 4 + offset_o) / bound,
  // evaluated here in plain doubles from the unit position (no integer reduction).
  const AmplifiedParams p = test_params();
  AmplifiedProducer amp(coarse_value, p);
  GradientNoise noise(p.seed);
  SplitMix64 rng(~p.seed);
  std::vector<double> offsets;
  for (int o = p.stored_depth + 1; o <= p.max_depth; ++o)
    for (int axis = 0; axis < 3; ++axis) offsets.push_back(rng.uniform(0, 256));
  const int M = p.brick_size, E = M + 2;
  for (const NodeAddress& a : {NodeAddress{3, 5, 2, 7}, NodeAddress{5, 17, 30, 4}, NodeAddress{6, 63, 0, 41}}) {
    const std::vector<float> b = produce(amp, a);
    const int64_t n = int64_t(1) << a.depth;
    for (int k = 0; k < E; k += 3)
      for (int j = 0; j < E; j += 2)
        for (int i = 0; i < E; ++i) {
          const Vec3d u(voxel_centre(a.x, i, M, n), voxel_centre(a.y, j, M, n), voxel_centre(a.z, k, M, n));
          double expected = coarse_value(std::clamp(u.x, 0.0, 1.0), std::clamp(u.y, 0.0, 1.0), std::clamp(u.z, 0.0, 1.0));
          double amplitude = p.amplitude;
          for (int o = p.stored_depth + 1; o <= a.depth; ++o) {
            const double f = M * std::ldexp(1.0, o) / 4.0;
            const size_t q = size_t(o - p.stored_depth - 1);
            expected += amplitude *
                        noise(u.x * f + offsets[3 * q], u.y * f + offsets[3 * q + 1], u.z * f + offsets[3 * q + 2]) /
                        kGradientNoiseBound;
            amplitude *= p.gain;
          }
          ASSERT_NEAR(b[brick_index(E, i, j, k)], expected, 2e-6)
              << "depth " << a.depth << " voxel " << i << "," << j << "," << k;
          ASSERT_NEAR(b[brick_index(E, i, j, k)] - coarse_value(std::clamp(u.x, 0.0, 1.0), std::clamp(u.y, 0.0, 1.0),
                                                                std::clamp(u.z, 0.0, 1.0)),
                      amp.detail_at(a, i, j, k), 2e-6);
        }
  }
}

TEST(ProceduralAmplified, ValuesStayWithinTheClassifyBound) {
  AmplifiedParams p = test_params();
  p.amplitude = 0.5;
  p.gain = 0.9;  // slow decay: the bound grows by almost the first amplitude per depth
  p.max_depth = p.stored_depth + 10;
  // The sampler sits on the bound's edges, so only the detail can leave it.
  auto edges = [](double x, double, double) { return x < 0.5 ? 0.2f : 0.8f; };
  AmplifiedProducer amp(edges, p);
  std::mt19937_64 rng(8);
  for (int d = p.stored_depth + 1; d <= p.max_depth; ++d) {
    const NodeContent c = amp.classify({d, 0, 0, 0});
    ASSERT_EQ(c.kind, NodeContent::brick);
    const double s = p.amplitude * (1 - std::pow(p.gain, d - p.stored_depth)) / (1 - p.gain);
    EXPECT_NEAR(amp.detail_bound(d), s, 1e-12);
    EXPECT_LE(c.lo, 0.2 - s);
    EXPECT_GE(c.hi, 0.8 + s);
    EXPECT_NEAR(c.lo, 0.2 - s, 1e-6);
    EXPECT_NEAR(c.hi, 0.8 + s, 1e-6);
    std::uniform_int_distribution<int64_t> coord(0, (int64_t(1) << d) - 1);
    double largest_detail = 0;
    for (int b = 0; b < 3; ++b) {
      const NodeAddress a{d, coord(rng), coord(rng), coord(rng)};
      for (float v : produce(amp, a)) {
        ASSERT_GE(v, c.lo) << "depth " << d;
        ASSERT_LE(v, c.hi) << "depth " << d;
        largest_detail = std::max({largest_detail, 0.2 - v, v - 0.8});
      }
    }
    // With one octave the bound is nearly reached (the noise's maximum is rare, so not quite);
    // deeper, the octaves' extremes seldom align, and only the bound is checked.
    if (d == p.stored_depth + 1) {
      EXPECT_GT(largest_detail, 0.6 * s);
    }
  }
}

TEST(ProceduralAmplified, DetailHasNearZeroMeanOverABrickPair) {
  AmplifiedParams p = test_params();
  p.brick_size = 32;
  AmplifiedProducer amp(coarse_value, p);
  for (int d = p.stored_depth + 1; d <= p.stored_depth + 2; ++d) {
    double sum = 0, sum2 = 0;
    int64_t count = 0;
    for (const NodeAddress& a : {NodeAddress{d, 4, 5, 6}, NodeAddress{d, 5, 5, 6}})
      for (int k = 1; k <= 32; ++k)
        for (int j = 1; j <= 32; ++j)
          for (int i = 1; i <= 32; ++i) {
            const double v = amp.detail_at(a, i, j, k) / p.amplitude;
            sum += v;
            sum2 += v * v;
            ++count;
          }
    const double mean = sum / double(count), rms = std::sqrt(sum2 / double(count));
    EXPECT_LT(std::abs(mean), 0.03) << "depth " << d;
    EXPECT_GT(rms, 0.1) << "depth " << d;
  }
}

TEST(ProceduralAmplified, DeterministicPerSeedAndDifferentAcrossSeeds) {
  AmplifiedParams p = test_params();
  AmplifiedProducer a(coarse_value, p), b(coarse_value, p);
  p.seed = 6;
  AmplifiedProducer c(coarse_value, p);
  const NodeAddress node{5, 9, 20, 31};
  const std::vector<float> va = produce(a, node), vb = produce(b, node), vc = produce(c, node);
  EXPECT_EQ(va, vb);
  size_t differ = 0;
  for (size_t i = 0; i < va.size(); ++i) differ += va[i] != vc[i];
  EXPECT_GT(differ, va.size() * 9 / 10);
}

TEST(ProceduralAmplified, AdjacentBricksAgreeAcrossFaces) {
  const AmplifiedParams p = test_params();
  AmplifiedProducer amp(coarse_value, p);
  const int M = p.brick_size, E = M + 2;
  for (int d : {p.stored_depth, p.stored_depth + 2, p.max_depth}) {
    const NodeAddress a{d, 1, 2, 1};
    const std::vector<float> va = produce(amp, a);
    const std::vector<float> nb[3] = {produce(amp, {d, 2, 2, 1}), produce(amp, {d, 1, 3, 1}), produce(amp, {d, 1, 2, 2})};
    for (int s = 0; s < E; ++s)
      for (int t = 0; t < E; ++t) {
        // Our border equals their first interior voxel, and their border our last one: the
        // voxel centres are computed from the same integers, so bit for bit.
        EXPECT_EQ(va[brick_index(E, E - 1, s, t)], nb[0][brick_index(E, 1, s, t)]);
        EXPECT_EQ(va[brick_index(E, M, s, t)], nb[0][brick_index(E, 0, s, t)]);
        EXPECT_EQ(va[brick_index(E, s, E - 1, t)], nb[1][brick_index(E, s, 1, t)]);
        EXPECT_EQ(va[brick_index(E, s, M, t)], nb[1][brick_index(E, s, 0, t)]);
        EXPECT_EQ(va[brick_index(E, s, t, E - 1)], nb[2][brick_index(E, s, t, 1)]);
        EXPECT_EQ(va[brick_index(E, s, t, M)], nb[2][brick_index(E, s, t, 0)]);
      }
  }
}

TEST(ProceduralAmplified, ConstantWhenNothingVaries) {
  AmplifiedParams p = test_params();
  p.lo = p.hi = 0.25;
  p.amplitude = 0;
  AmplifiedProducer amp([](double, double, double) { return 0.25f; }, p);
  const NodeContent c = amp.classify({4, 1, 2, 3});
  EXPECT_EQ(c.kind, NodeContent::constant);
  EXPECT_EQ(c.value, 0.25f);
  p.amplitude = 0.1;
  AmplifiedProducer noisy([](double, double, double) { return 0.25f; }, p);
  EXPECT_EQ(noisy.classify({2, 1, 2, 3}).kind, NodeContent::constant);  // no octave above the stored depth
  EXPECT_EQ(noisy.classify({3, 1, 2, 3}).kind, NodeContent::brick);
}

TEST(ProceduralAmplified, BrickIdsAreUniquePerAddress) {
  AmplifiedParams p = test_params();
  p.stored_depth = 30;
  p.max_depth = 40;
  AmplifiedProducer amp(coarse_value, p);
  // Every node of the first depths, then random nodes and two corners of every deeper depth
  // (both sides of depth 20): as many distinct ids as distinct addresses.
  std::set<std::array<int64_t, 4>> addresses;
  std::unordered_set<uint64_t> ids;
  auto add = [&](const NodeAddress& a) {
    addresses.insert({a.depth, a.x, a.y, a.z});
    ids.insert(amp.brick_id(a));
  };
  for (int d = 0; d <= 4; ++d)
    for (int64_t z = 0; z < (int64_t(1) << d); ++z)
      for (int64_t y = 0; y < (int64_t(1) << d); ++y)
        for (int64_t x = 0; x < (int64_t(1) << d); ++x) add({d, x, y, z});
  std::mt19937_64 rng(2);
  for (int d = 5; d <= 40; ++d) {
    std::uniform_int_distribution<int64_t> coord(0, (int64_t(1) << d) - 1);
    for (int s = 0; s < 3000; ++s) add({d, coord(rng), coord(rng), coord(rng)});
    add({d, 0, 0, 0});
    add({d, (int64_t(1) << d) - 1, 0, 0});
  }
  EXPECT_EQ(ids.size(), addresses.size());
  EXPECT_EQ(amp.brick_id({0, 0, 0, 0}), 0u);
  EXPECT_EQ(amp.brick_id({1, 0, 0, 0}), 1u);
  EXPECT_EQ(amp.brick_id({1, 1, 1, 1}), 8u);
  EXPECT_EQ(amp.brick_id({2, 0, 0, 0}), 9u);
}

TEST(ProceduralAmplified, RejectsBadParametersNamingThem) {
  auto expect_rejected = [](AmplifiedProducer::CoarseSampler sampler, const AmplifiedParams& p, const char* field) {
    try {
      AmplifiedProducer amp(std::move(sampler), p);
      ADD_FAILURE() << field << " accepted";
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), Errc::invalid_argument) << e.what();
      EXPECT_EQ(e.field(), field) << e.what();
      EXPECT_NE(std::string(e.what()).find(field), std::string::npos) << e.what();
    }
  };
  const double inf = std::numeric_limits<double>::infinity(), nan = std::nan("");
  AmplifiedParams p;
  p = test_params(), p.brick_size = 1, expect_rejected(coarse_value, p, "brick_size");
  p = test_params(), p.brick_size = 257, expect_rejected(coarse_value, p, "brick_size");
  p = test_params(), p.stored_depth = -1, expect_rejected(coarse_value, p, "stored_depth");
  p = test_params(), p.stored_depth = 31, p.max_depth = 31, expect_rejected(coarse_value, p, "stored_depth");
  p = test_params(), p.max_depth = 1, expect_rejected(coarse_value, p, "max_depth");
  p = test_params(), p.max_depth = p.stored_depth + 11, expect_rejected(coarse_value, p, "max_depth");
  p = test_params(), p.amplitude = nan, expect_rejected(coarse_value, p, "amplitude");
  p = test_params(), p.amplitude = inf, expect_rejected(coarse_value, p, "amplitude");
  p = test_params(), p.gain = -0.5, expect_rejected(coarse_value, p, "gain");
  p = test_params(), p.gain = inf, expect_rejected(coarse_value, p, "gain");
  p = test_params(), p.max_depth = -2, expect_rejected(coarse_value, p, "max_depth");
  p = test_params(), p.amplitude = 1e300, p.gain = 1e300, expect_rejected(coarse_value, p, "amplitude");
  p = test_params(), p.lo = 1, p.hi = 0, expect_rejected(coarse_value, p, "lo");
  p = test_params(), expect_rejected(nullptr, p, "coarse");
  // The defaults are accepted, with 3 levels of amplification.
  p = test_params(), p.max_depth = -1;
  EXPECT_EQ(AmplifiedProducer(coarse_value, p).max_depth(), p.stored_depth + 3);
  EXPECT_THROW(AmplifiedProducer(coarse_value, p).classify({p.stored_depth + 4, 0, 0, 0}), Error);
}

TEST(ProceduralAmplified, ProducesTheSameBricksFromManyThreads) {
  const AmplifiedParams p = test_params();
  AmplifiedProducer amp(coarse_value, p);
  std::vector<NodeAddress> nodes;
  for (int d = 1; d <= p.max_depth; ++d) nodes.push_back({d, (int64_t(1) << d) - 1, d % 2, 0});
  std::vector<std::vector<float>> serial;
  for (const NodeAddress& a : nodes) serial.push_back(produce(amp, a));
  std::vector<std::vector<std::vector<float>>> parallel(4);
  std::vector<std::thread> threads;
  for (size_t t = 0; t < parallel.size(); ++t)
    threads.emplace_back([&, t] {
      for (int rep = 0; rep < 3; ++rep)
        for (const NodeAddress& a : nodes) parallel[t].push_back(produce(amp, a));
    });
  for (auto& t : threads) t.join();
  for (const auto& results : parallel)
    for (size_t i = 0; i < results.size(); ++i) EXPECT_EQ(results[i], serial[i % nodes.size()]);
}

}  // namespace
}  // namespace brickyard::gigavoxels
