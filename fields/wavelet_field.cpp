// VTK's wavelet (vtkRTAnalyticSource), so that one dataset and one isovalue can be run through
// VTK and through brickyard side by side.

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

#include "core/error.h"
#include "fields/field_types.h"

namespace brickyard {
namespace {

/// vtkRTAnalyticSource (VTK's Imaging/Core/vtkRTAnalyticSource.cxx) at the point p of
/// [-1/2, 1/2]^3:
///   M exp(-(x^2 + y^2 + z^2) / (2 sigma^2)) + XMag sin(XFreq x) + YMag sin(YFreq y) + ZMag cos(ZFreq z)
/// with (x, y, z) = -p. VTK normalises each axis by its whole extent,
/// x = (Center[0] - i) / (WholeExtent[1] - WholeExtent[0]), so a VTK image whose centre sits in
/// the middle of its extent spans exactly [-1/2, 1/2] on every axis whatever its size, and x
/// falls as the index rises: hence the sign. An axis of one sample is x = 0 in both.
///
/// Equivalence (see docs/fields.md): `generate wavelet --size NX,NY,NZ --type f32` is bit for
/// bit the RTData of vtkRTAnalyticSource with SetWholeExtent(0, NX-1, 0, NY-1, 0, NZ-1) and
/// SetCenter((NX-1)/2, (NY-1)/2, (NZ-1)/2); for odd N that is VTK's default centre 0 with
/// WholeExtent -(N-1)/2..(N-1)/2, and N = 21 is VTK's untouched default source.
class Wavelet final : public FieldBase<Wavelet> {
 public:
  explicit Wavelet(FieldParamReader& p)
      : maximum_(p.get("maximum", 255.0, "height of the Gaussian at the centre (VTK Maximum)")),
        sigma_(p.get("standard_deviation", 0.5, "Gaussian width, in units of the domain's edge (VTK StandardDeviation)")),
        xfreq_(p.get("xfreq", 60.0, "frequency of the x sine, radians per domain edge (VTK XFreq)")),
        yfreq_(p.get("yfreq", 30.0, "frequency of the y sine (VTK YFreq)")),
        zfreq_(p.get("zfreq", 40.0, "frequency of the z cosine (VTK ZFreq)")),
        xmag_(p.get("xmag", 10.0, "amplitude of the x sine (VTK XMag)")),
        ymag_(p.get("ymag", 18.0, "amplitude of the y sine (VTK YMag)")),
        zmag_(p.get("zmag", 5.0, "amplitude of the z cosine (VTK ZMag)")) {
    // VTK would divide by zero here and fill the image with NaN and infinities.
    if (!(sigma_ > 0.0))
      throw Error(Errc::invalid_argument,
                  fmt::format("parameter 'standard_deviation' of field 'wavelet' must be positive, not {}", sigma_))
          .with_field("standard_deviation");
    inv_two_sigma2_ = 1.0 / (2.0 * sigma_ * sigma_);  // VTK's temp2, rounded as VTK rounds it
    params_ = p.declared();
  }
  std::string_view name() const override { return "wavelet"; }
  Box3d domain() const override { return {Vec3d(-0.5), Vec3d(0.5)}; }
  bool has_analytic_gradient() const override { return true; }

  ValueRange range() const override {
    // Each term's exact range over the domain, summed in eval's order (rounding is monotonic,
    // so the rounded sum of the bounds bounds the rounded sum). The terms depend on different
    // axes, so the sine part's bound is reached; only the Gaussian couples them.
    const double r2_max = 0.75;  // the corners
    // 1e-12 covers a sample that rounding puts a few ulps beyond a face.
    const double g_far = maximum_ * std::exp(-r2_max * inv_two_sigma2_) * (1.0 - 1e-12);
    const ValueRange g{std::min(maximum_, g_far), std::max(maximum_, g_far)};
    const ValueRange x = sine_term_range(xmag_, xfreq_), y = sine_term_range(ymag_, yfreq_);
    const ValueRange z = cosine_term_range(zmag_, zfreq_);
    return {g.lo + x.lo + y.lo + z.lo, g.hi + x.hi + y.hi + z.hi};
  }

  double eval(const Vec3d& p) const {
    const double x = -p.x, y = -p.y, z = -p.z;
    // VTK's order of operations, so that the float it stores is the float VTK stores. What is
    // left (our coordinates are -1/2 + i h, VTK's (c - i) h; the compiler may fuse a
    // multiply-add) moves the double by an ulp at most, which the float rounding absorbs: no
    // sample of 256^3 differs.
    const double r2 = (z * z + y * y) + x * x;
    // VTK keeps each sine term in a float (xfactor, yfactor, zfactor) before the sum; rounding
    // them the same way is what makes f32 grids bit-identical rather than off by one ulp in a
    // few percent of samples. It leaves steps of half a float ulp of each magnitude (about 1e-6
    // at the defaults) in value(), far below anything a renderer resolves.
    const float xf = static_cast<float>(xmag_ * std::sin(xfreq_ * x));
    const float yf = static_cast<float>(ymag_ * std::sin(yfreq_ * y));
    const float zf = static_cast<float>(zmag_ * std::cos(zfreq_ * z));
    return maximum_ * std::exp(-r2 * inv_two_sigma2_) + xf + yf + zf;
  }

  /// The gradient of the exact formula (without the float rounding of the terms).
  Vec3d gradient(const Vec3d& p) const override {
    const double x = -p.x, y = -p.y, z = -p.z;
    const double g = maximum_ * std::exp(-((z * z + y * y) + x * x) * inv_two_sigma2_);
    // d/dp = -d/dx: the Gaussian's -2 x g / (2 sigma^2) and the sines' derivatives flip sign.
    return {2.0 * inv_two_sigma2_ * x * g - xmag_ * xfreq_ * std::cos(xfreq_ * x),
            2.0 * inv_two_sigma2_ * y * g - ymag_ * yfreq_ * std::cos(yfreq_ * y),
            2.0 * inv_two_sigma2_ * z * g + zmag_ * zfreq_ * std::sin(zfreq_ * z)};
  }

 private:
  // Over the domain the argument f x spans [-|f|/2, |f|/2].
  static ValueRange sine_term_range(double mag, double freq) {
    const double a = std::abs(freq) / 2.0;
    if (a >= kPi / 2.0) return float_range(-std::abs(mag), std::abs(mag), false, false);  // a crest is inside
    const double s = std::abs(mag) * std::sin(a);
    return float_range(-s, s, true, true);
  }
  static ValueRange cosine_term_range(double mag, double freq) {
    const double a = std::abs(freq) / 2.0;
    const bool trough_inside = a >= kPi;
    const double c_min = trough_inside ? -1.0 : std::cos(a);  // the maximum, cos 0 = 1, is exact
    if (mag >= 0.0) return float_range(mag * c_min, mag, !trough_inside, false);
    return float_range(mag, mag * c_min, false, !trough_inside);
  }
  // The bounds as eval's float terms can reach them. Rounding to nearest is monotonic, so the
  // rounded bounds hold; a bound that comes from sin(a) or cos(a) at the interval's end also
  // moves one float ulp outwards, since libm is accurate to an ulp but not promised monotonic.
  static ValueRange float_range(double lo, double hi, bool widen_lo, bool widen_hi) {
    float flo = static_cast<float>(lo), fhi = static_cast<float>(hi);
    if (widen_lo) flo = std::nextafter(flo, -HUGE_VALF);
    if (widen_hi) fhi = std::nextafter(fhi, HUGE_VALF);
    return {flo, fhi};
  }

  double maximum_, sigma_, xfreq_, yfreq_, zfreq_, xmag_, ymag_, zmag_;
  double inv_two_sigma2_ = 0.0;
};

}  // namespace

std::unique_ptr<Field> make_wavelet(FieldParamReader& p) { return std::make_unique<Wavelet>(p); }

}  // namespace brickyard
