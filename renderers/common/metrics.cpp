#include "renderers/common/metrics.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "core/parallel.h"

namespace brickyard {

double percentile(std::span<double> values, double p) {
  if (!(p >= 0 && p <= 100)) throw Error(Errc::invalid_argument, fmt::format("percentile {} is outside [0, 100]", p));
  if (values.empty()) return 0;
  const size_t n = values.size();
  // p * n first: exact for whole-number p, where p / 100 * n would round 99 / 100 * 100 up to 100.
  const size_t rank = std::clamp<size_t>(size_t(std::ceil(p * double(n) / 100.0)), 1, n);  // 1-based
  std::nth_element(values.begin(), values.begin() + ptrdiff_t(rank - 1), values.end());
  return values[rank - 1];
}

std::string ImageError::to_json() const {
  nlohmann::ordered_json j;
  j["rmse"] = rmse;
  if (std::isfinite(psnr_db))
    j["psnr_db"] = psnr_db;
  else
    j["psnr_db"] = nullptr;  // identical colours: infinite PSNR
  j["ssim"] = ssim;
  j["depth_mean"] = depth_mean;
  j["depth_p99"] = depth_p99;
  j["depth_max"] = depth_max;
  j["depth_pixels"] = depth_pixels;
  j["normal_mean_deg"] = normal_mean_deg;
  j["normal_p99_deg"] = normal_p99_deg;
  j["normal_pixels"] = normal_pixels;
  j["coverage_mismatch"] = coverage_mismatch;
  j["coverage_mismatch_fraction"] = coverage_mismatch_fraction;
  j["nonfinite_color_pixels"] = nonfinite_color_pixels;
  return j.dump(2);
}

namespace {

// --- per-pixel rules, shared by compare_frames and write_error_maps -------------------------

void check_frames(const FrameBuffers& test, const FrameBuffers& reference, double voxel_size) {
  if (!(voxel_size > 0) || !std::isfinite(voxel_size))
    throw Error(Errc::invalid_argument, fmt::format("voxel size must be positive and finite, not {}", voxel_size))
        .with_field("voxel_size");
  if (test.width() != reference.width() || test.height() != reference.height())
    throw Error(Errc::invalid_argument, fmt::format("cannot compare a {}x{} frame with a {}x{} reference", test.width(),
                                                    test.height(), reference.width(), reference.height()));
  for (const FrameBuffers* f : {&test, &reference}) {
    const char* which = f == &test ? "test" : "reference";
    if (!f->depth.empty() && (f->depth.width() != f->width() || f->depth.height() != f->height()))
      throw Error(Errc::invalid_argument, fmt::format("the {} frame's depth buffer is {}x{} but its colour is {}x{}", which,
                                                      f->depth.width(), f->depth.height(), f->width(), f->height()));
    if (!f->normal.empty() && (f->normal.width() != f->width() || f->normal.height() != f->height()))
      throw Error(Errc::invalid_argument, fmt::format("the {} frame's normal buffer is {}x{} but its colour is {}x{}",
                                                      which, f->normal.width(), f->normal.height(), f->width(), f->height()));
  }
}

/// Which pixels count as hits: finite depth when both frames have depth, else alpha > 1/2.
struct HitRule {
  bool use_depth;
  explicit HitRule(const FrameBuffers& a, const FrameBuffers& b) : use_depth(!a.depth.empty() && !b.depth.empty()) {}
  bool operator()(const FrameBuffers& f, size_t i) const {
    return use_depth ? std::isfinite(f.depth.data()[i]) : f.color.data()[i].a > 0.5f;
  }
};

/// Squared difference of one channel; a non-finite channel in either image counts 1 (the
/// largest difference of values in [0, 1]). NaN or infinity in x or y makes x - y non-finite.
inline double channel_sq_error(float x, float y) {
  const double d = double(x) - double(y);
  return std::isfinite(d) ? d * d : 1.0;
}

inline bool finite_rgb(const Rgbaf& c) { return std::isfinite(c.r) && std::isfinite(c.g) && std::isfinite(c.b); }

/// Sum over R, G and B of the squared differences.
inline double color_sq_error(const Rgbaf& a, const Rgbaf& b) {
  return channel_sq_error(a.r, b.r) + channel_sq_error(a.g, b.g) + channel_sq_error(a.b, b.b);
}

/// Angle between two non-zero normals in degrees (atan2 form: accurate near 0 and 180 degrees,
/// where acos of the dot product loses half its digits); 180 when either is not finite.
inline double normal_angle_deg(const Vec3f& a, const Vec3f& b) {
  const Vec3d da(a), db(b);
  const double c = length(cross(da, db)), d = dot(da, db);
  if (!std::isfinite(c) || !std::isfinite(d)) return 180.0;
  return std::atan2(c, d) * (180.0 / kPi);
}

inline bool is_zero(const Vec3f& n) { return n.x == 0 && n.y == 0 && n.z == 0; }

// --- SSIM -------------------------------------------------------------------------------------
//
// Four Gaussian-filtered planes (x, y, xy, (x - y)^2) of the two luminance images, filtered
// separably: rows first, then columns. With d = x - y, the denominators are written as
//   mu_x^2 + mu_y^2 + C1 = (2 mu_x mu_y + C1) + (mu_x - mu_y)^2
//   s_x^2 + s_y^2 + C2   = (2 s_xy + C2) + s_d^2,   s_d^2 = E[d^2] - (mu_x - mu_y)^2
// (algebraically Wang's formula), so that identical images give exactly 1 and swapping the
// images gives exactly the same value, whatever the compiler contracts into FMAs, and the
// variance of a small difference is not lost to cancellation between E[x^2] and E[y^2].
//
// Rows are processed in fixed chunks of kSsimChunkRows output rows; each chunk filters the rows
// it needs (its own and kSsimRadius above and below) horizontally into a local buffer, so
// memory is O(width) per thread, and the per-chunk sums are added in chunk order so the result
// does not depend on the thread count.

constexpr int kSsimRadius = 5;  // 11x11 window
constexpr int kSsimTaps = 2 * kSsimRadius + 1;
constexpr double kSsimSigma = 1.5;
constexpr double kSsimC1 = (0.01 * 1.0) * (0.01 * 1.0);  // (K1 L)^2
constexpr double kSsimC2 = (0.03 * 1.0) * (0.03 * 1.0);  // (K2 L)^2
constexpr int kSsimChunkRows = 32;
constexpr int kSsimPlanes = 4;

// Filtering runs in double: E[xy] - E[x] E[y] cancels, and float's 6e-8 would show against
// C2 = 9e-4 as errors of 1e-5 in SSIM.
using SsimWindow = std::array<double, kSsimTaps>;

SsimWindow ssim_window() {
  std::array<double, kSsimTaps> w{};
  double sum = 0;
  for (int k = 0; k < kSsimTaps; ++k) {
    const double d = k - kSsimRadius;
    w[k] = std::exp(-d * d / (2 * kSsimSigma * kSsimSigma));
    sum += w[k];
  }
  SsimWindow out{};
  for (int k = 0; k < kSsimTaps; ++k) out[k] = w[k] / sum;
  return out;
}

/// out[i] = sum of w[k] in[i + k - r] over the taps inside [0, n), divided by those taps'
/// weight: the window is cut at the edges and renormalised.
void filter_line(const double* in, double* out, int n, const SsimWindow& w) {
  auto edge = [&](int i) {
    double s = 0, ws = 0;
    for (int k = 0; k < kSsimTaps; ++k) {
      const int j = i + k - kSsimRadius;
      if (j >= 0 && j < n) {
        s += w[k] * in[j];
        ws += w[k];
      }
    }
    out[i] = s / ws;
  };
  if (n <= 2 * kSsimRadius) {
    for (int i = 0; i < n; ++i) edge(i);
    return;
  }
  for (int i = 0; i < kSsimRadius; ++i) edge(i);
  for (int i = n - kSsimRadius; i < n; ++i) edge(i);
  double wsum = 0;
  for (double v : w) wsum += v;
  const double inv = 1.0 / wsum;
  // Interior: tap-outer loops over contiguous i, which the compiler vectorises.
  double* o = out + kSsimRadius;
  const int m = n - 2 * kSsimRadius;
  for (int i = 0; i < m; ++i) o[i] = w[0] * in[i];
  for (int k = 1; k < kSsimTaps; ++k) {
    const double wk = w[k];
    const double* src = in + k;
    for (int i = 0; i < m; ++i) o[i] += wk * src[i];
  }
  for (int i = 0; i < m; ++i) o[i] *= inv;
}

inline double luminance(const Rgbaf& c) { return 0.2126 * c.r + 0.7152 * c.g + 0.0722 * c.b; }

/// Luminance rows of both images at row y; a non-finite luminance becomes whichever of 0 and 1
/// is farther from the other image's (both non-finite: 1 and 0).
void luminance_rows(const Image<Rgbaf>& test, const Image<Rgbaf>& ref, int y, double* lt, double* lr) {
  const Rgbaf* a = test.row(y);
  const Rgbaf* b = ref.row(y);
  for (int x = 0; x < test.width(); ++x) {
    double u = luminance(a[x]), v = luminance(b[x]);
    const bool fu = std::isfinite(u), fv = std::isfinite(v);
    if (!fu && !fv) {
      u = 1;
      v = 0;
    } else if (!fu) {
      u = v < 0.5 ? 1.0 : 0.0;
    } else if (!fv) {
      v = u < 0.5 ? 1.0 : 0.0;
    }
    lt[x] = u;
    lr[x] = v;
  }
}

/// Sum of the SSIM map over output rows [y0, y1).
double ssim_chunk_sum(const Image<Rgbaf>& test, const Image<Rgbaf>& ref, int y0, int y1, const SsimWindow& w) {
  const int width = test.width(), height = test.height();
  const int h0 = std::max(0, y0 - kSsimRadius), h1 = std::min(height, y1 + kSsimRadius);
  const size_t W = size_t(width);
  const size_t rows = size_t(h1 - h0);
  // Step 1: luminance, products and horizontal filtering of every source row the chunk needs.
  std::vector<double> h(kSsimPlanes * rows * W);
  std::vector<double> src(kSsimPlanes * W);
  for (int s = h0; s < h1; ++s) {
    double* lt = src.data();
    double* lr = lt + W;
    double* tr = lr + W;
    double* dd = tr + W;
    luminance_rows(test, ref, s, lt, lr);
    for (size_t x = 0; x < W; ++x) {
      const double d = lt[x] - lr[x];
      tr[x] = lt[x] * lr[x];
      dd[x] = d * d;
    }
    for (int q = 0; q < kSsimPlanes; ++q)
      filter_line(src.data() + size_t(q) * W, h.data() + (size_t(q) * rows + size_t(s - h0)) * W, width, w);
  }
  // Step 2: vertical filtering of each output row, then the SSIM formula per pixel.
  std::vector<double> v(kSsimPlanes * W);
  double sum = 0;
  for (int y = y0; y < y1; ++y) {
    const int k0 = std::max(0, kSsimRadius - y), k1 = std::min(kSsimTaps, height - y + kSsimRadius);
    double ws = 0;
    for (int k = k0; k < k1; ++k) ws += w[k];
    const double inv = 1.0 / ws;
    for (int q = 0; q < kSsimPlanes; ++q) {
      double* out = v.data() + size_t(q) * W;
      const double* plane = h.data() + size_t(q) * rows * W;
      const auto row_of = [&](int k) { return plane + size_t(y + k - kSsimRadius - h0) * W; };
      const double* r0 = row_of(k0);
      for (size_t x = 0; x < W; ++x) out[x] = w[k0] * r0[x];
      for (int k = k0 + 1; k < k1; ++k) {
        const double wk = w[k];
        const double* rk = row_of(k);
        for (size_t x = 0; x < W; ++x) out[x] += wk * rk[x];
      }
      for (size_t x = 0; x < W; ++x) out[x] *= inv;
    }
    const double* mx = v.data();
    const double* my = mx + W;
    const double* exy = my + W;
    const double* edd = exy + W;
    for (size_t x = 0; x < W; ++x) {
      const double a = mx[x], b = my[x], m = a - b;
      const double sxy = exy[x] - a * b, sdd = edd[x] - m * m;
      const double l_num = 2 * a * b + kSsimC1, c_num = 2 * sxy + kSsimC2;
      sum += (l_num * c_num) / ((l_num + m * m) * (c_num + sdd));
    }
  }
  return sum;
}

double mean_ssim(const Image<Rgbaf>& test, const Image<Rgbaf>& ref) {
  if (test.empty()) return 1;
  const SsimWindow w = ssim_window();
  const int chunks = (test.height() + kSsimChunkRows - 1) / kSsimChunkRows;
  std::vector<double> sums(size_t(chunks), 0.0);
  parallel_for(0, chunks, 1, [&](int c0, int c1) {
    for (int c = c0; c < c1; ++c)
      sums[size_t(c)] = ssim_chunk_sum(test, ref, c * kSsimChunkRows, std::min(test.height(), (c + 1) * kSsimChunkRows), w);
  });
  double total = 0;
  for (double s : sums) total += s;
  return total / double(test.size());
}

// --- heat maps --------------------------------------------------------------------------------

/// The colour map's top: p99 of the comparable (non-NaN) values, their maximum if that is 0, else 0.
double heat_scale(const FloatImage& error) {
  std::vector<double> values;
  values.reserve(error.size());
  for (size_t i = 0; i < error.size(); ++i)
    if (!std::isnan(error.data()[i])) values.push_back(error.data()[i]);
  if (values.empty()) return 0;
  const double p99 = percentile(values, 99);
  return p99 > 0 ? p99 : *std::max_element(values.begin(), values.end());
}

uint8_t unit_to_byte(double v) { return uint8_t(std::lround(std::clamp(v, 0.0, 1.0) * 255.0)); }

}  // namespace

ImageError compare_frames(const FrameBuffers& test, const FrameBuffers& reference, double voxel_size) {
  check_frames(test, reference, voxel_size);
  ImageError e;
  const size_t n = test.color.size();
  const HitRule hit(test, reference);
  const bool depth = !test.depth.empty() && !reference.depth.empty();
  const bool normals = !test.normal.empty() && !reference.normal.empty();

  // Step 1: one pass over the pixels for colour, coverage, depth and normal differences.
  double color_sq = 0;
  std::vector<double> depth_err, normal_err;
  if (depth) depth_err.reserve(n);
  if (normals) normal_err.reserve(n);
  for (size_t i = 0; i < n; ++i) {
    const Rgbaf& a = test.color.data()[i];
    const Rgbaf& b = reference.color.data()[i];
    color_sq += color_sq_error(a, b);
    if (!finite_rgb(a) || !finite_rgb(b)) ++e.nonfinite_color_pixels;
    const bool ha = hit(test, i), hb = hit(reference, i);
    if (ha != hb) ++e.coverage_mismatch;
    if (depth) {
      const float da = test.depth.data()[i], db = reference.depth.data()[i];
      if (std::isfinite(da) && std::isfinite(db)) depth_err.push_back(std::abs(double(da) - double(db)) / voxel_size);
    }
    if (normals) {
      const Vec3f& na = test.normal.data()[i];
      const Vec3f& nb = reference.normal.data()[i];
      if (!is_zero(na) && !is_zero(nb)) normal_err.push_back(normal_angle_deg(na, nb));
    }
  }

  // Step 2: summaries.
  if (n > 0) {
    e.rmse = std::sqrt(color_sq / (3.0 * double(n)));
    e.coverage_mismatch_fraction = double(e.coverage_mismatch) / double(n);
  }
  e.psnr_db = e.rmse > 0 ? -20.0 * std::log10(e.rmse) : std::numeric_limits<double>::infinity();
  e.depth_pixels = depth_err.size();
  if (!depth_err.empty()) {
    double s = 0;
    for (double d : depth_err) s += d;
    e.depth_mean = s / double(depth_err.size());
    e.depth_max = *std::max_element(depth_err.begin(), depth_err.end());
    e.depth_p99 = percentile(depth_err, 99);
  }
  e.normal_pixels = normal_err.size();
  if (!normal_err.empty()) {
    double s = 0;
    for (double d : normal_err) s += d;
    e.normal_mean_deg = s / double(normal_err.size());
    e.normal_p99_deg = percentile(normal_err, 99);
  }

  // Step 3: SSIM, the only part that is more than a few operations per pixel.
  e.ssim = mean_ssim(test.color, reference.color);
  return e;
}

Rgba8 error_colormap(double t) {
  // Matt Zucker's degree-6 fit to matplotlib's inferno (https://www.shadertoy.com/view/WlfXRN, CC0).
  static constexpr double c[7][3] = {
      {0.0002189403691192265, 0.001651004631001012, -0.01948089843709184},
      {0.1065134194856116, 0.5639564367884091, 3.932712388889277},
      {11.60249308247187, -3.972853965665698, -15.9423941062914},
      {-41.70399613139459, 17.43639888205313, 44.35414519872813},
      {77.162935699427, -33.40235894210092, -81.80730925738993},
      {-71.31942824499214, 32.62606426397723, 73.20951985803202},
      {25.13112622477341, -12.24266895238567, -23.07032500287172},
  };
  t = std::isnan(t) ? 0.0 : std::clamp(t, 0.0, 1.0);
  double rgb[3];
  for (int ch = 0; ch < 3; ++ch) {
    double v = c[6][ch];
    for (int k = 5; k >= 0; --k) v = c[k][ch] + t * v;
    rgb[ch] = v;
  }
  return {unit_to_byte(rgb[0]), unit_to_byte(rgb[1]), unit_to_byte(rgb[2]), 255};
}

ImageRGBA8 colorize_error(const FloatImage& error, double scale) {
  ImageRGBA8 out(error.width(), error.height(), kNoDataGrey);
  for (size_t i = 0; i < error.size(); ++i) {
    const float e = error.data()[i];
    if (std::isnan(e)) continue;
    const double t = scale > 0 ? double(e) / scale : (e > 0 ? 1.0 : 0.0);
    out.data()[i] = error_colormap(t);
  }
  return out;
}

ErrorMaps write_error_maps(const FrameBuffers& test, const FrameBuffers& reference, double voxel_size,
                           const std::string& prefix) {
  check_frames(test, reference, voxel_size);
  ErrorMaps maps;
  const int w = test.width(), h = test.height();
  const size_t n = test.color.size();
  const float nan = std::numeric_limits<float>::quiet_NaN();

  // Colour: per-pixel RMS over R, G, B, comparable everywhere.
  {
    FloatImage err(w, h);
    for (size_t i = 0; i < n; ++i)
      err.data()[i] = float(std::sqrt(color_sq_error(test.color.data()[i], reference.color.data()[i]) / 3.0));
    maps.color_scale = heat_scale(err);
    maps.paths.push_back(prefix + "-color.png");
    write_png(maps.paths.back(), colorize_error(err, maps.color_scale));
  }
  if (!test.depth.empty() && !reference.depth.empty()) {
    FloatImage err(w, h, nan);
    for (size_t i = 0; i < n; ++i) {
      const float a = test.depth.data()[i], b = reference.depth.data()[i];
      if (std::isfinite(a) && std::isfinite(b)) err.data()[i] = float(std::abs(double(a) - double(b)) / voxel_size);
    }
    maps.depth_scale_voxels = heat_scale(err);
    maps.paths.push_back(prefix + "-depth.png");
    write_png(maps.paths.back(), colorize_error(err, maps.depth_scale_voxels));
  }
  if (!test.normal.empty() && !reference.normal.empty()) {
    FloatImage err(w, h, nan);
    for (size_t i = 0; i < n; ++i) {
      const Vec3f& a = test.normal.data()[i];
      const Vec3f& b = reference.normal.data()[i];
      if (!is_zero(a) && !is_zero(b)) err.data()[i] = float(normal_angle_deg(a, b));
    }
    maps.normal_scale_deg = heat_scale(err);
    maps.paths.push_back(prefix + "-normal.png");
    write_png(maps.paths.back(), colorize_error(err, maps.normal_scale_deg));
  }
  {
    const HitRule hit(test, reference);
    ImageRGBA8 img(w, h, kNoDataGrey);
    for (size_t i = 0; i < n; ++i) {
      const bool a = hit(test, i), b = hit(reference, i);
      if (a && b) {
        img.data()[i] = kBothHitGrey;
      } else if (a) {
        img.data()[i] = kTestOnlyColor;
        ++maps.test_only;
      } else if (b) {
        img.data()[i] = kReferenceOnlyColor;
        ++maps.reference_only;
      }
    }
    maps.paths.push_back(prefix + "-coverage.png");
    write_png(maps.paths.back(), img);
  }
  return maps;
}

}  // namespace brickyard
