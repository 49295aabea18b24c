#pragma once
/// @file preintegrated.h
/// @brief A pre-integrated transfer function (Engel, Kraus and Ertl 2001) in its integral
/// form: running integrals of the extinction and of the extinction-weighted colour over the
/// value axis give the emission-absorption integral of any ray segment whose value varies
/// linearly from s_front to s_back, for any segment length, in O(1), without the 2D table (the
/// table is a cache of exactly these differences). Self-attenuation inside a segment is
/// neglected, as in the 2D tables' usual construction.

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#include "renderers/common/transfer_function.h"

namespace brickyard::gigavoxels {

class PreintegratedTf {
 public:
  PreintegratedTf() = default;
  /// @param tf opacities are per finest voxel of length (as every back end reads them).
  explicit PreintegratedTf(const TransferFunction& tf, int size = 4096) {
    const auto& pts = tf.points();
    // Entries at the points' own values, in double (rounded to float, the first entry would
    // move off a zero-opacity point). Points that all share one value make a step there: the
    // table spans a sliver above it, so that values above take the last point.
    lo_ = pts.front().value;
    double hi = pts.back().value;
    if (!(hi > lo_)) hi = lo_ + std::max(std::abs(lo_), 1.0) * 1e-9;
    const int n = std::max(size, 2);
    scale_ = double(n - 1) / (hi - lo_);
    dv_ = (hi - lo_) / double(n - 1);
    integral_.assign(size_t(n), Integral{0.0, Vec3d(0.0)});
    point_.resize(size_t(n));
    for (size_t i = 0; i < size_t(n); ++i) {
      Vec3f c;
      float a;
      tf.eval(lo_ + double(i) * dv_, c, a);
      const double t = -std::log(std::max(1e-12, 1.0 - std::min(double(a), 1.0 - 1e-12)));
      point_[i] = {Vec3d(c), t};
      if (i > 0) {  // trapezoids over the value axis
        const Entry& prev = point_[i - 1];
        integral_[i].tau = integral_[i - 1].tau + 0.5 * (prev.tau + t) * dv_;
        integral_[i].ctau = integral_[i - 1].ctau + (prev.color * prev.tau + Vec3d(c) * t) * (0.5 * dv_);
      }
    }
    // Up to the entry before the first with any extinction, segments are transparent.
    size_t first = 0;
    while (first < point_.size() && point_[first].tau == 0) ++first;
    clear_up_to_ = first == 0 ? -kInfinity : first == point_.size() ? kInfinity : lo_ + double(first - 1) * dv_;
    last_ = n - 1;
  }

  /// @brief The segment's opacity and colour (not premultiplied) for a value going linearly
  /// from front to back over length_voxels finest voxels.
  void segment(float front, float back, double length_voxels, Vec3f& color, float& alpha) const {
    if (double(std::max(front, back)) <= clear_up_to_) {  // most of a sparse volume: no table, no exp
      color = Vec3f(0.0f), alpha = 0;
      return;
    }
    const double xf = position(front), xb = position(back);
    double tau;  // mean extinction per voxel over the segment
    Vec3d ctau;
    if (std::abs(xb - xf) < 1e-3) {
      const Entry e = point_at(0.5 * (xf + xb));
      tau = e.tau;
      ctau = e.color * e.tau;
    } else {
      const Integral f = integral(xf), b = integral(xb);
      const double inv = 1.0 / ((xb - xf) * dv_);
      tau = (b.tau - f.tau) * inv;
      ctau = (b.ctau - f.ctau) * inv;
    }
    alpha = opacity(float(std::max(0.0, tau) * length_voxels));
    color = tau > 1e-12 ? Vec3f(ctau * (1.0 / tau)) : Vec3f(0.0f);
  }

  /// @brief 1 - exp(-x) for x >= 0, in float (alpha is stored as one): below 1/8, where the
  /// difference would cancel, the series to x^5 (truncation below 2^-24 of the result); above,
  /// 1 - expf(-x), within about 2^-21 of it (glibc's expm1f costs three times as much).
  static float opacity(float x) {
    if (x < 0.125f) return x * (1 - x * (0.5f - x * (1.0f / 6 - x * (1.0f / 24 - x * (1.0f / 120)))));
    return 1 - std::exp(-x);
  }

 private:
  struct Entry {
    Vec3d color;
    double tau;
  };
  /// Table position of value v, not clamped: a segment reaching past the points integrates
  /// the end points' constant extinction there over its whole length. NaN becomes 0.
  double position(float v) const {
    // An infinite value is the largest finite one: the extinction there is the end's all the same.
    const double x = (double(std::clamp(v, -kFloatMax, kFloatMax)) - lo_) * scale_;
    return x == x ? x : 0.0;
  }
  /// The running integrals over [lo, value], side by side: a lookup reads two adjacent rows.
  struct Integral {
    double tau;  // of extinction
    Vec3d ctau;  // of colour * extinction
  };
  /// The running integrals at table position x, continued past either end with that end's
  /// constant extinction and colour.
  /// (Indices are signed and the last position kept: size_t conversions and the vectors'
  /// sizes cost a DVR sample 15 instructions and three branches.)
  Integral integral(double x) const {
    if (!(x > 0 && x < double(last_))) {  // x is never NaN (position())
      const int64_t i = x > 0 ? last_ : 0;
      const double d = (x - double(i)) * dv_;
      const Entry& p = point_[size_t(i)];
      return {integral_[size_t(i)].tau + p.tau * d, integral_[size_t(i)].ctau + p.color * (p.tau * d)};
    }
    const int64_t i = int64_t(x);
    const double f = x - double(i);
    const Integral* a = integral_.data() + i;
    return {a[0].tau + (a[1].tau - a[0].tau) * f, a[0].ctau + (a[1].ctau - a[0].ctau) * f};
  }
  Entry point_at(double x) const {
    x = std::clamp(x, 0.0, double(last_));
    const int64_t i = int64_t(x), j = std::min(i + 1, last_);
    const double f = x - double(i);
    const Entry& a = point_[size_t(i)];
    const Entry& b = point_[size_t(j)];
    return {a.color + (b.color - a.color) * f, a.tau + (b.tau - a.tau) * f};
  }

  static constexpr double kInfinity = std::numeric_limits<double>::infinity();
  static constexpr float kFloatMax = std::numeric_limits<float>::max();
  double lo_ = 0, scale_ = 0;
  double dv_ = 0;  // value per table entry
  double clear_up_to_ = -kInfinity;  // a segment whose values all lie at or below this is transparent
  int64_t last_ = 0;                  // the last table position
  std::vector<Integral> integral_;
  std::vector<Entry> point_;
};

}  // namespace brickyard::gigavoxels
