// Grids of several time steps, rendered: every back end draws time step K of a store of several
// exactly as it draws a store of that volume alone, in iso and DVR mode; a scene's time series
// (one session) shows each step in turn, back and forth; a step the store does not have is an
// error naming the scene's key.

#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "array_scene.h"
#include "core/error.h"
#include "preprocess/builder.h"
#include "render_test_util.h"
#include "session/render_session.h"
#include "shared_suite.h"
#include "test_util.h"

namespace brickyard {
namespace {

constexpr int kSteps = 3;
const Vec3s kDims{24, 20, 28};

/// A blob whose centre and radius move with the step: 1 at its centre, falling linearly to 0.
std::vector<float> blob(int step) {
  const Vec3d centre(8.0 + 4.0 * step, 10.0, 12.0 + 2.0 * step);
  const double radius = 7.0 + 1.5 * step;
  std::vector<float> v(size_t(volume(kDims)));
  for (int64_t z = 0; z < kDims.z; ++z)
    for (int64_t y = 0; y < kDims.y; ++y)
      for (int64_t x = 0; x < kDims.x; ++x)
        v[size_t((z * kDims.y + y) * kDims.x + x)] =
            float(std::max(0.0, 1.0 - length(Vec3d(double(x), double(y), double(z)) - centre) / radius));
  return v;
}

struct Stores {
  std::string series;
  std::vector<std::string> alone;
};

Stores build_stores(const testing::TempDir& dir) {
  Stores s;
  std::vector<std::unique_ptr<testing::ArraySource>> sources;
  std::vector<VolumeSource*> steps;
  BuildOptions o;
  o.brick_size = 8;
  for (int k = 0; k < kSteps; ++k) {
    sources.push_back(std::make_unique<testing::ArraySource>(kDims, blob(k)));
    steps.push_back(sources.back().get());
    s.alone.push_back(dir.file("alone" + std::to_string(k)));
    testing::ArraySource one(kDims, blob(k));
    build_store(one, s.alone.back(), o);
  }
  s.series = dir.file("series");
  build_series(steps, s.series, o);
  return s;
}

Scene scene_of(const std::string& dataset, const std::string& backend, RenderMode mode) {
  Scene s = testing::make_scene(dataset, backend, mode, 40);
  if (mode == RenderMode::iso) {
    s.isosurfaces = {Isosurface{0.5}};
  } else {
    s.transfer_function = TransferFunction({{0.2, {0.2f, 0.4f, 0.9f}, 0.0f}, {0.6, {0.9f, 0.8f, 0.3f}, 0.2f},
                                            {1.0, {1.0f, 0.4f, 0.2f}, 0.5f}});
  }
  s.shading.light = LightKind::headlight;
  return s;
}

const Camera kCamera = testing::look({40, -30, 35}, {11.5, 9.5, 13.5});

/// Whether two frames are the same, pixel for pixel, colour and depth.
::testing::AssertionResult same_frames(const FrameBuffers& a, const FrameBuffers& b) {
  int differ = 0, first = -1;
  for (int i = 0; i < a.width() * a.height(); ++i) {
    const Rgbaf ca = a.color.data()[i], cb = b.color.data()[i];
    const float da = a.depth.data()[i], db = b.depth.data()[i];
    const bool same = ca.r == cb.r && ca.g == cb.g && ca.b == cb.b && ca.a == cb.a && (da == db || (std::isinf(da) && std::isinf(db)));
    if (!same && first < 0) first = i;
    differ += !same;
  }
  if (differ == 0) return ::testing::AssertionSuccess();
  return ::testing::AssertionFailure() << differ << " pixels differ, the first at " << first % a.width() << ", "
                                       << first / a.width();
}

/// The back ends that render a grid from its bricks (an octree volume is built over one step).
std::vector<std::string> grid_backends(RenderMode mode) {
  std::vector<std::string> out;
  for (const std::string& name : testing::backends_for(mode)) {
    const BackendInfo& info = backends().find(name).info;
    if (std::find(info.records.begin(), info.records.end(), RecordKind::octree_page) == info.records.end()) out.push_back(name);
  }
  return out;
}

TEST(TimeSeriesRender, EveryBackEndDrawsAStepExactlyAsAStoreOfThatVolumeAlone) {
  testing::TempDir dir;
  const Stores stores = build_stores(dir);
  for (RenderMode mode : {RenderMode::iso, RenderMode::dvr}) {
    const std::vector<std::string> names = grid_backends(mode);
    ASSERT_GE(names.size(), 4u) << "raymarch, gobbetti, gigavoxels and the reference at least";
    for (const std::string& backend : names) {
      for (int k = 0; k < kSteps; ++k) {
        SCOPED_TRACE(backend + " " + std::string(to_string(mode)) + " step " + std::to_string(k));
        Scene series = scene_of(stores.series, backend, mode);
        series.time_step = k;
        const testing::Rendered a = testing::render_world(series, kCamera);
        const testing::Rendered b = testing::render_world(scene_of(stores.alone[size_t(k)], backend, mode), kCamera);
        EXPECT_GT(testing::hit_pixels(b.fb) + (mode == RenderMode::dvr ? 1 : 0), 0);
        EXPECT_TRUE(same_frames(a.fb, b.fb));
      }
    }
  }
}

TEST(TimeSeriesRender, ASceneTimeSeriesShowsEachStepInTurnInOneSession) {
  testing::TempDir dir;
  const Stores stores = build_stores(dir);
  for (const std::string backend : {"gigavoxels", "raymarch"}) {
    SCOPED_TRACE(backend);
    Scene series = scene_of(stores.series, backend, RenderMode::iso);
    series.time_step = 0;
    series.time_count = kSteps;
    RenderSession session(series);
    std::vector<FrameBuffers> alone(kSteps);
    for (int k = 0; k < kSteps; ++k) {
      RenderSession one(scene_of(stores.alone[size_t(k)], backend, RenderMode::iso));
      FrameSetup setup = one.setup(0, FrameOutputs{.depth = true});
      setup.camera = kCamera;
      testing::render_settled(one, setup, alone[size_t(k)]);
    }
    for (int frame = 0; frame < kSteps; ++frame) EXPECT_EQ(session.setup(frame).time_step, frame);
    // Steps 0, 1, 2, then 1 and 0 again: each the step's own image.
    for (int step : {0, 1, 2, 1, 0}) {
      FrameSetup setup = session.setup(step, FrameOutputs{.depth = true});
      setup.camera = kCamera;
      FrameBuffers fb;
      testing::render_settled(session, setup, fb);
      EXPECT_TRUE(same_frames(fb, alone[size_t(step)])) << "step " << step;
      EXPECT_EQ(&session.dataset().grid().nodes(), &session.store().nodes(step));
    }
  }
}

TEST(TimeSeriesRender, AStepTheStoreDoesNotHaveIsAnErrorNamingTheScenesKey) {
  testing::TempDir dir;
  const Stores stores = build_stores(dir);
  Scene s = scene_of(stores.series, "raymarch", RenderMode::iso);
  s.time_step = kSteps;
  try {
    RenderSession session(s);
    ADD_FAILURE() << "rendered a step the store does not have";
  } catch (const Error& e) {
    EXPECT_EQ(e.field(), "time_step");
    EXPECT_NE(std::string(e.what()).find("time step 3 of a dataset with 3 (0 to 2)"), std::string::npos) << e.what();
  }
  // A one-step store has only step 0.
  s = scene_of(stores.alone[0], "raymarch", RenderMode::iso);
  s.time_step = 1;
  EXPECT_THROW(RenderSession{s}, Error);
}

}  // namespace
}  // namespace brickyard
