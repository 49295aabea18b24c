// Scenes: every key of scenes/example.json read back, relative paths, camera paths, and the
// errors a user meets (each names the file and the key path); back-end parameters; the
// transfer function and its summed-area table.

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "core/error.h"
#include "session/render_session.h"
#include "renderers/common/renderer.h"
#include "renderers/common/scene.h"
#include "renderers/common/transfer_function.h"
#include "test_util.h"

namespace brickyard {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

const std::string kSourceDir = BRICKYARD_SOURCE_DIR;

/// The smallest valid scene around `extra` members (a JSON fragment starting with a comma, or "").
std::string scene_json(const std::string& extra, const std::string& camera = R"("camera": {"eye": [2, -1, 1.5], "target": [0.5, 0.5, 0.5]})") {
  return R"({"dataset": "vol.store", )" + camera + R"(, "isosurfaces": [{"value": 0.5}])" + extra + "}";
}

/// The Error that parse_scene throws for `text`, or a failure if it throws none.
Error parse_error(const std::string& text, const std::string& file = "/scenes/bad.json") {
  try {
    parse_scene(text, file);
  } catch (const Error& e) {
    return e;
  }
  ADD_FAILURE() << "no error for " << text;
  return Error(Errc::internal, "no error");
}

void expect_vec(const Vec3d& v, double x, double y, double z) {
  EXPECT_DOUBLE_EQ(v.x, x);
  EXPECT_DOUBLE_EQ(v.y, y);
  EXPECT_DOUBLE_EQ(v.z, z);
}
void expect_vec(const Vec3f& v, float x, float y, float z) {
  EXPECT_FLOAT_EQ(v.x, x);
  EXPECT_FLOAT_EQ(v.y, y);
  EXPECT_FLOAT_EQ(v.z, z);
}

// --- valid scenes --------------------------------------------------------------------------

TEST(Scene, ExampleSceneReadsEveryDocumentedKey) {
  const std::string file = kSourceDir + "/scenes/example.json";
  const Scene s = load_scene(file);
  EXPECT_EQ(s.file, file);
  EXPECT_EQ(s.dataset, (fs::path(kSourceDir) / "scenes" / "../out/demo/default.store").lexically_normal().string());
  EXPECT_EQ(s.backend, "raymarch");
  ASSERT_EQ(s.backend_params.size(), 1u);
  EXPECT_DOUBLE_EQ(s.backend_params.at("step"), 0.5);
  EXPECT_EQ(s.width, 512);
  EXPECT_EQ(s.height, 512);
  EXPECT_FALSE(s.has_path);
  EXPECT_EQ(s.frames(), 1);
  ASSERT_EQ(s.camera.keyframes.size(), 1u);
  EXPECT_EQ(s.camera.width, 512);
  EXPECT_EQ(s.camera.height, 512);
  const Camera& c = s.camera.keyframes[0];
  expect_vec(c.eye, 1.7, -0.9, 1.3);
  expect_vec(c.target, 0.5, 0.5, 0.45);
  expect_vec(c.up, 0, 0, 1);
  EXPECT_DOUBLE_EQ(c.fov_degrees, 35);
  EXPECT_FALSE(s.normalized_values);  // "values": "stored"
  EXPECT_EQ(s.mode, RenderMode::dvr);
  ASSERT_EQ(s.isosurfaces.size(), 1u);
  EXPECT_DOUBLE_EQ(s.isosurfaces[0].value, 0.5);
  expect_vec(s.isosurfaces[0].color, 0.95f, 0.75f, 0.35f);
  const auto& pts = s.transfer_function.points();
  ASSERT_EQ(pts.size(), 5u);
  const double values[] = {0.0, 0.55, 0.70, 0.85, 1.0};
  const float opacities[] = {0.0f, 0.0f, 0.08f, 0.30f, 0.60f};
  for (size_t i = 0; i < 5; ++i) {
    EXPECT_DOUBLE_EQ(pts[i].value, values[i]) << i;
    EXPECT_FLOAT_EQ(pts[i].opacity, opacities[i]) << i;
  }
  expect_vec(pts[2].color, 0.30f, 0.80f, 0.70f);
  EXPECT_DOUBLE_EQ(s.sampling_rate, 1.0);
  EXPECT_EQ(s.shading.light, LightKind::point);
  expect_vec(s.shading.light_position, 1.5, -1.0, 2.0);
  expect_vec(s.shading.light_color, 1, 1, 1);
  EXPECT_EQ(s.shading.normals, NormalMethod::central);
  EXPECT_FALSE(s.shading.shadows);
  EXPECT_FLOAT_EQ(s.shading.ambient, 0.2f);
  EXPECT_FLOAT_EQ(s.shading.diffuse, 0.7f);
  EXPECT_FLOAT_EQ(s.shading.specular, 0.2f);
  EXPECT_FLOAT_EQ(s.shading.shininess, 24);
  ASSERT_TRUE(s.clip.has_value());
  expect_vec(s.clip->lo, 0, 0, 0);
  expect_vec(s.clip->hi, 1, 1, 0.75);
  expect_vec(s.background, 0.06f, 0.06f, 0.08f);
  EXPECT_DOUBLE_EQ(s.quality.lod_ratio, 1.0);
  EXPECT_DOUBLE_EQ(s.quality.step_factor, 1.0);
  EXPECT_DOUBLE_EQ(s.quality.termination_opacity, 0.99);
  EXPECT_EQ(s.cache.l1_bytes, uint64_t(128) << 20);
  EXPECT_EQ(s.cache.l2_bytes, uint64_t(512) << 20);
  EXPECT_EQ(s.cache.l1_policy, "lru");
  EXPECT_EQ(s.cache.l2_policy, "lru");
  EXPECT_EQ(s.cache.loader_threads, 2);
}

TEST(Scene, TheShippedScenesParse) {
  for (const char* name : {"default-iso.json", "default-dvr.json"}) {
    const Scene s = load_scene(kSourceDir + "/scenes/" + name);
    EXPECT_EQ(s.backend, "raymarch") << name;
    EXPECT_EQ(s.width, 512) << name;
  }
  int scenes = 0;
  for (const auto& entry : fs::directory_iterator(kSourceDir + "/scenes")) {
    if (entry.path().extension() != ".json") continue;
    if (entry.path().filename().string().rfind("flight-", 0) == 0) continue;  // camera paths for brickyard flight
    SCOPED_TRACE(entry.path().string());
    EXPECT_NO_THROW(load_scene(entry.path().string()));
    ++scenes;
  }
  EXPECT_GE(scenes, 10);
}

TEST(Scene, EveryKeyTakesANonDefaultValue) {
  // Comments of both kinds, every key set to something other than its default.
  const std::string text = R"(
    // a full scene
    {
      "$schema": "ignored", "description": "everything",
      "dataset": "/data/vol.store",
      "backend": { "name": "reference", "params": { "step": 0.25, "analytic": 1 } },
      "image": { "width": 320, "height": 200 },  /* block comment */
      "camera": { "eye": [0.1, 0.2, 3], "target": [0.4, 0.5, 0.6], "up": [0, 1, 0], "fov_degrees": 20 },
      "values": "normalized",
      "mode": "iso",
      "isosurfaces": [ { "value": -1.5, "color": [1, 0, 0] }, { "value": 2, "color": [0, 0.5, 1] },
                       { "value": 3 }, { "value": 4.25, "color": [0, 0, 0] } ],
      "transfer_function": { "points": [ { "value": 0, "opacity": 0 }, { "value": 1, "color": [0.5, 0.25, 0], "opacity": 1 } ] },
      "sampling_rate": 2.5,
      "time_step": 3,
      "shading": { "light": "directional", "light_position": [1, 2, 3], "light_direction": [0, 0, -1],
                   "light_color": [0.5, 0.6, 0.7], "normals": "forward", "shadows": true,
                   "ambient": 0.05, "diffuse": 0.5, "specular": 0.75, "shininess": 7 },
      "clip": { "lo": [0.1, 0.2, 0.3], "hi": [0.9, 0.8, 0.7] },
      "background": [1, 1, 1],
      "quality": { "lod_ratio": 2, "step_factor": 0.5, "termination_opacity": 0.9 },
      "cache": { "l1": "16MiB", "l2": 1048576, "l1_policy": "clock", "l2_policy": "s3fifo", "loader_threads": 5 }
    })";
  const Scene s = parse_scene(text, "/elsewhere/full.json");
  EXPECT_EQ(s.dataset, "/data/vol.store");  // absolute: as given
  EXPECT_EQ(s.backend, "reference");
  EXPECT_DOUBLE_EQ(s.backend_params.at("step"), 0.25);
  EXPECT_DOUBLE_EQ(s.backend_params.at("analytic"), 1);
  EXPECT_EQ(s.width, 320);
  EXPECT_EQ(s.height, 200);
  EXPECT_EQ(s.camera.width, 320);
  EXPECT_EQ(s.camera.height, 200);
  expect_vec(s.camera.keyframes.at(0).eye, 0.1, 0.2, 3);
  expect_vec(s.camera.keyframes.at(0).up, 0, 1, 0);
  EXPECT_DOUBLE_EQ(s.camera.keyframes.at(0).fov_degrees, 20);
  EXPECT_TRUE(s.normalized_values);
  EXPECT_EQ(s.mode, RenderMode::iso);
  ASSERT_EQ(s.isosurfaces.size(), 4u);
  EXPECT_DOUBLE_EQ(s.isosurfaces[0].value, -1.5);
  expect_vec(s.isosurfaces[1].color, 0, 0.5f, 1);
  expect_vec(s.isosurfaces[2].color, 0.9f, 0.9f, 0.9f);  // the default colour
  EXPECT_DOUBLE_EQ(s.isosurfaces[3].value, 4.25);
  ASSERT_EQ(s.transfer_function.points().size(), 2u);
  expect_vec(s.transfer_function.points()[0].color, 1, 1, 1);  // the default colour
  EXPECT_DOUBLE_EQ(s.sampling_rate, 2.5);
  EXPECT_EQ(s.time_step, 3);
  EXPECT_EQ(s.shading.light, LightKind::directional);
  expect_vec(s.shading.light_position, 1, 2, 3);
  expect_vec(s.shading.light_direction, 0, 0, -1);
  expect_vec(s.shading.light_color, 0.5f, 0.6f, 0.7f);
  EXPECT_EQ(s.shading.normals, NormalMethod::forward);
  EXPECT_TRUE(s.shading.shadows);
  EXPECT_TRUE(s.shading.casts_shadows());
  EXPECT_FLOAT_EQ(s.shading.ambient, 0.05f);
  EXPECT_FLOAT_EQ(s.shading.diffuse, 0.5f);
  EXPECT_FLOAT_EQ(s.shading.specular, 0.75f);
  EXPECT_FLOAT_EQ(s.shading.shininess, 7);
  expect_vec(s.clip->lo, 0.1, 0.2, 0.3);
  expect_vec(s.clip->hi, 0.9, 0.8, 0.7);
  expect_vec(s.background, 1, 1, 1);
  EXPECT_DOUBLE_EQ(s.quality.lod_ratio, 2);
  EXPECT_DOUBLE_EQ(s.quality.step_factor, 0.5);
  EXPECT_DOUBLE_EQ(s.quality.termination_opacity, 0.9);
  EXPECT_EQ(s.cache.l1_bytes, uint64_t(16) << 20);
  EXPECT_EQ(s.cache.l2_bytes, 1048576u);
  EXPECT_EQ(s.cache.l1_policy, "clock");
  EXPECT_EQ(s.cache.l2_policy, "s3fifo");
  EXPECT_EQ(s.cache.loader_threads, 5);
}

TEST(Scene, DefaultsWhenOnlyTheRequiredKeysAreGiven) {
  const Scene s = parse_scene(scene_json(""), "s.json");
  EXPECT_EQ(s.backend, "raymarch");
  EXPECT_TRUE(s.backend_params.empty());
  EXPECT_EQ(s.width, 512);
  EXPECT_EQ(s.mode, RenderMode::iso);
  EXPECT_FALSE(s.normalized_values);
  EXPECT_EQ(s.shading.light, LightKind::headlight);
  EXPECT_EQ(s.shading.normals, NormalMethod::analytic);
  EXPECT_FALSE(s.shading.shadows);
  EXPECT_FALSE(s.clip.has_value());
  EXPECT_DOUBLE_EQ(s.camera.keyframes.at(0).fov_degrees, 45);
  expect_vec(s.camera.keyframes.at(0).up, 0, 0, 1);
  EXPECT_TRUE(s.transfer_function.empty());
  const Scene named = parse_scene(scene_json(R"(, "backend": "reference")"), "s.json");
  EXPECT_EQ(named.backend, "reference");  // a plain string names the back end alone
  EXPECT_TRUE(named.backend_params.empty());
}

TEST(Scene, CacheBudgetsAreByteCountsZeroIncluded) {
  // Whether a budget holds one page of the store is the session's to judge (it knows the
  // page's size and names the key): the scene reads any count of bytes, as a number or text.
  const Scene s = parse_scene(scene_json(R"(, "cache": {"l1": 0, "l2": "0"})"), "s.json");
  EXPECT_EQ(s.cache.l1_bytes, 0u);
  EXPECT_EQ(s.cache.l2_bytes, 0u);
  const Scene t = parse_scene(scene_json(R"(, "cache": {"l1": "157215", "l2": 157216})"), "s.json");
  EXPECT_EQ(t.cache.l1_bytes, 157215u);
  EXPECT_EQ(t.cache.l2_bytes, 157216u);
}

TEST(Scene, RelativeDatasetResolvesAgainstTheSceneFilesDirectory) {
  auto dataset_of = [](const std::string& dataset, const std::string& file) {
    return parse_scene(R"({"dataset": ")" + dataset + R"(", "camera": {"eye": [2, 0, 0], "target": [0, 0, 0]},
                           "isosurfaces": [{"value": 1}]})",
                       file)
        .dataset;
  };
  EXPECT_EQ(dataset_of("vol.store", "/a/b/scene.json"), "/a/b/vol.store");
  EXPECT_EQ(dataset_of("../stores/vol.store", "/a/b/scene.json"), "/a/stores/vol.store");
  EXPECT_EQ(dataset_of("./x/../vol.store", "/a/b/scene.json"), "/a/b/vol.store");
  EXPECT_EQ(dataset_of("/abs/vol.store", "/a/b/scene.json"), "/abs/vol.store");
  EXPECT_EQ(dataset_of("vol.store", "rel/scene.json"), "rel/vol.store");
  EXPECT_EQ(dataset_of("vol.store", "scene.json"), "vol.store");
  EXPECT_EQ(dataset_of("vol.store", ""), "vol.store");  // a scene built in code: the working directory

  // load_scene resolves the same way as parse_scene.
  testing::TempDir dir;
  fs::create_directories(dir.path() / "scenes");
  const std::string file = (dir.path() / "scenes" / "s.json").string();
  std::ofstream(file) << R"({"dataset": "../v.store", "camera": {"eye": [2, 0, 0], "target": [0, 0, 0]}, "isosurfaces": [{"value": 1}]})";
  EXPECT_EQ(load_scene(file).dataset, (dir.path() / "v.store").string());
}

TEST(Scene, ATimeSeriesCyclesItsStepsOverTheFrames) {
  const Scene still = parse_scene(scene_json(R"(, "time_step": 2)"), "s.json");
  EXPECT_EQ(still.frames(), 1);
  EXPECT_EQ(still.step_of(0), 2);
  EXPECT_EQ(still.step_of(5), 2);
  const Scene series = parse_scene(scene_json(R"(, "time_series": {"first": 1, "count": 3})"), "s.json");
  EXPECT_EQ(series.frames(), 3);  // a still camera: one frame a step
  EXPECT_EQ(series.step_of(0), 1);
  EXPECT_EQ(series.step_of(2), 3);
  EXPECT_EQ(series.step_of(3), 1);
  const Scene path = parse_scene(scene_json("", R"("camera_path": {"frames": 7, "keyframes": [
      {"eye": [2, 0, 0], "target": [0.5, 0.5, 0.5]}, {"eye": [0, 2, 0], "target": [0.5, 0.5, 0.5]}]},
      "time_series": {"count": 2})"),
                                 "s.json");
  EXPECT_EQ(path.frames(), 7);  // the path's frames, the steps starting again
  EXPECT_EQ(path.step_of(6), 0);
  EXPECT_EQ(path.step_of(5), 1);
}

TEST(Scene, CameraPathInline) {
  const Scene s = parse_scene(scene_json("", R"("camera_path": { "frames": 7, "fov_degrees": 30, "keyframes": [
      { "eye": [2, 0, 0], "target": [0.5, 0.5, 0.5] },
      { "eye": [0, 2, 0], "target": [0.5, 0.5, 0.5], "up": [0, 1, 1], "fov_degrees": 60 } ] })"),
                              "/x/p.json");
  EXPECT_TRUE(s.has_path);
  EXPECT_EQ(s.frames(), 7);
  ASSERT_EQ(s.camera.keyframes.size(), 2u);
  EXPECT_DOUBLE_EQ(s.camera.keyframes[0].fov_degrees, 30);  // the path's
  EXPECT_DOUBLE_EQ(s.camera.keyframes[1].fov_degrees, 60);  // its own
  expect_vec(s.camera.keyframes[1].eye, 0, 2, 0);
  expect_vec(s.camera.keyframes[1].up, 0, 1, 1);
  EXPECT_EQ(s.camera.width, 512);
  // The first and last frames are the end keyframes.
  expect_vec(s.camera.at(0).eye, 2, 0, 0);
  expect_vec(s.camera.at(6).eye, 0, 2, 0);
}

TEST(Scene, CameraPathFromAFileRelativeToTheScene) {
  testing::TempDir dir;
  fs::create_directories(dir.path() / "paths");
  std::ofstream(dir.file("paths/orbit.json")) << R"(// a flight
    {"frames": 12, "image": {"width": 64, "height": 48},
     "camera_path": {"fov_degrees": 50, "keyframes": [
        {"eye": [2, 0.5, 0.5], "target": [0.5, 0.5, 0.5]},
        {"eye": [0.5, 2, 0.5], "target": [0.5, 0.5, 0.5]},
        {"eye": [-1, 0.5, 0.5], "target": [0.5, 0.5, 0.5]}]}})";
  const Scene s = parse_scene(scene_json(R"(, "image": {"width": 100, "height": 80})", R"("camera_path": "paths/orbit.json")"),
                              dir.file("scene.json"));
  EXPECT_TRUE(s.has_path);
  EXPECT_EQ(s.frames(), 12);
  ASSERT_EQ(s.camera.keyframes.size(), 3u);
  expect_vec(s.camera.keyframes[2].eye, -1, 0.5, 0.5);
  EXPECT_DOUBLE_EQ(s.camera.keyframes[0].fov_degrees, 50);
  EXPECT_EQ(s.camera.width, 100);  // the scene's image, not the path file's
  EXPECT_EQ(s.camera.height, 80);

  // The shipped flight, as scenes/example.json suggests.
  const Scene flight = parse_scene(scene_json("", R"("camera_path": "flight-orbit.json")"), kSourceDir + "/scenes/mine.json");
  EXPECT_EQ(flight.frames(), 120);
  EXPECT_EQ(flight.camera.keyframes.size(), 6u);
}

TEST(Scene, NormalizedValuesMapOntoTheStoresRange) {
  Scene s = parse_scene(scene_json(R"(, "values": "normalized", "isosurfaces": [{"value": 0.25}, {"value": 1}],
      "transfer_function": {"points": [{"value": 0, "opacity": 0}, {"value": 0.5, "opacity": 0}, {"value": 1, "opacity": 0.5}]})"),
                        "s.json");
  ASSERT_TRUE(s.normalized_values);
  normalize_values(s, 10, 30);
  EXPECT_FALSE(s.normalized_values);
  EXPECT_DOUBLE_EQ(s.isosurfaces[0].value, 15);
  EXPECT_DOUBLE_EQ(s.isosurfaces[1].value, 30);
  ASSERT_EQ(s.transfer_function.points().size(), 3u);
  EXPECT_DOUBLE_EQ(s.transfer_function.points()[1].value, 20);
  EXPECT_FALSE(s.transfer_function.visible(10, 19.9));  // the table follows the points
  EXPECT_TRUE(s.transfer_function.visible(25, 26));
  normalize_values(s, 0, 1000);  // mapped once only
  EXPECT_DOUBLE_EQ(s.isosurfaces[0].value, 15);

  Scene stored = parse_scene(scene_json(R"(, "isosurfaces": [{"value": 0.25}])"), "s.json");
  normalize_values(stored, 10, 30);
  EXPECT_DOUBLE_EQ(stored.isosurfaces[0].value, 0.25);
}

TEST(Scene, ValueRangeVisibilityFollowsTheMode) {
  Scene iso = parse_scene(scene_json(R"(, "isosurfaces": [{"value": 0.5}, {"value": 2}])"), "s.json");
  EXPECT_TRUE(iso.value_range_visible(0.0, 1.0));
  EXPECT_TRUE(iso.value_range_visible(0.5, 0.5));
  EXPECT_TRUE(iso.value_range_visible(1.5, 3.0));
  EXPECT_FALSE(iso.value_range_visible(0.6, 1.9));
  EXPECT_FALSE(iso.value_range_visible(2.1, 9.0));
  Scene dvr = iso;
  dvr.mode = RenderMode::dvr;
  dvr.transfer_function = TransferFunction({{0.0, Vec3f(1.0f), 0.0f}, {0.5, Vec3f(1.0f), 0.0f}, {1.0, Vec3f(1.0f), 1.0f}});
  EXPECT_FALSE(dvr.value_range_visible(0.1, 0.4));
  EXPECT_TRUE(dvr.value_range_visible(0.1, 0.6));
  Scene mip = iso;
  mip.mode = RenderMode::mip;
  EXPECT_TRUE(mip.value_range_visible(0.6, 1.9));
}

// --- errors: each names the file and the key path ------------------------------------------

struct BadScene {
  const char* name;
  std::string text;
  std::vector<std::string> mentions;  // besides the file name
};

void PrintTo(const BadScene& b, std::ostream* os) { *os << b.name; }

class SceneRejects : public ::testing::TestWithParam<BadScene> {};

TEST_P(SceneRejects, NamingTheFileAndTheKey) {
  const BadScene& bad = GetParam();
  const Error e = parse_error(bad.text, "/scenes/bad-scene.json");
  EXPECT_EQ(e.file(), "/scenes/bad-scene.json") << e.what();
  EXPECT_THAT(e.what(), HasSubstr("bad-scene.json"));
  for (const std::string& m : bad.mentions) EXPECT_THAT(e.what(), HasSubstr(m));
  EXPECT_NE(e.code(), Errc::internal) << e.what();
}

const std::string kCam = R"("camera": {"eye": [2, -1, 1.5], "target": [0.5, 0.5, 0.5]})";
const std::string kTf = R"("transfer_function": {"points": [{"value": 0, "opacity": 0}, {"value": 1, "opacity": 0.5}]})";

INSTANTIATE_TEST_SUITE_P(
    Scene, SceneRejects,
    ::testing::Values(
        // unknown keys, top level and nested, with the known keys listed
        BadScene{"TimeStepAndTimeSeries", scene_json(R"(, "time_step": 1, "time_series": {"count": 2})"),
                 {"'time_series'", "not both"}},
        BadScene{"EmptyTimeSeries", scene_json(R"(, "time_series": {"count": 0})"), {"'time_series.count'"}},
        BadScene{"UnknownTimeSeriesKey", scene_json(R"(, "time_series": {"last": 3})"), {"'time_series.last'", "unknown key"}},
        BadScene{"UnknownTopLevelKey", scene_json(R"(, "colour": [1, 0, 0])"), {"'colour'", "unknown key", "'background'"}},
        BadScene{"MisspelledShadingKey", scene_json(R"(, "shading": {"ligth": "point"})"), {"'shading.ligth'", "unknown key", "'light'"}},
        BadScene{"UnknownIsosurfaceKey", scene_json(R"(, "isosurfaces": [{"value": 1}, {"value": 2, "colour": [1, 0, 0]}])"),
                 {"'isosurfaces[1].colour'", "unknown key"}},
        BadScene{"UnknownCameraKey", scene_json("", R"("camera": {"eye": [2, 0, 0], "target": [0, 0, 0], "fov": 30})"), {"'camera.fov'"}},
        BadScene{"UnknownImageKey", scene_json(R"(, "image": {"width": 64, "heigth": 64})"), {"'image.heigth'"}},
        BadScene{"UnknownQualityKey", scene_json(R"(, "quality": {"lod": 1})"), {"'quality.lod'"}},
        BadScene{"UnknownCacheKey", scene_json(R"(, "cache": {"l3": "1GiB"})"), {"'cache.l3'"}},
        BadScene{"UnknownClipKey", scene_json(R"(, "clip": {"lo": [0, 0, 0], "hi": [1, 1, 1], "mid": [0, 0, 0]})"), {"'clip.mid'"}},
        BadScene{"UnknownBackendKey", scene_json(R"(, "backend": {"name": "raymarch", "parms": {}})"), {"'backend.parms'"}},
        BadScene{"UnknownTransferFunctionPointKey",
                 scene_json(R"(, "mode": "dvr", "transfer_function": {"points": [{"value": 0, "opacity": 0, "alpha": 1}]})"),
                 {"'transfer_function.points[0].alpha'"}},
        BadScene{"UnknownCameraPathKey",
                 scene_json("", R"("camera_path": {"frame": 3, "keyframes": [{"eye": [2, 0, 0], "target": [0, 0, 0]}]})"),
                 {"'camera_path.frame'"}},
        BadScene{"UnknownKeyframeKey",
                 scene_json("", R"("camera_path": {"keyframes": [{"eye": [2, 0, 0], "target": [0, 0, 0]}, {"eye": [2, 0, 0], "traget": [0, 0, 0]}]})"),
                 {"'camera_path.keyframes[1]"}},
        // wrong types
        BadScene{"WidthIsAString", scene_json(R"(, "image": {"width": "512"})"), {"'image.width'", "expected an integer, found a string"}},
        BadScene{"WidthIsFractional", scene_json(R"(, "image": {"width": 51.2})"), {"'image.width'", "integer"}},
        BadScene{"ModeIsANumber", scene_json(R"(, "mode": 3)"), {"'mode'", "expected a string"}},
        BadScene{"UnknownMode", scene_json(R"(, "mode": "volume")"), {"'mode'", "'iso', 'dvr', 'mip'"}},
        BadScene{"ShadowsIsAString", scene_json(R"(, "shading": {"shadows": "yes"})"), {"'shading.shadows'", "true or false"}},
        BadScene{"UnknownValues", scene_json(R"(, "values": "percent")"), {"'values'", "'stored', 'normalized'"}},
        BadScene{"UnknownCachePolicy", scene_json(R"(, "cache": {"l1_policy": "lfu"})"), {"'cache.l1_policy'", "'lru'"}},
        BadScene{"OfflineOnlyCachePolicy", scene_json(R"(, "cache": {"l2_policy": "opt"})"), {"'cache.l2_policy'"}},
        BadScene{"UnknownLight", scene_json(R"(, "shading": {"light": "sun"})"), {"'shading.light'", "'directional'"}},
        BadScene{"EyeHasTwoComponents", scene_json("", R"("camera": {"eye": [2, 0], "target": [0, 0, 0]})"), {"'camera.eye'", "[x, y, z]"}},
        BadScene{"BackgroundIsAString", scene_json(R"(, "background": "black")"), {"'background'"}},
        BadScene{"ShadingIsAnArray", scene_json(R"(, "shading": [])"), {"'shading'", "expected an object"}},
        BadScene{"IsosurfaceIsANumber", scene_json(R"(, "isosurfaces": [0.5])"), {"'isosurfaces[0]'", "expected an object"}},
        BadScene{"IsosurfacesIsAnObject", scene_json(R"(, "isosurfaces": {"value": 1})"), {"'isosurfaces'"}},
        BadScene{"IsovalueIsAString", scene_json(R"(, "isosurfaces": [{"value": "0.5"}])"), {"'isosurfaces[0].value'", "expected a number"}},
        BadScene{"BackendParamIsAString", scene_json(R"(, "backend": {"name": "raymarch", "params": {"step": "fine"}})"),
                 {"'backend.params.step'", "expected a number"}},
        BadScene{"BackendIsANumber", scene_json(R"(, "backend": 3)"), {"'backend'"}},
        BadScene{"DatasetIsANumber", R"({"dataset": 3, )" + kCam + R"(, "isosurfaces": [{"value": 1}]})", {"'dataset'", "expected a string"}},
        BadScene{"CacheSizeIsNotASize", scene_json(R"(, "cache": {"l1": "lots"})"), {"cache.l1", "'lots'"}},
        BadScene{"CacheSizeIsNegative", scene_json(R"(, "cache": {"l2": -5})"), {"'cache.l2'"}},
        BadScene{"CameraPathIsANumber", scene_json("", R"("camera_path": 5)"), {"'camera_path'"}},
        // out of range
        BadScene{"OpacityAboveOne",
                 scene_json(R"(, "mode": "dvr", "transfer_function": {"points": [{"value": 0, "opacity": 0}, {"value": 1, "opacity": 1.5}]})"),
                 {"'transfer_function.points[1].opacity'", "1.5 is outside [0, 1]"}},
        BadScene{"FiveIsosurfaces", scene_json(R"(, "isosurfaces": [{"value": 1}, {"value": 2}, {"value": 3}, {"value": 4}, {"value": 5}])"),
                 {"'isosurfaces'", "1 to 4"}},
        BadScene{"NoIsosurfacesInTheList", scene_json(R"(, "isosurfaces": [])"), {"'isosurfaces'", "1 to 4"}},
        BadScene{"WidthZero", scene_json(R"(, "image": {"width": 0})"), {"'image.width'", "0 is outside [1, 16384]"}},
        BadScene{"HeightTooLarge", scene_json(R"(, "image": {"height": 20000})"), {"'image.height'"}},
        BadScene{"ColourAboveOne", scene_json(R"(, "isosurfaces": [{"value": 1, "color": [1.2, 0, 0]}])"), {"'isosurfaces[0].color'", "[0, 1]"}},
        BadScene{"FieldOfView180", scene_json("", R"("camera": {"eye": [2, 0, 0], "target": [0, 0, 0], "fov_degrees": 180})"),
                 {"'camera.fov_degrees'"}},
        BadScene{"EyeOnTarget", scene_json("", R"("camera": {"eye": [1, 1, 1], "target": [1, 1, 1]})"), {"'camera.target'", "coincide"}},
        BadScene{"UpAlongTheView", scene_json("", R"("camera": {"eye": [0, 0, 2], "target": [0, 0, 0]})"), {"'camera.up'", "points against the viewing direction"}},
        BadScene{"UpNearlyAlongTheView", scene_json("", R"("camera": {"eye": [0, 0, 0], "target": [0, 0, 2], "up": [1e-9, 0, 3]})"),
                 {"'camera.up'", "points along the viewing direction"}},
        BadScene{"HugeNumber", scene_json("", R"("camera": {"eye": [0, 1e999, 2], "target": [0, 0, 0]})"), {"number overflow", "not valid JSON"}},
        BadScene{"ZeroFrames", scene_json("", R"("camera_path": {"frames": 0, "keyframes": [{"eye": [2, 0, 0], "target": [0, 0, 0]}]})"),
                 {"'camera_path.frames'"}},
        BadScene{"NoKeyframes", scene_json("", R"("camera_path": {"keyframes": []})"), {"'camera_path.keyframes'"}},
        BadScene{"TerminationOpacityAboveOne", scene_json(R"(, "quality": {"termination_opacity": 2})"), {"'quality.termination_opacity'"}},
        BadScene{"SamplingRateZero", scene_json(R"(, "sampling_rate": 0)"), {"'sampling_rate'"}},
        BadScene{"NoLoaderThreads", scene_json(R"(, "cache": {"loader_threads": 0})"), {"'cache.loader_threads'"}},
        BadScene{"AmbientAboveOne", scene_json(R"(, "shading": {"ambient": 1.5})"), {"'shading.ambient'"}},
        BadScene{"ShininessBelowOne", scene_json(R"(, "shading": {"shininess": 0.5})"), {"'shading.shininess'"}},
        BadScene{"ZeroLightDirection", scene_json(R"(, "shading": {"light": "directional", "light_direction": [0, 0, 0]})"),
                 {"'shading.light_direction'"}},
        BadScene{"EmptyClipBox", scene_json(R"(, "clip": {"lo": [0.5, 0, 0], "hi": [0.4, 1, 1]})"), {"'clip.hi'", "empty"}},
        BadScene{"DecreasingTransferFunction",
                 scene_json(R"(, "mode": "dvr", "transfer_function": {"points": [{"value": 1, "opacity": 0}, {"value": 0.5, "opacity": 1}]})"),
                 {"'transfer_function.points[1].value'", "increasing"}},
        BadScene{"TransferFunctionWithoutPoints", scene_json(R"(, "mode": "dvr", "transfer_function": {"points": []})"),
                 {"'transfer_function.points'"}},
        BadScene{"TransferFunctionPointWithoutOpacity", scene_json(R"(, "mode": "dvr", "transfer_function": {"points": [{"value": 0}]})"),
                 {"'transfer_function.points[0].opacity'", "missing"}},
        // missing or contradictory keys
        BadScene{"MissingDataset", "{" + kCam + R"(, "isosurfaces": [{"value": 1}]})", {"'dataset'", "missing"}},
        BadScene{"EmptyDataset", R"({"dataset": "", )" + kCam + R"(, "isosurfaces": [{"value": 1}]})", {"'dataset'"}},
        BadScene{"IsoModeWithoutIsosurfaces", R"({"dataset": "v", )" + kCam + R"(, "mode": "iso"})", {"'isosurfaces'", "iso mode"}},
        BadScene{"DefaultModeWithoutIsosurfaces", R"({"dataset": "v", )" + kCam + "}", {"'isosurfaces'"}},
        BadScene{"DvrWithoutTransferFunction", R"({"dataset": "v", )" + kCam + R"(, "mode": "dvr"})", {"'transfer_function'", "dvr"}},
        BadScene{"CameraAndCameraPath",
                 scene_json(R"(, "camera_path": {"keyframes": [{"eye": [2, 0, 0], "target": [0, 0, 0]}]})"),
                 {"camera_path", "exactly one of 'camera' and 'camera_path'"}},
        BadScene{"NeitherCameraNorPath", R"({"dataset": "v", "isosurfaces": [{"value": 1}]})", {"'camera'", "exactly one"}},
        BadScene{"ShadowsInDvrMode", R"({"dataset": "v", )" + kCam + ", " + kTf + R"(, "mode": "dvr", "shading": {"shadows": true}})",
                 {"shading", "iso mode only"}},
        BadScene{"ShadowsInMipMode", scene_json(R"(, "mode": "mip", "shading": {"light": "point", "shadows": true})"), {"shading", "iso"}},
        BadScene{"CameraMissingTarget", scene_json("", R"("camera": {"eye": [2, 0, 0]})"), {"'camera.target'", "missing"}},
        BadScene{"BackendWithoutName", scene_json(R"(, "backend": {"params": {}})"), {"'backend.name'", "missing"}},
        // not JSON at all
        BadScene{"MalformedJson", R"({"dataset": "v", "camera": {"eye": [2, 0, 0] "target": [0, 0, 0]}})", {"not valid JSON"}},
        BadScene{"TrailingComma", scene_json(R"(, "mode": "iso",)"), {"not valid JSON"}},
        BadScene{"TopLevelArray", "[1, 2, 3]", {"expected an object"}},
        BadScene{"Empty", "", {"not valid JSON"}}),
    [](const ::testing::TestParamInfo<BadScene>& p) { return std::string(p.param.name); });

TEST(Scene, ShadowsInDvrModeNameTheShadowsKey) {
  const Error e = parse_error(R"({"dataset": "v", )" + kCam + ", " + kTf + R"(, "mode": "dvr", "shading": {"shadows": true}})");
  EXPECT_EQ(e.field(), "shading.shadows") << e.what();
}

TEST(Scene, LoadSceneNamesAMissingOrMalformedFile) {
  testing::TempDir dir;
  try {
    load_scene(dir.file("absent.json"));
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), Errc::io);
    EXPECT_THAT(e.what(), HasSubstr("absent.json"));
  }
  std::ofstream(dir.file("broken.json")) << "{ // a comment\n \"dataset\": \"v\",, }";
  try {
    load_scene(dir.file("broken.json"));
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), Errc::format);
    EXPECT_THAT(e.what(), HasSubstr("broken.json"));
    EXPECT_THAT(e.what(), HasSubstr("not valid JSON"));
  }
  std::ofstream(dir.file("typo.json")) << scene_json(R"(, "shading": {"ligth": "none"})");
  try {
    load_scene(dir.file("typo.json"));
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("typo.json"));
    EXPECT_THAT(e.what(), HasSubstr("'shading.ligth'"));
  }
}

TEST(Scene, CameraPathFileErrorsNameThatFileAndTheKey) {
  testing::TempDir dir;
  const std::string scene = dir.file("scene.json");
  {
    const Error e = parse_error(scene_json("", R"("camera_path": "missing-path.json")"), scene);
    EXPECT_THAT(e.what(), HasSubstr("missing-path.json"));
    EXPECT_THAT(e.what(), HasSubstr("camera_path"));
  }
  std::ofstream(dir.file("bad-path.json")) << R"({"frames": 3, "camera_path": {"keyframes": []}})";
  {
    const Error e = parse_error(scene_json("", R"("camera_path": "bad-path.json")"), scene);
    EXPECT_THAT(e.what(), HasSubstr("bad-path.json"));
    EXPECT_THAT(e.what(), HasSubstr("camera_path.keyframes"));
  }
}

// --- back-end parameters --------------------------------------------------------------------

TEST(BackendParams, DefaultsOverriddenByTheGivenValues) {
  const BackendInfo& info = backends().find("raymarch").info;
  const BackendParams defaults(info, {});
  EXPECT_DOUBLE_EQ(defaults["step"], 0.5);
  const BackendParams p(info, {{"step", 0.25}});
  EXPECT_DOUBLE_EQ(p["step"], 0.25);
  EXPECT_EQ(p.values().size(), info.params.size());
}

TEST(BackendParams, UnknownOrOutOfRangeParameterNamesTheKeyAndTheFile) {
  const BackendInfo& info = backends().find("raymarch").info;
  try {
    BackendParams(info, {{"stepp", 1.0}}, "/scenes/s.json");
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), Errc::invalid_argument);
    EXPECT_THAT(e.what(), HasSubstr("/scenes/s.json"));
    EXPECT_THAT(e.what(), HasSubstr("backend.params.stepp"));
    EXPECT_THAT(e.what(), HasSubstr("'step', 'refine'"));  // the known parameters
  }
  try {
    BackendParams(info, {{"step", 100.0}}, "/scenes/s.json");
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("/scenes/s.json"));
    EXPECT_THAT(e.what(), HasSubstr("backend.params.step"));
    EXPECT_THAT(e.what(), HasSubstr("outside"));
  }
}

TEST(RenderSession, RejectsAnUnknownParameterOfTheScenesBackEndBeforeOpeningTheStore) {
  // The store does not exist: the parameter is checked first.
  const Scene s = parse_scene(scene_json(R"(, "backend": {"name": "raymarch", "params": {"setp": 1}})"), "/nowhere/scene.json");
  try {
    RenderSession session(s);
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), Errc::format);  // the scene file is at fault: exit 1
    EXPECT_THAT(e.what(), HasSubstr("/nowhere/scene.json"));
    EXPECT_THAT(e.what(), HasSubstr("backend.params.setp"));
  }
  // A parameter given on the command line (Options) is not the scene's: no file to name.
  const Scene plain = parse_scene(scene_json(""), "/nowhere/scene.json");
  RenderSession::Options o;
  o.params["warp"] = 2;
  try {
    RenderSession session(plain, o);
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("backend.params.warp"));
  }
  // The scene's parameters belong to its back end: another back end does not see them.
  const Scene ref = parse_scene(scene_json(R"(, "backend": {"name": "raymarch", "params": {"refine": 3}})"), "/nowhere/scene.json");
  RenderSession::Options other;
  other.backend = "reference";
  try {
    RenderSession session(ref, other);
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), Not(HasSubstr("refine")));
    EXPECT_THAT(e.what(), HasSubstr("nowhere"));  // the missing store
  }
}

TEST(RenderSession, UnknownBackEndListsTheKnownOnesAndNamesTheScene) {
  const Scene s = parse_scene(scene_json(R"(, "backend": "raytrace")"), "/nowhere/scene.json");
  try {
    RenderSession session(s);
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), Errc::format);  // the scene file is at fault: exit 1
    EXPECT_THAT(e.what(), HasSubstr("'raytrace'"));
    EXPECT_THAT(e.what(), HasSubstr("'reference', 'raymarch'"));
    EXPECT_THAT(e.what(), HasSubstr("backend"));
  }
}

// --- transfer function ----------------------------------------------------------------------

TfPoint pt(double value, float opacity, Vec3f color = Vec3f(1.0f)) { return TfPoint{value, color, opacity}; }

TEST(TransferFunction, EvalInterpolatesLinearlyAndClampsAtTheEnds) {
  const TransferFunction tf({pt(0, 0.0f, {1, 0, 0}), pt(1, 0.5f, {0, 1, 0}), pt(3, 1.0f, {0, 0, 1})});
  Vec3f c;
  float a;
  tf.eval(0.5, c, a);
  expect_vec(c, 0.5f, 0.5f, 0);
  EXPECT_FLOAT_EQ(a, 0.25f);
  tf.eval(2.5, c, a);
  expect_vec(c, 0, 0.25f, 0.75f);
  EXPECT_FLOAT_EQ(a, 0.875f);
  tf.eval(1, c, a);  // exactly on a point
  expect_vec(c, 0, 1, 0);
  EXPECT_FLOAT_EQ(a, 0.5f);
  tf.eval(-7, c, a);  // below: the first point
  expect_vec(c, 1, 0, 0);
  EXPECT_FLOAT_EQ(a, 0);
  tf.eval(30, c, a);  // above: the last
  expect_vec(c, 0, 0, 1);
  EXPECT_FLOAT_EQ(a, 1);
  tf.eval(std::numeric_limits<double>::quiet_NaN(), c, a);  // NaN: the first point
  EXPECT_FLOAT_EQ(a, 0);
  EXPECT_FLOAT_EQ(tf.opacity(2), 0.75f);
}

TEST(TransferFunction, EqualValuesMakeAStep) {
  const TransferFunction tf({pt(0, 0.0f), pt(1, 0.0f), pt(1, 1.0f), pt(2, 1.0f)});
  EXPECT_FLOAT_EQ(tf.opacity(0.999), 0);
  EXPECT_FLOAT_EQ(tf.opacity(1.001), 1);
  EXPECT_FALSE(tf.visible(0.0, 0.99));
  EXPECT_TRUE(tf.visible(0.99, 1.01));
  EXPECT_TRUE(tf.visible(1.5, 1.6));
}

TEST(TransferFunction, EmptyIsInvisibleAndBlack) {
  const TransferFunction tf;
  EXPECT_TRUE(tf.empty());
  EXPECT_FALSE(tf.visible(-1e9, 1e9));
  EXPECT_FLOAT_EQ(tf.opacity(0.5), 0);
  EXPECT_GT(tf.visible_lo(), tf.visible_hi());
}

TEST(TransferFunction, ZeroOpacityRangesAreInvisibleAndRangesTouchingARampAreVisible) {
  // A tent: zero opacity below 0.4 and above 0.6, peak at 0.5.
  const TransferFunction tf({pt(0, 0), pt(0.4, 0), pt(0.5, 1), pt(0.6, 0), pt(1, 0)});
  EXPECT_FALSE(tf.visible(0.0, 0.39));
  EXPECT_FALSE(tf.visible(0.61, 1.0));
  EXPECT_FALSE(tf.visible(0.1, 0.2));
  EXPECT_TRUE(tf.visible(0.0, 0.401));   // reaches just into the rising ramp
  EXPECT_TRUE(tf.visible(0.599, 1.0));   // and the falling one
  EXPECT_TRUE(tf.visible(0.45, 0.46));   // inside
  EXPECT_TRUE(tf.visible(0.5, 0.5));     // a single value
  EXPECT_TRUE(tf.visible(-5, 5));        // holds it all
  EXPECT_FALSE(tf.visible(-5, -1));      // beyond the low end: the first point's opacity, 0
  EXPECT_FALSE(tf.visible(2, 5));        // beyond the high end: the last point's, 0
  EXPECT_FALSE(tf.visible(0.6, 0.4));    // an empty range
  EXPECT_DOUBLE_EQ(tf.visible_lo(), 0.4);
  EXPECT_DOUBLE_EQ(tf.visible_hi(), 0.6);
}

TEST(TransferFunction, VisibleEndsExtendBeyondThePoints) {
  const TransferFunction low({pt(0, 0.3f), pt(0.5, 0), pt(1, 0)});
  EXPECT_TRUE(low.visible(-10, -5));
  EXPECT_FALSE(low.visible(0.6, 20));
  EXPECT_EQ(low.visible_lo(), -std::numeric_limits<double>::infinity());
  EXPECT_DOUBLE_EQ(low.visible_hi(), 0.5);
  const TransferFunction high({pt(0, 0), pt(0.5, 0), pt(1, 0.2f)});
  EXPECT_TRUE(high.visible(5, 10));
  EXPECT_FALSE(high.visible(-10, 0.4));
  EXPECT_DOUBLE_EQ(high.visible_lo(), 0.5);
  EXPECT_EQ(high.visible_hi(), std::numeric_limits<double>::infinity());
  const TransferFunction none({pt(0, 0), pt(1, 0)});
  EXPECT_FALSE(none.visible(-1e9, 1e9));
  EXPECT_GT(none.visible_lo(), none.visible_hi());
}

TEST(TransferFunction, OnePointIsVisibleEverywhereOrNowhere) {
  const TransferFunction on({pt(0.5, 0.3f)});
  EXPECT_TRUE(on.visible(-3, -2));
  EXPECT_TRUE(on.visible(0.5, 0.5));
  EXPECT_TRUE(on.visible(7, 8));
  const TransferFunction off({pt(0.5, 0.0f)});
  EXPECT_FALSE(off.visible(-3, 8));
}

TEST(TransferFunction, ASpikeNarrowerThanABinIsVisible) {
  const TransferFunction tf({pt(0, 0), pt(0.5, 0), pt(0.50001, 1), pt(0.50002, 0), pt(1, 0)});
  EXPECT_TRUE(tf.visible(0.500005, 0.500006));
  EXPECT_TRUE(tf.visible(0.2, 0.8));
  EXPECT_FALSE(tf.visible(0.2, 0.4));
  EXPECT_FALSE(tf.visible(0.6, 0.8));
}

/// Exact visibility of a piecewise-linear function over [lo, hi]: its maximum there is at an
/// end of the range or at a point inside.
bool exactly_visible(const TransferFunction& tf, double lo, double hi) {
  if (lo > hi) return false;
  if (tf.opacity(lo) > 0 || tf.opacity(hi) > 0) return true;
  for (const TfPoint& p : tf.points())
    if (p.value >= lo && p.value <= hi && p.opacity > 0) return true;
  return false;
}

TEST(TransferFunction, SummedAreaTableIsConservativeAndExactBeyondOneBin) {
  // Random functions with runs of zero opacity; random ranges. The table never says invisible
  // when something is visible, and says visible only within two bins of a visible value.
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  constexpr int kBins = 256;
  int invisible = 0, visible = 0;
  for (int f = 0; f < 40; ++f) {
    std::vector<TfPoint> points;
    double v = unit(rng) * 2 - 1;
    for (int i = 0, n = 2 + int(unit(rng) * 8); i < n; ++i) {
      points.push_back(pt(v, unit(rng) < 0.5 ? 0.0f : float(unit(rng))));
      v += unit(rng) < 0.1 ? 0.0 : unit(rng);  // now and then a step
    }
    const TransferFunction tf(points, kBins);
    const double span = tf.points().back().value - tf.points().front().value;
    const double bin = span > 0 ? span / kBins : 0;
    for (int r = 0; r < 400; ++r) {
      double a = tf.points().front().value - 0.5 + unit(rng) * (span + 1);
      double b = a + unit(rng) * unit(rng) * span;
      const bool answer = tf.visible(a, b);
      if (exactly_visible(tf, a, b)) {
        EXPECT_TRUE(answer) << "function " << f << " range [" << a << ", " << b << "]";
        ++visible;
      } else if (!exactly_visible(tf, a - 2 * bin, b + 2 * bin)) {
        EXPECT_FALSE(answer) << "function " << f << " range [" << a << ", " << b << "]";
        ++invisible;
      }
    }
  }
  EXPECT_GT(visible, 1000);
  EXPECT_GT(invisible, 1000);
}

}  // namespace
}  // namespace brickyard
