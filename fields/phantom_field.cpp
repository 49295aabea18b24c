// The 3D Shepp-Logan head phantom in Hounsfield-like units: CT-shaped data with a known answer.

#include <array>
#include <cmath>

#include "fields/field_types.h"

namespace brickyard {
namespace {

/// One ellipsoid of the phantom: its density is added wherever a point lies inside it.
struct PhantomEllipsoid {
  int density;      ///< in thousandths of the skull's unit (Shepp & Logan's 2.0 is 2000)
  Vec3d semi_axes;  ///< along its own axes, before the rotation
  Vec3d center;
  double degrees;   ///< rotation about z, counter-clockwise seen from +z
};

/// Shepp & Logan (1974) head section extended to 3D as in Kak & Slaney, "Principles of
/// Computerized Tomographic Imaging" (1988), table 3.1: the skull (2.0), the brain (-0.98 of
/// it removed), two ventricles (-0.02) and six small tumours (+0.01), on [-1, 1]^3.
constexpr std::array<PhantomEllipsoid, 10> kSheppLogan = {{
    {2000, {0.6900, 0.9200, 0.810}, {0.00, 0.0000, 0.00}, 0},
    {-980, {0.6624, 0.8740, 0.780}, {0.00, -0.0184, 0.00}, 0},
    {-20, {0.1100, 0.3100, 0.220}, {0.22, 0.0000, 0.00}, -18},
    {-20, {0.1600, 0.4100, 0.280}, {-0.22, 0.0000, 0.00}, 18},
    {10, {0.2100, 0.2500, 0.410}, {0.00, 0.3500, 0.00}, 0},
    {10, {0.0460, 0.0460, 0.050}, {0.00, 0.1000, 0.00}, 0},
    {10, {0.0460, 0.0460, 0.050}, {0.00, -0.1000, 0.00}, 0},
    {10, {0.0460, 0.0230, 0.050}, {-0.08, -0.6050, 0.00}, 0},
    {10, {0.0230, 0.0230, 0.020}, {0.00, -0.6060, 0.00}, 0},
    {10, {0.0230, 0.0460, 0.020}, {0.06, -0.6050, 0.00}, 0},
}};

/// The phantom's densities as Hounsfield-like units: HU = 1000 (density - 1), so that the
/// air outside is -1000, the ventricles 0 (water), the brain 20, the tumours 10 to 40 and
/// the skull 1000. Integer everywhere (the densities are multiples of 0.01), so i16 grids
/// store it exactly.
class SheppLogan final : public FieldBase<SheppLogan> {
 public:
  explicit SheppLogan(FieldParamReader& p) {
    for (size_t i = 0; i < kSheppLogan.size(); ++i) {
      const double a = kSheppLogan[i].degrees * kPi / 180.0;
      cos_[i] = std::cos(a), sin_[i] = std::sin(a);
    }
    params_ = p.declared();
  }
  std::string_view name() const override { return "shepp-logan"; }
  Box3d domain() const override { return {Vec3d(-1.0), Vec3d(1.0)}; }
  ValueRange range() const override { return {-1000.0, 1000.0}; }
  bool integer_valued() const override { return true; }
  bool has_analytic_gradient() const override { return true; }  // zero wherever it is defined
  Vec3d gradient(const Vec3d&) const override { return {}; }

  double eval(const Vec3d& p) const {
    int density = 0;
    for (size_t i = 0; i < kSheppLogan.size(); ++i) {
      const PhantomEllipsoid& e = kSheppLogan[i];
      const Vec3d d = p - e.center;
      // Into the ellipsoid's frame: rotated back by its angle.
      const double u = (cos_[i] * d.x + sin_[i] * d.y) / e.semi_axes.x;
      const double v = (-sin_[i] * d.x + cos_[i] * d.y) / e.semi_axes.y;
      const double w = d.z / e.semi_axes.z;
      if (u * u + v * v + w * w <= 1.0) density += e.density;
    }
    return double(density - 1000);
  }

 private:
  std::array<double, kSheppLogan.size()> cos_{}, sin_{};
};

}  // namespace

std::unique_ptr<Field> make_shepp_logan(FieldParamReader& p) { return std::make_unique<SheppLogan>(p); }

}  // namespace brickyard
