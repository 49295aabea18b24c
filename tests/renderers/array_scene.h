#pragma once
// Volumes held in memory, stored for the back-end suites (stability, stiff cases): an f32
// array with unit spacing and origin 0, so world, voxel and camera coordinates coincide;
// scenes at the finest level and frames rendered with world-space cameras; and the check that
// every pixel of a frame is finite and in range.

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <span>
#include <string>
#include <vector>

#include "preprocess/builder.h"
#include "preprocess/octree_builder.h"
#include "preprocess/volume_source.h"
#include "session/render_session.h"
#include "shared_suite.h"
#include "test_util.h"

namespace brickyard::testing {

/// A volume held in memory as floats, its voxels `spacing` apart from the origin, stored as
/// `type` (an integer type takes each value converted as it is: whole numbers in its range).
class ArraySource final : public VolumeSource {
 public:
  ArraySource(const Vec3s& dims, std::vector<float> values, const Vec3d& spacing = Vec3d(1.0),
              ValueType type = ValueType::f32)
      : dims_(dims), values_(std::move(values)), spacing_(spacing), type_(type) {
    BY_CHECK(int64_t(values_.size()) == volume(dims_));
  }
  std::string name() const override { return "array"; }
  Vec3s dims() const override { return dims_; }
  Vec3d spacing() const override { return spacing_; }
  ValueType type() const override { return type_; }
  void read_slab(int64_t z0, int64_t z1, std::span<std::byte> out) override {
    const size_t slice = size_t(dims_.x * dims_.y), n = size_t(z1 - z0) * slice;
    BY_CHECK(out.size() == n * size_of(type_));
    dispatch_value_type(type_, [&](auto tag) {
      using T = decltype(tag);
      T* dst = reinterpret_cast<T*>(out.data());
      for (size_t i = 0; i < n; ++i) dst[i] = static_cast<T>(values_[size_t(z0) * slice + i]);
    });
  }
  std::string describe_json() const override { return R"({"kind":"array"})"; }

 private:
  Vec3s dims_;
  std::vector<float> values_;
  Vec3d spacing_;
  ValueType type_;
};

inline std::string build_array(const TempDir& dir, const std::string& name, const Vec3s& dims, std::vector<float> v,
                               int brick_size = 8, const Vec3d& spacing = Vec3d(1.0), ValueType type = ValueType::f32) {
  ArraySource src(dims, std::move(v), spacing, type);
  BuildOptions o;
  o.brick_size = brick_size;
  build_store(src, dir.file(name), o);
  build_octree(dir.file(name), {});  // for the back ends that read an octree volume
  return dir.file(name);
}

inline Scene make_scene(const std::string& dataset, const std::string& backend, RenderMode mode, int size) {
  Scene s;
  s.dataset = dataset;
  s.backend = backend;
  s.mode = mode;
  s.camera.keyframes = {Camera{}};
  s.width = s.height = s.camera.width = s.camera.height = size;
  s.background = Vec3f(0.1f, 0.2f, 0.3f);
  s.cache.l1_bytes = uint64_t(8) << 20;
  s.cache.l2_bytes = uint64_t(8) << 20;
  s.cache.loader_threads = 1;
  s.quality.lod_ratio = 0.01;  // full resolution for level-of-detail back ends
  return s;
}

inline Camera look(const Vec3d& eye, const Vec3d& target, const Vec3d& up = Vec3d(0, 0, 1), double fov = 30) {
  Camera c;
  c.eye = eye;
  c.target = target;
  c.up = up;
  c.fov_degrees = fov;
  return c;
}

struct Rendered {
  FrameBuffers fb;
  FrameStats stats;
  CacheStats cache;
  Camera camera;  // world space
  Box3d world;
};

/// Renders `scene`'s converged frame with a camera in world coordinates.
inline Rendered render_world(const Scene& scene, const Camera& camera) {
  RenderSession session(scene);
  FrameSetup setup = session.setup(0, FrameOutputs{.depth = true, .normals = true});
  setup.camera = camera;
  Rendered r;
  r.stats = render_settled(session, setup, r.fb);
  r.cache = session.pages().stats();
  r.camera = camera;
  r.world = session.context().geometry().world;
  return r;
}

/// Every pixel finite and in range: colour and alpha in [0, 1], depth a distance or +inf,
/// normals unit (or zero where there is none). Returns the number of pixels drawn (alpha > 0).
inline int expect_sane(const FrameBuffers& fb, const std::string& what) {
  int covered = 0, bad = 0;
  for (int y = 0; y < fb.height(); ++y)
    for (int x = 0; x < fb.width(); ++x) {
      const Rgbaf c = fb.color(x, y);
      const float depth = fb.depth(x, y);
      const Vec3f n = fb.normal(x, y);
      bool ok = true;
      for (float v : {c.r, c.g, c.b, c.a}) ok = ok && std::isfinite(v) && v >= -1e-6f && v <= 1 + 1e-5f;
      ok = ok && !std::isnan(depth) && depth >= 0;
      ok = ok && std::isfinite(n.x) && std::isfinite(n.y) && std::isfinite(n.z);
      const float len = length(n);
      ok = ok && (len == 0 || std::fabs(len - 1) < 1e-4f);
      if (c.a > 0) ++covered;
      if (!ok && bad++ < 5)
        ADD_FAILURE() << what << ": pixel (" << x << ", " << y << ") colour " << c.r << " " << c.g << " " << c.b << " "
                      << c.a << " depth " << depth << " normal " << n;
    }
  EXPECT_EQ(bad, 0) << what;
  return covered;
}

}  // namespace brickyard::testing
