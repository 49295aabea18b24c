#pragma once
/// @file frame.h
/// @brief What a renderer produces: colour, depth and normal buffers of one frame, and the
/// statistics of how it got there.
///
/// Conventions shared by every back end, the reference renderer and the error metrics:
/// - colour is linear RGB in [0, 1], already composited over the scene's background; alpha is
///   the pixel's coverage (accumulated opacity for DVR, 1 for a surface hit, 0 for a miss);
/// - depth is the distance from the eye along the primary ray, in world units, +infinity
///   where the ray hits nothing (for DVR and MIP: where accumulated opacity first reaches 1/2,
///   and where the maximum lies, respectively);
/// - normals are unit world-space vectors facing the eye, (0, 0, 0) where there is no hit or
///   where the frame did not ask for normals.

#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "core/image.h"
#include "core/math.h"

namespace brickyard {

struct Rgbaf {
  float r = 0, g = 0, b = 0, a = 0;
  friend constexpr bool operator==(const Rgbaf&, const Rgbaf&) = default;
};

/// @brief Which optional buffers a frame fills. Colour is always produced; a buffer not asked
/// for costs nothing (normals are computed only when shading or this flag needs them).
struct FrameOutputs {
  bool depth = true;
  bool normals = false;
};

struct FrameBuffers {
  Image<Rgbaf> color;
  FloatImage depth;     ///< empty when FrameOutputs::depth was false
  Image<Vec3f> normal;  ///< empty when FrameOutputs::normals was false

  FrameBuffers() = default;
  FrameBuffers(int width, int height, const FrameOutputs& outputs)
      : color(width, height),
        depth(outputs.depth ? width : 0, outputs.depth ? height : 0, std::numeric_limits<float>::infinity()),
        normal(outputs.normals ? width : 0, outputs.normals ? height : 0) {}
  int width() const { return color.width(); }
  int height() const { return color.height(); }
};

/// @brief Counters a tile accumulates while it renders; summed over tiles per frame.
struct RayCounters {
  uint64_t rays = 0;           ///< primary rays
  uint64_t samples = 0;        ///< field reconstructions (trilinear or analytic evaluations)
  uint64_t cells = 0;          ///< grid cells intersected (the reference's cubic solves)
  uint64_t nodes = 0;          ///< node-table entries tested (empty-space skipping, traversal)
  uint64_t bricks = 0;         ///< brick visits (a ray entering a brick it samples)
  uint64_t gradients = 0;      ///< gradient evaluations (shading, normals)
  uint64_t shadow_rays = 0;
  uint64_t lookups = 0, hits = 0, misses = 0;  ///< cache accesses made by the tile

  RayCounters& operator+=(const RayCounters& o);
};

struct PhaseTime {
  std::string name;
  double seconds = 0;
};

/// @brief Statistics of one frame: where the time went, what the rays did, what the cache did.
struct FrameStats {
  int frame = 0;
  int width = 0, height = 0;
  int threads = 0;                 ///< threads the frame's arena allows
  int tile_threads = 0;            ///< distinct threads that rendered its tiles
  double seconds = 0;              ///< the whole frame, wall clock
  std::vector<PhaseTime> phases;   ///< e.g. prepare, render, finish
  RayCounters counters;
  // from the cache, for this frame
  uint64_t requests = 0;        ///< distinct brick requests posted
  uint64_t uploads = 0;         ///< bricks uploaded into the L1 pool
  uint64_t stalls = 0;          ///< blocking fetches that waited for a load
  uint64_t bytes_read = 0;      ///< compressed bytes read from the store
  uint64_t bytes_decoded = 0;
  uint64_t unreadable = 0;      ///< records found unreadable so far (corrupt or missing): drawn around, never retried

  /// Figures particular to the back end (working set, index size, culled nodes), by name.
  std::vector<std::pair<std::string, double>> backend;
  /// Why the frame was delivered below the quality the scene asked for, empty when it was not:
  /// what the back end ran short of that more frames will not bring (a pool too small for the
  /// cut it wants, exact mode out of passes). A frame still refining as its data arrives is not
  /// below it. Reasons are joined by "; ".
  std::string below_quality;

  double phase(const std::string& name) const;
  double backend_value(const std::string& name) const;
  void add_phase(const std::string& name, double seconds);
  /// @brief Adds a reason to below_quality.
  void add_below_quality(const std::string& reason);
  std::string to_json() const;
};

/// @brief A frame rendered at `factor` times its width and height, brought to its own size:
/// a pixel's colour and alpha are the mean of its factor x factor sub-pixels (a box filter),
/// its depth and normal those of the middle sub-pixel, whose ray is the pixel's centre ray.
/// `factor` is odd so that such a sub-pixel exists; a depth or normal averaged across a
/// silhouette would be neither surface's. The image a pixel should show is the mean over
/// its area, which renderers that filter by their footprint (mipmaps) approximate and a
/// single centre ray aliases.
FrameBuffers resolve_supersampled(const FrameBuffers& fine, int factor);

/// @brief Colour as 8-bit RGBA (opaque), rounding to nearest: for PNG output.
ImageRGBA8 to_rgba8(const Image<Rgbaf>& color);
/// @brief Depth as grey (near bright, far dark, misses black), scaled over the finite range.
ImageRGBA8 depth_to_rgba8(const FloatImage& depth);
/// @brief Normals mapped from [-1, 1] to [0, 255] per component; no hit is black.
ImageRGBA8 normals_to_rgba8(const Image<Vec3f>& normal);

}  // namespace brickyard
