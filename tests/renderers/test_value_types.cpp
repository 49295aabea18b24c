// Signed and unsigned integer stores against their float conversion, over every back end: a
// store of i8 or i16 voxels must render the image the same values stored as f32 render (the
// conversion is exact, so only the interpolation's rounding may differ), and a CT-like head
// whose air an automatic background made empty must render unchanged where it is visible.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include "array_scene.h"
#include "preprocess/builder.h"
#include "renderers/common/metrics.h"

namespace brickyard {
namespace {

using testing::backends_for;
using testing::build_array;
using testing::expect_sane;
using testing::look;
using testing::make_scene;
using testing::render_world;

/// A CT-like head on n^3 voxels in Hounsfield-like units scaled by `scale` (1 for i16, 1/10
/// for i8): air -1000 with a few units of deterministic noise, a skull shell of bone (+1000)
/// around soft tissue (+40), every value a whole number.
std::vector<float> ct_head(int n, double scale) {
  std::vector<float> v;
  const double c = 0.5 * (n - 1), r = 0.42 * (n - 1);
  for (int z = 0; z < n; ++z)
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x) {
        const double d = std::hypot(x - c, 1.15 * (y - c), z - c) / r;
        const uint32_t h = (uint32_t(x) * 73856093u) ^ (uint32_t(y) * 19349663u) ^ (uint32_t(z) * 83492791u);
        const double noise = double(int(h % 17u) - 8);
        double hu = -1000 + noise;
        if (d < 1.0) hu = d > 0.82 ? 1000 + 4 * noise : 40 + noise;
        v.push_back(float(std::round(hu * scale)));
      }
  return v;
}

const Camera kView = look({-22, -30, 46}, {15.5, 15.5, 15.5}, {0, 0, 1}, 40);

Scene scene_for(const std::string& store, const std::string& backend, RenderMode mode, double scale) {
  Scene s = make_scene(store, backend, mode, 40);
  s.shading.light = LightKind::headlight;
  if (mode == RenderMode::iso) {
    s.isosurfaces = {Isosurface{500 * scale}};
  } else {
    // Air transparent, tissue faint, bone opaque: what a user draws of a CT.
    s.transfer_function = TransferFunction({{-300 * scale, Vec3f(0.8f, 0.4f, 0.3f), 0.0f},
                                            {100 * scale, Vec3f(0.8f, 0.4f, 0.3f), 0.05f},
                                            {1200 * scale, Vec3f(1.0f, 1.0f, 0.9f), 0.8f}});
  }
  return s;
}

TEST(ValueTypes, EveryBackEndRendersSignedIntegersAsTheirFloatConversion) {
  testing::TempDir dir;
  const int n = 32;
  for (const auto& [type, scale] : {std::pair{ValueType::i16, 1.0}, std::pair{ValueType::i8, 0.1}}) {
    const std::vector<float> values = ct_head(n, scale);
    const std::string name(to_string(type));
    const std::string stored = build_array(dir, name, {n, n, n}, values, 8, Vec3d(1.0), type);
    const std::string floats = build_array(dir, name + "-f32", {n, n, n}, values, 8);
    EXPECT_EQ(Store(stored).format().type, type);
    EXPECT_EQ(Store(stored).manifest().min_value, *std::min_element(values.begin(), values.end()));
    for (RenderMode mode : {RenderMode::iso, RenderMode::dvr})
      for (const std::string& backend : backends_for(mode)) {
        const std::string what = backend + " " + name + " " + std::string(to_string(mode));
        SCOPED_TRACE(what);
        const auto a = render_world(scene_for(stored, backend, mode, scale), kView);
        const auto b = render_world(scene_for(floats, backend, mode, scale), kView);
        EXPECT_GT(expect_sane(a.fb, what), 300);
        const ImageError e = compare_frames(a.fb, b.fb, 1.0);
        EXPECT_LT(e.rmse, 2e-3) << e.to_json();
      }
  }
}

TEST(ValueTypes, AirMadeEmptyByAnAutomaticBackgroundRendersUnchanged) {
  testing::TempDir dir;
  const int n = 32;
  const std::vector<float> values = ct_head(n, 1.0);
  auto build = [&](const std::string& name, bool automatic) {
    testing::ArraySource src({n, n, n}, values, Vec3d(1.0), ValueType::i16);
    BuildOptions o;
    o.brick_size = 8;
    if (automatic) o.background_auto = true, o.constant_tolerance = 40;
    build_store(src, dir.file(name), o);
    build_octree(dir.file(name), {});
    return dir.file(name);
  };
  const std::string plain = build("plain", false), empty_air = build("air", true);
  const Manifest m = Store(empty_air).manifest();
  EXPECT_NEAR(m.background, -1000, 8);
  EXPECT_EQ(Store(plain).manifest().stats.back().empty, 0);
  EXPECT_GT(m.stats.back().empty, 0);
  for (RenderMode mode : {RenderMode::iso, RenderMode::dvr})
    for (const std::string& backend : backends_for(mode)) {
      const std::string what = backend + " " + std::string(to_string(mode));
      SCOPED_TRACE(what);
      const auto a = render_world(scene_for(empty_air, backend, mode, 1.0), kView);
      const auto b = render_world(scene_for(plain, backend, mode, 1.0), kView);
      EXPECT_GT(expect_sane(a.fb, what), 300);
      const ImageError e = compare_frames(a.fb, b.fb, 1.0);
      EXPECT_LT(e.rmse, 2e-3) << e.to_json();
    }
}

}  // namespace
}  // namespace brickyard
