#pragma once
/// @file procedural.h
/// @brief The `gigavoxels` back end's procedural brick producers (Crassin et al., GigaVoxels,
/// sec. on procedural data): bricks computed on demand by the loader instead of read from a
/// store. Two producers: an instanced fractal (the Menger sponge, one brick shared by every
/// non-empty node at every depth) and noise amplification of a stored coarse volume.
///
/// Concurrency. A producer is immutable after construction: classify(), produce() and
/// brick_id() may be called from many threads at once. produce() allocates nothing per voxel
/// (the amplified producer allocates one small per-axis table per brick).
///
/// Geometry. The tree is an N^3-tree over the unit cube [0,1]^3. A node at depth d has integer
/// coordinates c = (x, y, z), each in [0, N^d), and covers [c / N^d, (c + 1) / N^d]; depth 0 is
/// the root. A brick has M^3 voxels plus a one-voxel border on each side: E = M + 2 float32
/// values per axis, x fastest, index ((k E) + j) E + i for i, j, k in [0, E). Voxel i has its
/// centre at unit coordinate (c + (i - 0.5) / M) / N^d along its axis: indices 0 and E - 1 are
/// the border, lying in the neighbouring nodes. Addresses outside [0, max_depth()] or outside
/// [0, N^d) are caller bugs: Error(Errc::internal).

#include <cstdint>
#include <functional>
#include <vector>

#include "fields/gradient_noise.h"

namespace brickyard::gigavoxels {

/// @brief A node of the N^3-tree: depth and integer coordinates (see the file comment).
struct NodeAddress {
  int depth = 0;
  int64_t x = 0, y = 0, z = 0;
  friend bool operator==(const NodeAddress&, const NodeAddress&) = default;
};

/// @brief What a node holds, known without computing voxels.
struct NodeContent {
  enum Kind { constant, brick } kind = constant;
  float value = 0;       ///< the value of a constant node
  float lo = 0, hi = 0;  ///< a bound of the node's values, border included
};

/// @brief A source of bricks computed on demand. Immutable: every member is safe from many threads.
class BrickProducer {
 public:
  virtual ~BrickProducer() = default;
  /// @brief N: children per axis.
  virtual int arity() const = 0;
  /// @brief M: voxels per axis inside a brick (E = M + 2 with the border).
  virtual int brick_size() const = 0;
  /// @brief The deepest depth this producer produces.
  virtual int max_depth() const = 0;
  /// @brief Constant or brick, with a bound of the values; cheap (no voxels computed).
  virtual NodeContent classify(const NodeAddress&) const = 0;
  /// @brief Writes the node's E^3 values to out; only for nodes that classify() as brick.
  virtual void produce(const NodeAddress&, float* out) const = 0;
  /// @brief Nodes with equal ids have identical bricks (instancing: a pool stores one copy).
  virtual uint64_t brick_id(const NodeAddress&) const = 0;
};

/// @brief The Menger sponge as an instanced fractal over a 3^3-tree (N = 3).
///
/// A node is empty (constant 0, bound [0, 0]) when, at any depth up to its own, two or more of
/// the base-3 digits of its coordinates are 1: the digit rule of the `menger` field
/// (fields/fractal_fields.cpp), whose level-l digits are those of floor(p 3^levels). Every
/// other node holds the same brick (one brick_id): the sponge refined log3(M) levels below the
/// node, whose voxel boxes are exactly the cells of that refinement, so each voxel's
/// box-filtered occupancy is exactly 0 or 1 and the brick's interior mean is (20/27)^log3(M).
/// A non-empty node at depth d therefore shows exactly the `menger` field of d + log3(M)
/// levels. The border is what a non-empty neighbour holds, which by the sponge's mirror
/// symmetry is the edge voxel repeated (see the constructor); across a face with an empty
/// neighbour the shared brick cannot know it, so its border there still reads as that edge.
class MengerProducer final : public BrickProducer {
 public:
  /// @brief brick_size M must be 3, 9, 27 or 81; else Error(invalid_argument) naming brick_size.
  explicit MengerProducer(int brick_size = 27);

  int arity() const override { return 3; }
  int brick_size() const override { return M_; }
  /// @brief 39: the deepest depth whose coordinates (up to 3^39 - 1) fit in int64.
  int max_depth() const override { return kMaxDepth; }
  NodeContent classify(const NodeAddress& node) const override;
  /// @brief Copies the shared brick.
  void produce(const NodeAddress& node, float* out) const override;
  /// @brief kSharedBrickId for every node.
  uint64_t brick_id(const NodeAddress& node) const override;

  static constexpr int kMaxDepth = 39;
  static constexpr uint64_t kSharedBrickId = 0;
  /// @brief The shared brick, E^3 values.
  const std::vector<float>& shared_brick() const { return brick_; }

 private:
  int M_;
  std::vector<float> brick_;
};

/// @brief Parameters of AmplifiedProducer.
struct AmplifiedParams {
  int brick_size = 32;      ///< M, in [2, 256]
  int stored_depth = 0;     ///< depth of the finest stored level, in [0, 30]
  int max_depth = -1;       ///< deepest produced depth, in [stored_depth, stored_depth + 10]; -1: stored_depth + 3
  double amplitude = 0.1;   ///< amplitude of the first added octave (depth stored_depth + 1); finite
  double gain = 0.5;        ///< amplitude ratio between successive octaves; finite, >= 0
  uint64_t seed = 1;        ///< noise permutation and octave offsets
  double lo = 0, hi = 1;    ///< a bound of the coarse sampler's values; finite, lo <= hi
};

/// @brief Perlin-noise amplification of a stored coarse volume over an octree (N = 2): detail
/// continues below the stored resolution.
///
/// The value at depth d and unit position p is
///   coarse(p) + sum_{o = s+1}^{d} a_o n_o(p),   a_o = amplitude gain^(o - s - 1),  s = stored_depth,
///   n_o(p) = noise(p M 2^o / 4 + offset_o) / kGradientNoiseBound,  so |n_o| <= 1.
/// p M 2^o is p in voxels of depth o, so f0 = 1/4: a noise lattice cell spans 4 voxels of its
/// own depth. Perlin noise's energy lies at about 1/2 to 1 cycle per lattice cell, i.e. 1/8 to
/// 1/4 cycle per voxel, well under the voxels' Nyquist limit of 1/2, so trilinear
/// interpolation resolves it; one depth up the same octave would be at 1/4 to 1/2 cycle per
/// (twice as large) voxel, at the limit, which is why a brick at depth d holds exactly the
/// octaves up to d (mip levels are band-limited). The per-octave offsets keep the octaves'
/// lattices, which nest, from sharing their zeros: SplitMix64(~seed).uniform(0, 256), three
/// per octave (x, y, z) from o = s + 1 on, as the `fbm` field draws its offsets; the
/// permutation is GradientNoise(seed).
///
/// Positions. Voxel centres are computed from the integer numerator n = 2 (c M + i) - 1 (in
/// half-voxels of depth d) so that two bricks that see the same voxel compute the same
/// position bit for bit: the coarse sampler gets u = clamp(n / (2 M) 2^-d, 0, 1) per axis (border
/// voxels of edge bricks would lie half a voxel outside), and the noise lattice coordinate of
/// octave o is reduced modulo the noise's period 256 in integers, so it stays exact at any depth.
/// Adjacent bricks' borders hence equal each other's first interior voxels.
///
/// classify() is always a brick (a constant lo when lo == hi and no octave is added), bound
/// [lo - S_d, hi + S_d] with S_d = sum of |a_o| for o <= d, rounded outward to float: a true
/// bound as long as the sampler stays within [lo, hi].
class AmplifiedProducer final : public BrickProducer {
 public:
  /// @brief The coarse volume's trilinear value at a unit position in [0, 1]^3. Called from
  /// the loader's threads: must be thread-safe.
  using CoarseSampler = std::function<float(double ux, double uy, double uz)>;

  /// @brief Error(invalid_argument), naming the parameter, for an empty sampler, a parameter
  /// outside the ranges of AmplifiedParams, or an amplitude and gain whose bound overflows.
  AmplifiedProducer(CoarseSampler coarse, const AmplifiedParams& params);

  int arity() const override { return 2; }
  int brick_size() const override { return M_; }
  int max_depth() const override { return max_depth_; }
  int stored_depth() const { return stored_depth_; }
  NodeContent classify(const NodeAddress& node) const override;
  void produce(const NodeAddress& node, float* out) const override;
  /// @brief Unique per address. Through depth 20 an exact enumeration ((8^d - 1) / 7 + Morton
  /// code, below 2^61); deeper, a 64-bit mix with the top bit set (no 64-bit id can be
  /// collision-free over the 2^120 addresses of depth 40; the chance of one is 2^-63 per pair).
  uint64_t brick_id(const NodeAddress& node) const override;

  static constexpr int kMaxAmplification = 10;
  static constexpr int kMaxStoredDepth = 30;
  /// @brief S_d: the bound of the added detail at depth d (0 at d <= stored_depth).
  double detail_bound(int depth) const { return detail_bound_[size_t(depth)]; }
  /// @brief The added detail alone at a voxel (i, j, k) of a node (the value minus coarse),
  /// evaluated voxel by voxel: the scalar reference that produce() is tested against.
  double detail_at(const NodeAddress& node, int i, int j, int k) const;

 private:
  CoarseSampler coarse_;
  int M_, stored_depth_, max_depth_;
  double lo_, hi_;
  GradientNoise noise_;
  std::vector<double> scale_;         ///< per octave o > s (index o - s - 1): a_o / kGradientNoiseBound
  std::vector<double> offset_;        ///< per octave, 3 lattice offsets in [0, 256)
  std::vector<double> detail_bound_;  ///< S_d for d in [0, max_depth]
};

}  // namespace brickyard::gigavoxels
