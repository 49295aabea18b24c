#include "renderers/common/transfer_function.h"

#include <algorithm>
#include <cmath>

namespace brickyard {

TransferFunction::TransferFunction(std::vector<TfPoint> points, int table_size) : points_(std::move(points)) {
  std::stable_sort(points_.begin(), points_.end(), [](const TfPoint& a, const TfPoint& b) { return a.value < b.value; });
  if (points_.empty()) return;
  table_lo_ = points_.front().value;
  table_hi_ = points_.back().value;
  const int bins = table_hi_ > table_lo_ ? std::max(table_size, 1) : 1;
  prefix_.assign(size_t(bins) + 1, 0.0);
  const double width = (table_hi_ - table_lo_) / bins;
  // The maximum of a piecewise-linear function over a bin is at a bin end or at a point inside.
  size_t p = 0;
  for (int b = 0; b < bins; ++b) {
    const double lo = table_lo_ + b * width, hi = b + 1 == bins ? table_hi_ : lo + width;
    float m = std::max(opacity(lo), opacity(hi));
    while (p < points_.size() && points_[p].value < lo) ++p;
    for (size_t q = p; q < points_.size() && points_[q].value <= hi; ++q) m = std::max(m, points_[q].opacity);
    prefix_[size_t(b) + 1] = prefix_[size_t(b)] + double(m);
  }
  // Visible interval: from the first to the last point of non-zero opacity, widened to the
  // neighbouring points (the ramp up to a visible point is visible), unbounded at open ends.
  size_t first = points_.size(), last = 0;
  for (size_t i = 0; i < points_.size(); ++i)
    if (points_[i].opacity > 0) {
      first = std::min(first, i);
      last = i;
    }
  if (first == points_.size()) return;  // invisible everywhere
  visible_lo_ = first == 0 ? -INFINITY : points_[first - 1].value;
  visible_hi_ = last + 1 == points_.size() ? INFINITY : points_[last + 1].value;
}

void TransferFunction::eval(double v, Vec3f& color, float& opacity_out) const {
  if (points_.empty()) {
    color = Vec3f(0.0f);
    opacity_out = 0;
    return;
  }
  if (!(v > points_.front().value)) {  // NaN takes the first point
    color = points_.front().color;
    opacity_out = points_.front().opacity;
    return;
  }
  if (v >= points_.back().value) {
    color = points_.back().color;
    opacity_out = points_.back().opacity;
    return;
  }
  const auto it = std::upper_bound(points_.begin(), points_.end(), v, [](double x, const TfPoint& p) { return x < p.value; });
  const TfPoint& b = *it;
  const TfPoint& a = *(it - 1);
  const float t = float((v - a.value) / (b.value - a.value));
  color = a.color + (b.color - a.color) * t;
  opacity_out = a.opacity + (b.opacity - a.opacity) * t;
}

float TransferFunction::opacity(double v) const {
  Vec3f c;
  float o;
  eval(v, c, o);
  return o;
}

bool TransferFunction::visible(double lo, double hi) const {
  if (points_.empty() || !(lo <= hi)) return false;
  if (lo < table_lo_ && points_.front().opacity > 0) return true;
  if (hi > table_hi_ && points_.back().opacity > 0) return true;
  const double a = std::max(lo, table_lo_), b = std::min(hi, table_hi_);
  if (a > b) return false;
  const size_t bins = prefix_.size() - 1;
  if (table_hi_ <= table_lo_) return prefix_[1] > 0;
  const double scale = double(bins) / (table_hi_ - table_lo_);
  const size_t i0 = std::min(bins - 1, size_t(std::max(0.0, std::floor((a - table_lo_) * scale))));
  const size_t i1 = std::min(bins - 1, size_t(std::max(0.0, std::floor((b - table_lo_) * scale))));
  return prefix_[i1 + 1] - prefix_[i0] > 0;
}

TfTable::TfTable(const TransferFunction& tf, double step_voxels, int size) {
  if (tf.empty()) {
    entries_.assign(1, Entry{0, 0, 0, 0});
    return;
  }
  const double lo = tf.points().front().value, hi = tf.points().back().value;
  const int n = hi > lo ? std::max(size, 2) : 1;
  entries_.resize(size_t(n));
  for (int i = 0; i < n; ++i) {
    const double v = n > 1 ? lo + (hi - lo) * double(i) / double(n - 1) : lo;
    Vec3f c;
    float a;
    tf.eval(v, c, a);
    entries_[size_t(i)] = {c.x, c.y, c.z, float(1 - std::pow(1 - double(a), step_voxels))};
  }
  lo_ = lo;
  scale_ = n > 1 ? double(n - 1) / (hi - lo) : 0.0;
  last_ = float(n - 1);
}

}  // namespace brickyard
