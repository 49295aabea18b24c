#pragma once
/// @file math.h
/// @brief Small fixed-size vectors, axis-aligned boxes and rays, in float, double and int.
///
/// Header-only and dependency-free so that hot loops in every layer inline them.

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <ostream>

namespace brickyard {

/// @brief Three-component vector; T is float, double or an integer type.
template <typename T>
struct Vec3 {
  T x{}, y{}, z{};

  constexpr Vec3() = default;
  constexpr Vec3(T x_, T y_, T z_) : x(x_), y(y_), z(z_) {}
  constexpr explicit Vec3(T s) : x(s), y(s), z(s) {}
  template <typename U>
  constexpr explicit Vec3(const Vec3<U>& o) : x(static_cast<T>(o.x)), y(static_cast<T>(o.y)), z(static_cast<T>(o.z)) {}

  constexpr T& operator[](int i) { return i == 0 ? x : (i == 1 ? y : z); }
  constexpr const T& operator[](int i) const { return i == 0 ? x : (i == 1 ? y : z); }

  constexpr Vec3 operator-() const { return {-x, -y, -z}; }
  constexpr Vec3& operator+=(const Vec3& o) { x += o.x; y += o.y; z += o.z; return *this; }
  constexpr Vec3& operator-=(const Vec3& o) { x -= o.x; y -= o.y; z -= o.z; return *this; }
  constexpr Vec3& operator*=(T s) { x *= s; y *= s; z *= s; return *this; }
  constexpr Vec3& operator/=(T s) { x /= s; y /= s; z /= s; return *this; }

  friend constexpr Vec3 operator+(Vec3 a, const Vec3& b) { return a += b; }
  friend constexpr Vec3 operator-(Vec3 a, const Vec3& b) { return a -= b; }
  friend constexpr Vec3 operator*(Vec3 a, T s) { return a *= s; }
  friend constexpr Vec3 operator*(T s, Vec3 a) { return a *= s; }
  friend constexpr Vec3 operator/(Vec3 a, T s) { return a /= s; }
  /// Component-wise product and quotient.
  friend constexpr Vec3 operator*(const Vec3& a, const Vec3& b) { return {a.x * b.x, a.y * b.y, a.z * b.z}; }
  friend constexpr Vec3 operator/(const Vec3& a, const Vec3& b) { return {a.x / b.x, a.y / b.y, a.z / b.z}; }
  friend constexpr bool operator==(const Vec3& a, const Vec3& b) = default;

  friend std::ostream& operator<<(std::ostream& os, const Vec3& v) {
    return os << '(' << +v.x << ", " << +v.y << ", " << +v.z << ')';
  }
};

using Vec3f = Vec3<float>;
using Vec3d = Vec3<double>;
using Vec3i = Vec3<int32_t>;
using Vec3u = Vec3<uint32_t>;
using Vec3s = Vec3<int64_t>;  ///< signed 64-bit, for voxel counts and coordinates of huge grids

template <typename T> constexpr T dot(const Vec3<T>& a, const Vec3<T>& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
template <typename T> constexpr Vec3<T> cross(const Vec3<T>& a, const Vec3<T>& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
template <typename T> T length(const Vec3<T>& v) { return std::sqrt(dot(v, v)); }
/// @brief Unit vector along v; the zero vector stays zero rather than becoming NaN.
template <typename T> Vec3<T> normalize(const Vec3<T>& v) {
  T len = length(v);
  return len > T(0) ? v / len : Vec3<T>{};
}
template <typename T> constexpr Vec3<T> min(const Vec3<T>& a, const Vec3<T>& b) {
  return {std::min(a.x, b.x), std::min(a.y, b.y), std::min(a.z, b.z)};
}
template <typename T> constexpr Vec3<T> max(const Vec3<T>& a, const Vec3<T>& b) {
  return {std::max(a.x, b.x), std::max(a.y, b.y), std::max(a.z, b.z)};
}
template <typename T> constexpr T min_component(const Vec3<T>& v) { return std::min(v.x, std::min(v.y, v.z)); }
template <typename T> constexpr T max_component(const Vec3<T>& v) { return std::max(v.x, std::max(v.y, v.z)); }
/// @brief Index (0, 1, 2) of the component with the largest magnitude: the major axis of a direction.
template <typename T> constexpr int major_axis(const Vec3<T>& v) {
  T ax = v.x < 0 ? -v.x : v.x, ay = v.y < 0 ? -v.y : v.y, az = v.z < 0 ? -v.z : v.z;
  return ax >= ay ? (ax >= az ? 0 : 2) : (ay >= az ? 1 : 2);
}
template <typename T> Vec3<T> floor(const Vec3<T>& v) { return {std::floor(v.x), std::floor(v.y), std::floor(v.z)}; }
template <typename T> Vec3<T> abs(const Vec3<T>& v) { return {std::abs(v.x), std::abs(v.y), std::abs(v.z)}; }
template <typename T> constexpr Vec3<T> lerp(const Vec3<T>& a, const Vec3<T>& b, T t) { return a + (b - a) * t; }
/// @brief Product of the components as a 64-bit count (for grid sizes); no overflow check.
template <typename T> constexpr int64_t volume(const Vec3<T>& v) {
  return int64_t(v.x) * int64_t(v.y) * int64_t(v.z);
}

/// @brief Axis-aligned box [lo, hi]. A default box is empty (lo > hi) and grows by extend().
template <typename T>
struct Box3 {
  Vec3<T> lo{std::numeric_limits<T>::max()};
  Vec3<T> hi{std::numeric_limits<T>::lowest()};

  constexpr Box3() = default;
  constexpr Box3(const Vec3<T>& lo_, const Vec3<T>& hi_) : lo(lo_), hi(hi_) {}

  constexpr bool empty() const { return lo.x > hi.x || lo.y > hi.y || lo.z > hi.z; }
  constexpr Vec3<T> extent() const { return hi - lo; }
  constexpr Vec3<T> center() const { return (lo + hi) / T(2); }
  constexpr bool contains(const Vec3<T>& p) const {
    return p.x >= lo.x && p.y >= lo.y && p.z >= lo.z && p.x <= hi.x && p.y <= hi.y && p.z <= hi.z;
  }
  constexpr bool overlaps(const Box3& b) const {
    return lo.x <= b.hi.x && b.lo.x <= hi.x && lo.y <= b.hi.y && b.lo.y <= hi.y && lo.z <= b.hi.z && b.lo.z <= hi.z;
  }
  constexpr Box3& extend(const Vec3<T>& p) { lo = min(lo, p); hi = max(hi, p); return *this; }
  constexpr Box3& extend(const Box3& b) { lo = min(lo, b.lo); hi = max(hi, b.hi); return *this; }
  constexpr Box3 intersect(const Box3& b) const { return {max(lo, b.lo), min(hi, b.hi)}; }
  friend constexpr bool operator==(const Box3& a, const Box3& b) = default;
  friend std::ostream& operator<<(std::ostream& os, const Box3& b) { return os << '[' << b.lo << " .. " << b.hi << ']'; }
};

/// @brief Distance from p to the nearest point of the box (0 inside it).
template <typename T>
T distance(const Box3<T>& box, const Vec3<T>& p) {
  return length(max(max(box.lo - p, p - box.hi), Vec3<T>(T(0))));
}

using Box3f = Box3<float>;
using Box3d = Box3<double>;
using Box3i = Box3<int32_t>;

/// @brief Ray o + t d for t in [tmin, tmax]. inv_dir is precomputed for slab tests; a zero
/// component of d gives an infinite inverse, which the slab test handles (IEEE semantics).
template <typename T>
struct Ray {
  Vec3<T> org;
  Vec3<T> dir;
  T tmin = T(0);
  T tmax = std::numeric_limits<T>::infinity();

  constexpr Ray() = default;
  constexpr Ray(const Vec3<T>& o, const Vec3<T>& d, T t0 = T(0), T t1 = std::numeric_limits<T>::infinity())
      : org(o), dir(d), tmin(t0), tmax(t1) {}
  constexpr Vec3<T> at(T t) const { return org + dir * t; }
  Vec3<T> inv_dir() const { return {T(1) / dir.x, T(1) / dir.y, T(1) / dir.z}; }
};

using Rayf = Ray<float>;
using Rayd = Ray<double>;

/// @brief Parametric interval [t0, t1] where a ray overlaps a box; t0 > t1 means a miss.
template <typename T>
struct Interval {
  T t0, t1;
  constexpr bool empty() const { return !(t0 <= t1); }
};

/// @brief Slab test. Robust to axis-parallel rays (zero direction components): the
/// 0 * inf = NaN cases are resolved by min/max ordering that ignores NaN operands.
template <typename T>
Interval<T> intersect(const Ray<T>& ray, const Box3<T>& box) {
  T t0 = ray.tmin, t1 = ray.tmax;
  for (int a = 0; a < 3; ++a) {
    T inv = T(1) / ray.dir[a];
    T tn = (box.lo[a] - ray.org[a]) * inv;
    T tf = (box.hi[a] - ray.org[a]) * inv;
    if (tn > tf) std::swap(tn, tf);
    // NaN arises when the origin lies exactly on a slab plane of a parallel ray: keep the
    // interval unchanged then, because the ray runs inside that plane.
    if (tn > t0) t0 = tn;
    if (tf < t1) t1 = tf;
  }
  return {t0, t1};
}

constexpr double kPi = 3.14159265358979323846;

/// @brief log2(x) within 2e-9 of std::log2 and inlined, for per-sample level-of-detail: the
/// exponent from the bits, the mantissa taken into [sqrt(1/2), sqrt(2)) and its log by the
/// atanh series 2/ln 2 (s + s^3/3 + ... + s^9/9), s = (y - 1)/(y + 1), |s| < 0.172 (the first
/// term left out is below 1.1e-9). Zero, subnormal, infinite and NaN inputs go to std::log2.
inline double log2_fast(double x) {
  if (!(x >= std::numeric_limits<double>::min() && x <= std::numeric_limits<double>::max())) return std::log2(x);
  uint64_t bits = std::bit_cast<uint64_t>(x);
  int exponent = int(bits >> 52) - 1023;
  double y = std::bit_cast<double>((bits & 0x000fffffffffffffull) | 0x3ff0000000000000ull);
  if (y > 1.4142135623730951) y *= 0.5, ++exponent;
  const double s = (y - 1) / (y + 1), s2 = s * s;
  return double(exponent) + 2.8853900817779268 * s * (1 + s2 * (1.0 / 3 + s2 * (1.0 / 5 + s2 * (1.0 / 7 + s2 * (1.0 / 9)))));
}

/// @brief x^n by repeated squaring: at most 2 log2(n) multiplications; as each squaring
/// doubles the relative error so far, within about n/2 ulp of the exact power (the exponent's
/// own condition number: an ulp of x moves x^n by n ulp). std::pow costs a libm call: a tenth
/// of a lit DVR sample's instructions went to it for the specular term.
constexpr double pow_uint(double x, unsigned n) {
  double r = 1;
  for (; n; n >>= 1, x *= x)
    if (n & 1) r *= x;
  return r;
}

}  // namespace brickyard
