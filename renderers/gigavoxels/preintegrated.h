#pragma once
/// @file preintegrated.h
/// @brief A pre-integrated transfer function (Engel, Kraus and Ertl 2001) in its integral
/// form: running integrals of the extinction and of the extinction-weighted colour over the
/// value axis give the emission-absorption integral of any ray segment whose value varies
/// linearly from s_front to s_back, for any segment length, in O(1), without the 2D table (the
/// table is a cache of exactly these differences). Self-attenuation inside a segment is
/// neglected, as in the 2D tables' usual construction.

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
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
    // No points: transparent everywhere (every entry's opacity is 0).
    lo_ = pts.empty() ? 0.0 : pts.front().value;
    double hi = pts.empty() ? 1.0 : pts.back().value;
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
    // One row past the last, equal to it: segments() interpolates at the last position
    // (weight 0 on the row after) without a test.
    integral_.push_back(integral_.back());
    for (const bool upper : {false, true}) {
      const Entry& p = point_[upper ? size_t(last_) : 0];
      end_slope_[upper] = {p.tau, Vec3d(p.color)};
    }
  }

  /// @brief The segment's opacity and colour (not premultiplied) for a value going linearly
  /// from front to back over length_voxels finest voxels.
  void segment(float front, float back, double length_voxels, Vec3f& color, float& alpha) const {
    if (clear(front, back)) {  // most of a sparse volume: no table, no exp
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

  /// @brief segment() for the n segments of a run of samples (n <= kLanes), side by side:
  /// segment k goes from value[k] to value[k + 1] over length[k] finest voxels. The same
  /// arithmetic, and so the same results, with each value's running integrals looked up once
  /// for the segments on both sides of it (one by one, segment() looks each up twice), and
  /// the opacities in vector lanes. Segments whose ends are too close for a difference of
  /// integrals (the midpoint's extinction stands in) are left to segment(), as are no others.
  template <int kLanes>
  void segments(const float (&value)[kLanes + 1], const double (&length)[kLanes], int n, Vec3f (&color)[kLanes],
                float (&alpha)[kLanes]) const {
    static_assert(kLanes == 8, "opacities in lanes are 8 floats (AVX2)");
    double x[kLanes + 1];
    Row at[kLanes + 1];
    for (int k = 0; k <= n; ++k) x[k] = position(value[k]), at[k] = integral_row(x[k]);
    float extinction[kLanes] = {};  // tau times the length, per segment
    bool close_ends[kLanes] = {};
    bool any_close = false;
    for (int k = 0; k < n; ++k) {
      const double dx = x[k + 1] - x[k];
      const bool visible = !clear(value[k], value[k + 1]);
      close_ends[k] = visible && std::abs(dx) < 1e-3;
      any_close |= close_ends[k];
      const Row d = (at[k + 1] - at[k]) * (1.0 / (dx * dv_));  // tau, ctau
      const double tau = d[0];
      extinction[k] = visible ? float(std::max(0.0, tau) * length[k]) : 0.0f;
      color[k] = visible && tau > 1e-12 ? Vec3f(Vec3d(d[1], d[2], d[3]) * (1.0 / tau)) : Vec3f(0.0f);
    }
    opacities(extinction, alpha);
    for (int k = 0; any_close && k < n; ++k)
      if (close_ends[k]) segment(value[k], value[k + 1], length[k], color[k], alpha[k]);
  }

  /// @brief 1 - exp(-x) for x >= 0, in float (alpha is stored as one): below 1/8, where the
  /// difference would cancel, the series to x^5 (truncation below 2^-24 of the result); above,
  /// 1 - exp(-x) by exp_negative(), within about 2^-21 of it (glibc's expm1f costs three times
  /// as much, and neither has a form in lanes that gives the same results).
  static float opacity(float x) {
    if (x < 0.125f) return opacity_series(x);
    return 1 - exp_negative(x);
  }
  /// @brief opacity() of 8 values side by side, with the same results.
  static void opacities(const float (&x)[8], float (&out)[8]) {
    Floats8 v;
    std::memcpy(&v, x, sizeof v);
    const Floats8 series = opacity_series(v), exp = 1.0f - exp_negative(v);
    const Floats8 o = v < (Floats8{} + 0.125f) ? series : exp;
    std::memcpy(out, &o, sizeof o);
  }

 private:
  using Floats8 = float __attribute__((vector_size(32)));
  using Ints8 = int32_t __attribute__((vector_size(32)));
  /// The series of 1 - exp(-x) to x^5 (F: a float, or floats in lanes).
  template <typename F>
  [[gnu::always_inline]] static F opacity_series(F x) {
    return x * (1.0f - x * (0.5f - x * (1.0f / 6 - x * (1.0f / 24 - x * (1.0f / 120)))));
  }
  /// exp(-x) for x >= 0 (Cody and Waite's reduction to 2^n exp(r), |r| <= ln 2 / 2, and a
  /// degree-7 polynomial for exp(r), as in Moshier's Cephes expf): within 2 ulp. F: a float,
  /// or floats in lanes, with the same operations in each, so the same results.
  template <typename F>
  [[gnu::always_inline]] static F exp_negative(F x) {
    const F cap = F{} + 87.0f;  // 2^n stays a normal float; exp(-87) is below float's epsilon
    x = x < cap ? x : cap;
    const F round = F{} + 12582912.0f;  // 1.5 * 2^23: adding and subtracting it rounds to a whole number
    const F n = (x * -1.44269504088896341f + round) - round;
    const F r = (-x - n * 0.693359375f) - n * -2.12194440e-4f;  // ln 2 in two parts: n ln 2 exactly
    F p = F{} + 1.9875691500e-4f;
    p = p * r + 1.3981999507e-3f;
    p = p * r + 8.3334519073e-3f;
    p = p * r + 4.1665795894e-2f;
    p = p * r + 1.6666665459e-1f;
    p = p * r + 5.0000001201e-1f;
    return (p * (r * r) + r + 1.0f) * exp2_whole(n);
  }
  /// 2^n for a whole n in [-126, 0], from its bits.
  [[gnu::always_inline]] static float exp2_whole(float n) { return std::bit_cast<float>((int32_t(n) + 127) << 23); }
  [[gnu::always_inline]] static Floats8 exp2_whole(Floats8 n) { return (Floats8)((__builtin_convertvector(n, Ints8) + 127) << 23); }

  /// Whether a segment from front to back is transparent (a NaN end is not).
  bool clear(float front, float back) const { return double(std::max(front, back)) <= clear_up_to_; }

  /// An Integral's fields side by side in one vector (tau, then ctau).
  using Row = double __attribute__((vector_size(32)));
  /// The running integrals at table position x without a branch: the position clamped into
  /// the table, interpolated between its rows, plus the end's constant extinction beyond it
  /// (times 0 inside).
  [[gnu::always_inline]] Row integral_row(double x) const {
    const double inside = std::clamp(x, 0.0, double(last_));
    const int64_t i = int64_t(inside);
    const double f = inside - double(i);
    Row a, b;
    std::memcpy(&a, &integral_[size_t(i)], sizeof a);
    std::memcpy(&b, &integral_[size_t(i) + 1], sizeof b);
    const double td = end_slope_[x > 0].tau * ((x - inside) * dv_);
    const Vec3d& c = end_slope_[x > 0].ctau;
    return a + (b - a) * f + Row{td, c.x * td, c.y * td, c.z * td};
  }

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
  static_assert(sizeof(Integral) == 4 * sizeof(double), "integral_row() reads an Integral as 4 doubles");
  /// The running integrals at table position x, continued past either end with that end's
  /// constant extinction and colour: integral_row()'s, so that segment() and segments() agree
  /// to the last bit (FMA contraction fused one form of the end's term and not another).
  Integral integral(double x) const {
    const Row v = integral_row(x);
    return {v[0], Vec3d(v[1], v[2], v[3])};
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
  std::vector<Integral> integral_;  // last_ + 2 rows: the last repeated
  std::vector<Entry> point_;
  // The extinction and colour (an Integral's fields) past the lower end [0] and the upper [1].
  Integral end_slope_[2] = {};
};

}  // namespace brickyard::gigavoxels
