#include "renderers/common/frame.h"

#include <algorithm>
#include <cmath>

#include <nlohmann/json.hpp>

#include "core/error.h"

namespace brickyard {

RayCounters& RayCounters::operator+=(const RayCounters& o) {
  rays += o.rays;
  samples += o.samples;
  cells += o.cells;
  nodes += o.nodes;
  bricks += o.bricks;
  gradients += o.gradients;
  shadow_rays += o.shadow_rays;
  lookups += o.lookups;
  hits += o.hits;
  misses += o.misses;
  return *this;
}

double FrameStats::phase(const std::string& name) const {
  for (const auto& p : phases)
    if (p.name == name) return p.seconds;
  return 0;
}

double FrameStats::backend_value(const std::string& name) const {
  for (const auto& [n, v] : backend)
    if (n == name) return v;
  return 0;
}

void FrameStats::add_phase(const std::string& name, double s) {
  for (auto& p : phases)
    if (p.name == name) {
      p.seconds += s;
      return;
    }
  phases.push_back({name, s});
}

void FrameStats::add_below_quality(const std::string& reason) {
  below_quality += (below_quality.empty() ? "" : "; ") + reason;
}

FrameBuffers resolve_supersampled(const FrameBuffers& fine, int factor) {
  BY_CHECK(factor >= 1 && factor % 2 == 1);
  BY_CHECK(fine.width() % factor == 0 && fine.height() % factor == 0);
  const int w = fine.width() / factor, h = fine.height() / factor, middle = factor / 2;
  FrameOutputs outputs;
  outputs.depth = !fine.depth.empty();
  outputs.normals = !fine.normal.empty();
  FrameBuffers out(w, h, outputs);
  const double weight = 1.0 / double(factor * factor);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      double sum[4] = {0, 0, 0, 0};
      for (int j = 0; j < factor; ++j)
        for (int i = 0; i < factor; ++i) {
          const Rgbaf& c = fine.color(factor * x + i, factor * y + j);
          sum[0] += c.r, sum[1] += c.g, sum[2] += c.b, sum[3] += c.a;
        }
      out.color(x, y) = {float(sum[0] * weight), float(sum[1] * weight), float(sum[2] * weight), float(sum[3] * weight)};
      const int cx = factor * x + middle, cy = factor * y + middle;
      if (outputs.depth) out.depth(x, y) = fine.depth(cx, cy);
      if (outputs.normals) out.normal(x, y) = fine.normal(cx, cy);
    }
  return out;
}

std::string FrameStats::to_json() const {
  nlohmann::ordered_json j;
  j["frame"] = frame;
  j["width"] = width;
  j["height"] = height;
  j["threads"] = threads;
  j["tile_threads"] = tile_threads;
  j["seconds"] = seconds;
  nlohmann::ordered_json ph = nlohmann::ordered_json::object();
  for (const auto& p : phases) ph[p.name] = p.seconds;
  j["phases"] = ph;
  nlohmann::ordered_json be = nlohmann::ordered_json::object();
  for (const auto& [name, value] : backend) be[name] = value;
  j["backend"] = be;
  j["below_quality"] = below_quality.empty() ? nlohmann::ordered_json(nullptr) : nlohmann::ordered_json(below_quality);
  const RayCounters& c = counters;
  j["rays"] = c.rays;
  j["samples"] = c.samples;
  j["cells"] = c.cells;
  j["nodes"] = c.nodes;
  j["bricks"] = c.bricks;
  j["gradients"] = c.gradients;
  j["shadow_rays"] = c.shadow_rays;
  j["rays_per_second"] = seconds > 0 ? double(c.rays) / seconds : 0.0;
  j["rays_per_second_per_thread"] = seconds > 0 && threads > 0 ? double(c.rays) / seconds / threads : 0.0;
  j["cache"] = {{"lookups", c.lookups}, {"hits", c.hits},       {"misses", c.misses},
                {"requests", requests}, {"uploads", uploads},   {"stalls", stalls},
                {"bytes_read", bytes_read}, {"bytes_decoded", bytes_decoded}, {"unreadable", unreadable}};
  return j.dump(2);
}

namespace {
uint8_t to_byte(float v) {
  if (!(v > 0)) return 0;  // NaN maps to 0 too
  if (v >= 1) return 255;
  return uint8_t(std::lround(v * 255.0f));
}
}  // namespace

ImageRGBA8 to_rgba8(const Image<Rgbaf>& color) {
  ImageRGBA8 out(color.width(), color.height());
  for (size_t i = 0; i < color.size(); ++i) {
    const Rgbaf& c = color.data()[i];
    out.data()[i] = {to_byte(c.r), to_byte(c.g), to_byte(c.b), 255};
  }
  return out;
}

ImageRGBA8 depth_to_rgba8(const FloatImage& depth) {
  float lo = std::numeric_limits<float>::infinity(), hi = -lo;
  for (size_t i = 0; i < depth.size(); ++i)
    if (std::isfinite(depth.data()[i])) {
      lo = std::min(lo, depth.data()[i]);
      hi = std::max(hi, depth.data()[i]);
    }
  ImageRGBA8 out(depth.width(), depth.height(), Rgba8{0, 0, 0, 255});
  const float span = hi > lo ? hi - lo : 1.0f;
  for (size_t i = 0; i < depth.size(); ++i) {
    const float d = depth.data()[i];
    if (!std::isfinite(d)) continue;
    const uint8_t g = to_byte(1.0f - 0.8f * (d - lo) / span);  // near: white, far: dark grey
    out.data()[i] = {g, g, g, 255};
  }
  return out;
}

ImageRGBA8 normals_to_rgba8(const Image<Vec3f>& normal) {
  ImageRGBA8 out(normal.width(), normal.height(), Rgba8{0, 0, 0, 255});
  for (size_t i = 0; i < normal.size(); ++i) {
    const Vec3f n = normal.data()[i];
    if (n == Vec3f(0.0f)) continue;
    out.data()[i] = {to_byte(0.5f * (n.x + 1)), to_byte(0.5f * (n.y + 1)), to_byte(0.5f * (n.z + 1)), 255};
  }
  return out;
}

}  // namespace brickyard
