#pragma once
/// @file metrics.h
/// @brief Error metrics of a rendered frame against a reference frame, and heat maps of them.
///
/// Everything here compares two FrameBuffers that follow frame.h's conventions. The rules
/// for pixels that cannot be compared, and for broken input, are part of the contract:
/// - colour is compared at every pixel (it is already composited over the background);
/// - depth is compared where both frames hit (finite depth in both); NaN depth counts as a
///   miss, so it shows up as a coverage mismatch where the other frame hits;
/// - normals are compared where both are non-zero; a normal with a non-finite component
///   counts as 180 degrees off;
/// - "hit" is finite depth when both frames have depth buffers, otherwise alpha > 1/2 in both;
/// - a non-finite colour channel (NaN or infinity, in either image) never makes a metric NaN:
///   it counts as the largest error, 1 for that channel in the RMSE, and for SSIM the pixel's
///   luminance becomes whichever of 0 and 1 lies farther from the other image's. Such pixels
///   are counted in ImageError::nonfinite_color_pixels so they are never hidden.
///
/// All functions are pure (no state); compare_frames runs its SSIM pass in parallel through
/// core/parallel.h and returns the same result whatever the thread count.

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "core/image.h"
#include "renderers/common/frame.h"

namespace brickyard {

/// @brief How far a test frame is from a reference frame.
struct ImageError {
  double rmse = 0;     ///< colour RMSE over R, G and B of all pixels, values in [0, 1]
  /// 20 log10(1 / rmse) in dB; +infinity when the colours are identical (rmse = 0).
  /// to_json() writes that infinity as null.
  double psnr_db = 0;
  /// Mean SSIM (Wang et al. 2004) of linear Rec. 709 luminance, L = 1, K1 = 0.01, K2 = 0.03,
  /// 11x11 Gaussian window with sigma 1.5, one value per pixel: near the border the window is
  /// cut at the image edge and its weights renormalised (so images smaller than the window
  /// work, down to 1x1), where Wang's reference code crops the 5-pixel border instead.
  /// Computed in double; exactly 1 for identical colours and exactly symmetric in the frames.
  double ssim = 1;
  double depth_mean = 0, depth_p99 = 0, depth_max = 0;  ///< |depth difference| in voxels where both hit
  double normal_mean_deg = 0, normal_p99_deg = 0;       ///< angle between normals where both are non-zero
  uint64_t depth_pixels = 0, normal_pixels = 0;         ///< pixels the depth / normal figures cover
  uint64_t coverage_mismatch = 0;                       ///< pixels hit by exactly one of the frames
  double coverage_mismatch_fraction = 0;                ///< coverage_mismatch over all pixels
  uint64_t nonfinite_color_pixels = 0;                  ///< pixels with a NaN/inf RGB channel in either frame

  /// @brief One JSON object with the fields above under their own names (psnr_db is null when
  /// infinite).
  std::string to_json() const;
};

/// @brief Compares `test` against `reference`. voxel_size (world units per voxel, > 0)
/// converts depth differences to voxels. Depth figures need both depth buffers, normal figures
/// both normal buffers; otherwise they stay 0 with 0 pixels. Throws Error(invalid_argument)
/// when the frames' sizes differ, a buffer's size differs from its frame's colour buffer, or
/// voxel_size is not a positive finite number.
ImageError compare_frames(const FrameBuffers& test, const FrameBuffers& reference, double voxel_size);

/// @brief Where write_error_maps put its images and what their colour scales mean.
struct ErrorMaps {
  std::vector<std::string> paths;  ///< the files written, in the order colour, depth, normal, coverage
  /// Error at the top of each colour map (larger errors saturate): the 99th percentile of the
  /// error over comparable pixels, or its maximum when that percentile is 0; 0 when there is
  /// no error at all (then every comparable pixel has the bottom colour). 0 for a map not written.
  double color_scale = 0;          ///< per-pixel RMS of the R, G, B differences, in [0, 1] units
  double depth_scale_voxels = 0;
  double normal_scale_deg = 0;
  uint64_t test_only = 0, reference_only = 0;  ///< coverage map: pixels hit only by that frame
};

/// @brief Writes heat maps of the errors compare_frames measures as PNGs named PREFIX-color.png
/// (per-pixel RMS RGB difference), PREFIX-depth.png (voxels), PREFIX-normal.png (degrees) and
/// PREFIX-coverage.png. The first three use error_colormap() from 0 to their scale; pixels
/// that cannot be compared (no hit in one or both frames) are kNoDataGrey. The coverage map
/// shows pixels hit only by the test frame in kTestOnlyColor, only by the reference in
/// kReferenceOnlyColor, by both in kBothHitGrey and by neither in kNoDataGrey. Maps whose
/// buffers are absent from either frame are skipped. Same errors as compare_frames, and
/// Error(io) when a file cannot be written.
ErrorMaps write_error_maps(const FrameBuffers& test, const FrameBuffers& reference, double voxel_size,
                           const std::string& prefix);

inline constexpr Rgba8 kNoDataGrey{48, 48, 48, 255};
inline constexpr Rgba8 kBothHitGrey{128, 128, 128, 255};
inline constexpr Rgba8 kTestOnlyColor{230, 159, 0, 255};       ///< orange (Okabe-Ito)
inline constexpr Rgba8 kReferenceOnlyColor{86, 180, 233, 255};  ///< sky blue (Okabe-Ito)

/// @brief The 'inferno' colour map (black, purple, orange, pale yellow; lightness rises
/// monotonically) at t in [0, 1], clamped outside, from Matt Zucker's public-domain degree-6
/// polynomial fit to matplotlib's table. Output is sRGB-encoded, ready for a PNG.
Rgba8 error_colormap(double t);

/// @brief error / scale through error_colormap(), saturating at 1; NaN pixels (not
/// comparable) become kNoDataGrey. scale 0 maps 0 to the bottom colour and anything above
/// it to the top.
ImageRGBA8 colorize_error(const FloatImage& error, double scale);

/// @brief The p-th percentile (p in [0, 100]) by nearest rank: the ceil(p/100 * n)-th smallest
/// value (the smallest for p = 0), so the result is always one of the values. Reorders
/// `values` (std::nth_element, O(n) on average). 0 for no values. NaNs must not be present.
double percentile(std::span<double> values, double p);

}  // namespace brickyard
