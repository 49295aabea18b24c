// Closed-form fields: Marschner-Lobb, sphere and torus distances, gyroid.

#include <cmath>

#include <fmt/format.h>

#include "core/error.h"
#include "fields/field_types.h"

namespace brickyard {
namespace {

/// Marschner & Lobb (1994), "An evaluation of reconstruction filters for volume rendering":
/// rho(x,y,z) = (1 - sin(pi z / 2) + alpha (1 + rho_r(sqrt(x^2 + y^2)))) / (2 (1 + alpha)),
/// rho_r(r) = cos(2 pi f_M cos(pi r / 2)), on [-1,1]^3, with alpha = 0.25 and f_M = 6.
class MarschnerLobb final : public FieldBase<MarschnerLobb> {
 public:
  explicit MarschnerLobb(FieldParamReader& p)
      : alpha_(p.get("alpha", 0.25, "weight of the radial ripple")),
        fm_(p.get("fm", 6.0, "ripple frequency f_M")) {
    if (alpha_ <= 0) throw Error(Errc::invalid_argument, "alpha must be positive").with_field("alpha");
    params_ = p.declared();
  }
  std::string_view name() const override { return "marschner-lobb"; }
  Box3d domain() const override { return {Vec3d(-1.0), Vec3d(1.0)}; }
  ValueRange range() const override { return {0.0, 1.0}; }
  bool has_analytic_gradient() const override { return true; }

  double eval(const Vec3d& p) const {
    const double r = std::sqrt(p.x * p.x + p.y * p.y);
    const double rho_r = std::cos(2.0 * kPi * fm_ * std::cos(kPi * r / 2.0));
    return (1.0 - std::sin(kPi * p.z / 2.0) + alpha_ * (1.0 + rho_r)) / (2.0 * (1.0 + alpha_));
  }

  Vec3d gradient(const Vec3d& p) const override {
    const double r = std::sqrt(p.x * p.x + p.y * p.y);
    const double k = 1.0 / (2.0 * (1.0 + alpha_));
    // d rho_r / dr = pi^2 f_M sin(pi r / 2) sin(2 pi f_M cos(pi r / 2)); divided by r it stays
    // finite at r = 0, where sin(pi r/2)/r -> pi/2.
    const double sin_ratio = r > 1e-12 ? std::sin(kPi * r / 2.0) / r : kPi / 2.0;
    const double drho_over_r = kPi * kPi * fm_ * sin_ratio * std::sin(2.0 * kPi * fm_ * std::cos(kPi * r / 2.0));
    return {k * alpha_ * drho_over_r * p.x, k * alpha_ * drho_over_r * p.y,
            -k * (kPi / 2.0) * std::cos(kPi * p.z / 2.0)};
  }

 private:
  double alpha_, fm_;
};

/// Signed distance to a sphere: |p - c| - R.
class SphereSdf final : public FieldBase<SphereSdf> {
 public:
  explicit SphereSdf(FieldParamReader& p)
      : radius_(p.get("radius", 0.35, "sphere radius (domain is the unit cube)")),
        center_(p.get("cx", 0.5, "centre x"), p.get("cy", 0.5, "centre y"), p.get("cz", 0.5, "centre z")) {
    if (radius_ <= 0) throw Error(Errc::invalid_argument, "radius must be positive").with_field("radius");
    params_ = p.declared();
  }
  std::string_view name() const override { return "sphere"; }
  Box3d domain() const override { return {Vec3d(0.0), Vec3d(1.0)}; }
  ValueRange range() const override {
    // The farthest point of a box from c is one of its corners.
    const Box3d d = domain();
    const Vec3d far = max(abs(d.lo - center_), abs(d.hi - center_));
    const double nearest_inside = d.contains(center_) ? -radius_ : length(max(d.lo - center_, max(center_ - d.hi, Vec3d(0.0)))) - radius_;
    return {nearest_inside, length(far) - radius_};
  }
  bool has_analytic_gradient() const override { return true; }
  double eval(const Vec3d& p) const { return length(p - center_) - radius_; }
  Vec3d gradient(const Vec3d& p) const override { return normalize(p - center_); }

 private:
  double radius_;
  Vec3d center_;
};

/// Signed distance to a torus of major radius R and minor radius r around the z axis
/// through c: |(sqrt(dx^2 + dy^2) - R, dz)| - r.
class TorusSdf final : public FieldBase<TorusSdf> {
 public:
  explicit TorusSdf(FieldParamReader& p)
      : major_(p.get("major", 0.3, "distance from the centre to the tube's centre line")),
        minor_(p.get("minor", 0.1, "tube radius")),
        center_(p.get("cx", 0.5, "centre x"), p.get("cy", 0.5, "centre y"), p.get("cz", 0.5, "centre z")) {
    if (minor_ <= 0 || major_ <= minor_)
      throw Error(Errc::invalid_argument, fmt::format("need 0 < minor < major, got minor {} major {}", minor_, major_))
          .with_field("minor");
    params_ = p.declared();
  }
  std::string_view name() const override { return "torus"; }
  Box3d domain() const override { return {Vec3d(0.0), Vec3d(1.0)}; }
  ValueRange range() const override {
    // |q|^2 = (rho - R)^2 + dz^2 is largest at the largest |dz| and at the rho farthest from R;
    // over a box those extremes are reached at corners (largest rho) or on the axis (rho = 0).
    const Box3d d = domain();
    double hi = std::abs(0.0 - major_);
    const double dz = std::max(std::abs(d.lo.z - center_.z), std::abs(d.hi.z - center_.z));
    const double rho_max = std::hypot(std::max(std::abs(d.lo.x - center_.x), std::abs(d.hi.x - center_.x)),
                                      std::max(std::abs(d.lo.y - center_.y), std::abs(d.hi.y - center_.y)));
    hi = std::max(hi, std::abs(rho_max - major_));
    return {-minor_, std::hypot(hi, dz) - minor_};
  }
  bool has_analytic_gradient() const override { return true; }
  double eval(const Vec3d& p) const {
    const Vec3d d = p - center_;
    return std::hypot(std::hypot(d.x, d.y) - major_, d.z) - minor_;
  }
  Vec3d gradient(const Vec3d& p) const override {
    const Vec3d d = p - center_;
    const double rho = std::hypot(d.x, d.y);
    const double qx = rho - major_;
    const double q = std::hypot(qx, d.z);
    if (q == 0.0) return {};
    if (rho == 0.0) return normalize(Vec3d{0.0, 0.0, d.z});  // on the axis every radial direction ties
    return {qx / q * d.x / rho, qx / q * d.y / rho, d.z / q};
  }

 private:
  double major_, minor_;
  Vec3d center_;
};

/// Gyroid sin(wx)cos(wy) + sin(wy)cos(wz) + sin(wz)cos(wx), w = 2 pi * periods. Its level sets
/// are smooth surfaces of every orientation with a closed-form gradient: the normal-error oracle.
class Gyroid final : public FieldBase<Gyroid> {
 public:
  explicit Gyroid(FieldParamReader& p) : periods_(p.get("periods", 2.0, "periods across the unit cube")) {
    if (periods_ <= 0) throw Error(Errc::invalid_argument, "periods must be positive").with_field("periods");
    w_ = 2.0 * kPi * periods_;
    params_ = p.declared();
  }
  std::string_view name() const override { return "gyroid"; }
  Box3d domain() const override { return {Vec3d(0.0), Vec3d(1.0)}; }
  ValueRange range() const override { return {-1.5, 1.5}; }
  bool has_analytic_gradient() const override { return true; }
  double eval(const Vec3d& p) const {
    const double x = w_ * p.x, y = w_ * p.y, z = w_ * p.z;
    return std::sin(x) * std::cos(y) + std::sin(y) * std::cos(z) + std::sin(z) * std::cos(x);
  }
  Vec3d gradient(const Vec3d& p) const override {
    const double x = w_ * p.x, y = w_ * p.y, z = w_ * p.z;
    const double sx = std::sin(x), cx = std::cos(x), sy = std::sin(y), cy = std::cos(y), sz = std::sin(z),
                 cz = std::cos(z);
    return {w_ * (cx * cy - sz * sx), w_ * (-sx * sy + cy * cz), w_ * (-sy * sz + cz * cx)};
  }

 private:
  double periods_, w_ = 0.0;
};

/// A linear function a . p + b: every isosurface is a plane, exactly reproduced by linear
/// interpolation on any tetrahedral mesh and by trilinear interpolation on any grid (the
/// tetrahedral reference's exactness oracle).
class LinearField final : public FieldBase<LinearField> {
 public:
  explicit LinearField(FieldParamReader& p)
      : a_(p.get("ax", 1.0, "x coefficient"), p.get("ay", 0.5, "y coefficient"), p.get("az", 0.25, "z coefficient")),
        b_(p.get("b", 0.0, "constant term")) {
    params_ = p.declared();
  }
  std::string_view name() const override { return "linear"; }
  Box3d domain() const override { return {Vec3d(0.0), Vec3d(1.0)}; }
  ValueRange range() const override {
    double lo = b_, hi = b_;
    for (int i = 0; i < 3; ++i) lo += std::min(0.0, a_[i]), hi += std::max(0.0, a_[i]);
    return {lo, hi};
  }
  bool has_analytic_gradient() const override { return true; }
  double eval(const Vec3d& p) const { return a_.x * p.x + a_.y * p.y + a_.z * p.z + b_; }
  Vec3d gradient(const Vec3d&) const override { return a_; }

 private:
  Vec3d a_;
  double b_;
};

}  // namespace

std::unique_ptr<Field> make_linear(FieldParamReader& p) { return std::make_unique<LinearField>(p); }
std::unique_ptr<Field> make_marschner_lobb(FieldParamReader& p) { return std::make_unique<MarschnerLobb>(p); }
std::unique_ptr<Field> make_sphere_sdf(FieldParamReader& p) { return std::make_unique<SphereSdf>(p); }
std::unique_ptr<Field> make_torus_sdf(FieldParamReader& p) { return std::make_unique<TorusSdf>(p); }
std::unique_ptr<Field> make_gyroid(FieldParamReader& p) { return std::make_unique<Gyroid>(p); }

}  // namespace brickyard
