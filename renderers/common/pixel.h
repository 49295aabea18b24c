#pragma once
/// @file pixel.h
/// @brief What every back end does around a pixel's ray, shared so that back ends differ only
/// in how they sample: the primary ray in voxel coordinates and the span it overlaps the
/// rendered region, the pixel's result written into whichever buffers the frame has, and
/// the colour of a MIP maximum.

#include <algorithm>
#include <cmath>
#include <limits>

#include "renderers/common/renderer.h"

namespace brickyard {

/// @brief A pixel's result before it is written.
struct PixelResult {
  Vec3f color;
  float alpha = 0;
  double depth = std::numeric_limits<double>::infinity();
  Vec3d normal{0.0};
};

/// @brief The primary ray of a pixel: world ray (unit direction), the same ray in voxel
/// coordinates (same parameter t: world distance), and the span inside the rendered region.
struct PrimaryRay {
  Rayd world;
  Vec3d org, dir;  ///< voxel coordinates
  Interval<double> span;
  /// @brief Whether the ray overlaps the region. A ray without a direction (eye = target)
  /// has an unbounded span and sees nothing.
  bool hits() const { return !span.empty() && std::isfinite(span.t1); }
};

inline PrimaryRay primary_ray(const ImageRays& rays, const VolumeGeometry& geo, int x, int y) {
  PrimaryRay r;
  r.world = rays.ray(x + 0.5, y + 0.5);
  r.org = geo.to_voxel(r.world.org);
  r.dir = r.world.dir / geo.spacing;
  r.span = intersect(Rayd(r.org, r.dir), geo.voxel_clip);
  r.span.t0 = std::max(r.span.t0, 0.0);
  return r;
}

inline void write_pixel(FrameBuffers& out, int x, int y, const PixelResult& p) {
  out.color(x, y) = {p.color.x, p.color.y, p.color.z, p.alpha};
  if (!out.depth.empty()) out.depth(x, y) = float(p.depth);
  if (!out.normal.empty()) out.normal(x, y) = Vec3f(p.normal);
}

/// @brief The colour of a MIP maximum: the transfer function's colour over the background by
/// its opacity, or without a transfer function grey over the store's value range.
inline void mip_color(const RenderContext& ctx, double value, PixelResult& p) {
  const Scene& scene = ctx.scene();
  Vec3f c;
  float a = 1;
  if (!scene.transfer_function.empty()) {
    scene.transfer_function.eval(value, c, a);
  } else {
    const double lo = ctx.dataset().min_value, hi = ctx.dataset().max_value;
    c = Vec3f(float(hi > lo ? std::clamp((value - lo) / (hi - lo), 0.0, 1.0) : 1.0));
  }
  p.color = c * a + scene.background * (1 - a);
  p.alpha = a;
}

}  // namespace brickyard
