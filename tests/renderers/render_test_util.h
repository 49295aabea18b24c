#pragma once
// Helpers shared by the back-end tests: the scene fragments they render, session options for a
// back end with parameters, and the check that a frame holds no NaN or infinite colour.

#include <cmath>
#include <map>
#include <string>

#include "renderers/common/render.h"

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

}  // namespace brickyard::testing
