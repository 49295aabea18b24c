#pragma once
// Helpers shared by the back-end tests: the scene fragments they render, session options for a
// back end with parameters, and the check that a frame holds no NaN or infinite colour.

#include <cmath>
#include <map>
#include <string>

#include <gtest/gtest.h>

#include "renderers/common/metrics.h"
#include "session/render_session.h"

namespace brickyard::testing {

/// An isosurface at 0.5 under a headlight.
inline const std::string& iso_scene() {
  static const std::string s = R"("mode": "iso", "isosurfaces": [{"value": 0.5}], "shading": {"light": "headlight"})";
  return s;
}

/// Volume rendering of the upper half of [0, 1], increasingly opaque.
inline const std::string& dvr_scene() {
  static const std::string s = R"("mode": "dvr", "transfer_function": {"points": [
      {"value": 0.55, "color": [0.2, 0.4, 0.9], "opacity": 0}, {"value": 0.8, "color": [0.9, 0.8, 0.3], "opacity": 0.3},
      {"value": 1.0, "color": [1, 0.4, 0.2], "opacity": 0.6}]})";
  return s;
}

inline RenderSession::Options backend_options(const std::string& name, std::map<std::string, double> params = {}) {
  RenderSession::Options o;
  o.backend = name;
  o.params = std::move(params);
  return o;
}

inline bool all_finite(const FrameBuffers& fb) {
  for (size_t i = 0; i < fb.color.size(); ++i) {
    const Rgbaf c = fb.color.data()[i];
    if (!std::isfinite(c.r) || !std::isfinite(c.g) || !std::isfinite(c.b) || !std::isfinite(c.a)) return false;
  }
  return true;
}

/// The reference renderer's frame of a scene, with depth and normals unless told otherwise.
inline FrameBuffers reference_frame(const Scene& scene, const FrameOutputs& outputs = {.depth = true, .normals = true}) {
  RenderSession ref(scene, backend_options("reference"));
  FrameBuffers truth;
  ref.render(0, truth, outputs);
  return truth;
}

/// Pixels where the frame hit something (a finite depth).
inline int hit_pixels(const FrameBuffers& fb) {
  int hits = 0;
  for (int y = 0; y < fb.height(); ++y)
    for (int x = 0; x < fb.width(); ++x) hits += std::isfinite(fb.depth(x, y));
  return hits;
}

/// A back end's frame at the finest level against the reference, beside raymarch's at the same
/// step (crossings refined 20 times): colour RMSE below max_rmse and at most 1.2x raymarch's
/// plus 1e-3, coverage mismatch under 0.5%, and for isosurfaces depth p99 under 0.05 voxel and
/// normals within 2 degrees on average.
inline void expect_as_good_as_raymarch(const Scene& scene, const FrameBuffers& fb, double step, double max_rmse) {
  const FrameBuffers truth = reference_frame(scene);
  RenderSession rm(scene, backend_options("raymarch", {{"step", step}, {"refine", 20}}));
  FrameBuffers baseline;
  rm.render(0, baseline, {.depth = true, .normals = true});
  const double voxel = rm.context().geometry().voxel_size;
  const ImageError e = compare_frames(fb, truth, voxel);
  const ImageError b = compare_frames(baseline, truth, voxel);
  EXPECT_LT(e.rmse, max_rmse) << e.to_json();
  EXPECT_LE(e.rmse, 1.2 * b.rmse + 1e-3) << e.to_json() << b.to_json();
  EXPECT_LT(e.coverage_mismatch_fraction, 0.005) << e.to_json();
  if (scene.mode == RenderMode::iso) {
    EXPECT_LT(e.depth_p99, 0.05) << e.to_json();
    EXPECT_LT(e.normal_mean_deg, 2.0) << e.to_json();
  }
}

}  // namespace brickyard::testing
