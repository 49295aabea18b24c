// Fields with large constant regions: the Menger sponge and sparse blob clusters.

#include <algorithm>
#include <cmath>
#include <vector>

#include <fmt/format.h>

#include "core/error.h"
#include "fields/field_types.h"
#include "fields/random.h"

namespace brickyard {
namespace {

/// Menger sponge of a given depth on the unit cube: 1 in the solid, 0 in the removed parts.
/// A point is removed at level l when at least two of its base-3 digits at position l are 1
/// (it lies in the middle third along two axes). Digits come from integer arithmetic on
/// floor(p * 3^levels), so cell boundaries are exact and the solid fraction is (20/27)^levels.
class Menger final : public FieldBase<Menger> {
 public:
  explicit Menger(FieldParamReader& p) : levels_(static_cast<int>(p.get_int("levels", 4, 0, 18, "recursion depth"))) {
    cells_ = 1;
    for (int l = 0; l < levels_; ++l) cells_ *= 3;
    params_ = p.declared();
  }
  std::string_view name() const override { return "menger"; }
  Box3d domain() const override { return {Vec3d(0.0), Vec3d(1.0)}; }
  ValueRange range() const override { return {0.0, 1.0}; }
  bool has_analytic_gradient() const override { return true; }  // zero wherever it is defined
  Vec3d gradient(const Vec3d&) const override { return {}; }

  double eval(const Vec3d& p) const {
    if (!(p.x >= 0 && p.y >= 0 && p.z >= 0 && p.x <= 1 && p.y <= 1 && p.z <= 1)) return 0.0;
    int64_t ix = cell(p.x), iy = cell(p.y), iz = cell(p.z);
    for (int l = 0; l < levels_; ++l) {
      const int ones = int(ix % 3 == 1) + int(iy % 3 == 1) + int(iz % 3 == 1);
      if (ones >= 2) return 0.0;
      ix /= 3; iy /= 3; iz /= 3;
    }
    return 1.0;
  }

 private:
  int64_t cell(double t) const {
    return std::min(static_cast<int64_t>(t * static_cast<double>(cells_)), cells_ - 1);
  }
  int levels_;
  int64_t cells_ = 1;
};

/// Clusters of smooth blobs: value = 1 - prod_i (1 - w_i(p)), with the compactly supported
/// bump w(r) = (1 - r^2/R^2)^3 for r < R. Exactly 0 outside every blob (most of the domain),
/// in [0, 1] everywhere, C2, with a closed-form gradient. A uniform grid of blob lists keeps
/// evaluation cost independent of the blob count.
class SparseBlobs final : public FieldBase<SparseBlobs> {
 public:
  explicit SparseBlobs(FieldParamReader& p) {
    const auto seed = static_cast<uint64_t>(p.get_int("seed", 1, 0, int64_t(1) << 52, "placement seed"));
    const auto clusters = p.get_int("clusters", 6, 1, 1000, "number of clusters");
    const auto per_cluster = p.get_int("blobs", 24, 1, 10000, "blobs per cluster");
    const double cluster_radius = p.get("cluster_radius", 0.08, "radius of the ball blob centres are drawn from");
    const double blob_radius = p.get("blob_radius", 0.03, "largest blob radius (radii are drawn in [R/2, R])");
    if (cluster_radius < 0 || blob_radius <= 0)
      throw Error(Errc::invalid_argument, "blob_radius must be positive and cluster_radius non-negative")
          .with_field("blob_radius");
    params_ = p.declared();

    SplitMix64 rng(seed);
    for (int64_t c = 0; c < clusters; ++c) {
      const Vec3d centre{rng.uniform(0.15, 0.85), rng.uniform(0.15, 0.85), rng.uniform(0.15, 0.85)};
      for (int64_t b = 0; b < per_cluster; ++b) {
        Vec3d offset;
        do {
          offset = {rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-1, 1)};
        } while (dot(offset, offset) > 1.0);
        const double radius = blob_radius * rng.uniform(0.5, 1.0);
        blobs_.push_back({centre + offset * cluster_radius, 1.0 / (radius * radius), radius});
      }
    }
    cells_.resize(size_t(kGrid) * kGrid * kGrid);
    for (uint32_t i = 0; i < blobs_.size(); ++i) {
      const Blob& b = blobs_[i];
      const Vec3i lo = cell_of(b.centre - Vec3d(b.radius)), hi = cell_of(b.centre + Vec3d(b.radius));
      for (int z = lo.z; z <= hi.z; ++z)
        for (int y = lo.y; y <= hi.y; ++y)
          for (int x = lo.x; x <= hi.x; ++x) cells_[size_t((z * kGrid + y) * kGrid + x)].push_back(i);
    }
  }
  std::string_view name() const override { return "sparse-blobs"; }
  Box3d domain() const override { return {Vec3d(0.0), Vec3d(1.0)}; }
  ValueRange range() const override { return {0.0, 1.0}; }
  bool has_analytic_gradient() const override { return true; }

  double eval(const Vec3d& p) const {
    double keep = 1.0;  // product of (1 - w_i)
    const Vec3i c = cell_of(p);
    for (uint32_t i : cells_[size_t((c.z * kGrid + c.y) * kGrid + c.x)]) {
      const Blob& b = blobs_[i];
      const Vec3d d = p - b.centre;
      const double t = 1.0 - dot(d, d) * b.inv_r2;
      if (t > 0) keep *= 1.0 - t * t * t;
    }
    return 1.0 - keep;
  }

  Vec3d gradient(const Vec3d& p) const override {
    // d/dp [1 - prod(1 - w_i)] = sum_i w_i'(p) prod_{j != i} (1 - w_j), with prefix and
    // suffix products so that a factor of exactly 0 (a blob centre) needs no division.
    const Vec3i c = cell_of(p);
    std::vector<double> keep;
    std::vector<Vec3d> dw;
    for (uint32_t i : cells_[size_t((c.z * kGrid + c.y) * kGrid + c.x)]) {
      const Blob& b = blobs_[i];
      const Vec3d d = p - b.centre;
      const double t = 1.0 - dot(d, d) * b.inv_r2;
      if (t <= 0) continue;
      keep.push_back(1.0 - t * t * t);
      dw.push_back(d * (-6.0 * t * t * b.inv_r2));  // dw/dp = 3 t^2 * dt/dp, dt/dp = -2 d / R^2
    }
    const size_t n = keep.size();
    std::vector<double> suffix(n + 1, 1.0);
    for (size_t i = n; i-- > 0;) suffix[i] = suffix[i + 1] * keep[i];
    Vec3d g;
    double prefix = 1.0;
    for (size_t i = 0; i < n; ++i) {
      g += dw[i] * (prefix * suffix[i + 1]);
      prefix *= keep[i];
    }
    return g;
  }

 private:
  static constexpr int kGrid = 16;
  struct Blob {
    Vec3d centre;
    double inv_r2;
    double radius;
  };
  static Vec3i cell_of(const Vec3d& p) {
    auto axis = [](double t) { return std::clamp(static_cast<int>(std::floor(t * kGrid)), 0, kGrid - 1); };
    return {axis(p.x), axis(p.y), axis(p.z)};
  }

  std::vector<Blob> blobs_;
  std::vector<std::vector<uint32_t>> cells_;
};

}  // namespace

std::unique_ptr<Field> make_menger(FieldParamReader& p) { return std::make_unique<Menger>(p); }
std::unique_ptr<Field> make_sparse_blobs(FieldParamReader& p) { return std::make_unique<SparseBlobs>(p); }

}  // namespace brickyard
