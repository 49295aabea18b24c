#pragma once
/// @file transfer_function.h
/// @brief Piecewise-linear transfer function (colour and opacity against value), and the
/// summed-area table of its opacity that answers "is anything visible in [lo, hi]?" in O(1),
/// so that nodes whose value range maps to zero opacity are never fetched.

#include <vector>

#include "core/math.h"

namespace brickyard {

struct TfPoint {
  double value = 0;
  Vec3f color{1.0f};
  float opacity = 0;  ///< per voxel length at the reference step (1 voxel), in [0, 1]
};

class TransferFunction {
 public:
  TransferFunction() = default;
  /// @brief `points` sorted by value (strictly increasing values are not required: equal
  /// values make a step). Values below the first point take the first point's colour and
  /// opacity, above the last the last's.
  explicit TransferFunction(std::vector<TfPoint> points, int table_size = 4096);

  bool empty() const { return points_.empty(); }
  const std::vector<TfPoint>& points() const { return points_; }
  /// @brief Colour and opacity at v (exact piecewise-linear interpolation).
  void eval(double v, Vec3f& color, float& opacity) const;
  float opacity(double v) const;
  /// @brief Whether any value in [lo, hi] has non-zero opacity (conservative: never false when
  /// something in the range is visible), from the opacity summed-area table.
  bool visible(double lo, double hi) const;
  /// @brief The smallest interval holding every value of non-zero opacity (empty: lo > hi).
  double visible_lo() const { return visible_lo_; }
  double visible_hi() const { return visible_hi_; }

 private:
  std::vector<TfPoint> points_;
  // Summed-area table: prefix_[i] = sum of the maximum opacity over bins [0, i); bins split
  // [points.front().value, points.back().value] evenly. Outside that interval the opacity is
  // the end points', handled separately.
  std::vector<double> prefix_;
  double table_lo_ = 0, table_hi_ = 0;
  double visible_lo_ = 1, visible_hi_ = 0;
};

/// @brief The transfer function resampled for a render loop: colour and opacity already
/// corrected for a sampling step, in a table read with linear interpolation (one multiply, one
/// conversion and two loads per sample instead of a search and a pow). Values outside the
/// function's points take the end entries, like TransferFunction::eval.
class TfTable {
 public:
  TfTable() = default;
  /// @param step_voxels the sampling step: opacity a becomes 1 - (1 - a)^step.
  TfTable(const TransferFunction& tf, double step_voxels, int size = 4096);
  void lookup(float v, Vec3f& color, float& alpha) const {
    // In double: a table over denormal values (a span of 1e-40 has a scale past the largest
    // float) or near the largest float (v - lo overflows) still finds its entry.
    const double xd = (double(v) - lo_) * scale_;
    const float x = xd > 0 ? (xd < last_ ? float(xd) : last_) : 0;  // NaN becomes 0
    const int i = int(x);
    const int j = i + 1 < int(entries_.size()) ? i + 1 : i;
    const float f = x - float(i);
    const Entry& a = entries_[size_t(i)];
    const Entry& b = entries_[size_t(j)];
    color = {a.r + (b.r - a.r) * f, a.g + (b.g - a.g) * f, a.b + (b.b - a.b) * f};
    alpha = a.a + (b.a - a.a) * f;
  }

 private:
  struct Entry {
    float r, g, b, a;
  };
  std::vector<Entry> entries_;
  double lo_ = 0, scale_ = 0;
  float last_ = 0;
};

}  // namespace brickyard
