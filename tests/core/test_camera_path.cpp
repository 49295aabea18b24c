#include <gtest/gtest.h>

#include <cmath>
#include <fstream>

#include "core/camera.h"
#include "core/error.h"
#include "test_util.h"

namespace brickyard {
namespace {

std::string path_file(const testing::TempDir& dir, const std::string& camera) {
  const std::string path = dir.file("path.json");
  std::ofstream(path) << R"({"camera": )" << camera << "}";
  return path;
}

void expect_camera_error(const std::string& path, const std::string& field, const std::string& message) {
  try {
    CameraPath::load(path);
    FAIL() << "accepted " << field;
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), Errc::format) << e.what();
    EXPECT_EQ(e.file(), path);
    EXPECT_EQ(e.field(), field) << e.what();
    EXPECT_NE(e.message().find(message), std::string::npos) << e.what();
  }
}

TEST(CameraPath, ReadsOneCameraWithUnitRays) {
  testing::TempDir dir;
  const CameraPath p = CameraPath::load(path_file(dir, R"({"eye": [0.5, -1.5, 0.5], "target": [0.5, 0.5, 0.5]})"));
  ASSERT_EQ(p.keyframes.size(), 1u);
  const Rayd r = p.keyframes[0].ray(0.5 * p.width, 0.5 * p.height, p.width, p.height);
  EXPECT_NEAR(length(r.dir), 1.0, 1e-12);
}

// Found by fuzzing (tests/fuzz/regressions/camera_path/): finite eye and target so far apart
// that their distance overflows gave a zero viewing direction, so every ray was degenerate; an
// up that long was silently replaced.
TEST(CameraPath, EyeAndTargetTooFarApartAreAnErrorNamingTheKey) {
  testing::TempDir dir;
  expect_camera_error(path_file(dir, R"({"eye": [1e300, 0, 0], "target": [-1e300, 0, 0]})"), "camera.target",
                      "eye and target are too far apart");
  expect_camera_error(path_file(dir, R"({"eye": [0, 0, 0], "target": [0, 0, 0]})"), "camera.target", "coincide");
  expect_camera_error(path_file(dir, R"({"eye": [0, 0, 0], "target": [1, 0, 0], "up": [1e300, 1e300, 1e300]})"), "camera.up",
                      "up is too long");
}

}  // namespace
}  // namespace brickyard
