// Scene files (renderers/common/scene.h): parse_scene over untrusted JSON, then what a session
// asks of a scene before it renders: values mapped onto a store's range, the frame count, each
// frame's camera and time step, and whether a value range is visible.

#include <string>

#include "renderers/common/scene.h"
#include "tests/fuzz/fuzz_util.h"

using namespace brickyard;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  // A scene in the temporary directory: a camera path file it names is looked for there.
  static const std::string file = (fuzz::temp_dir() / "scene.json").string();
  // Camera paths the seeds name (scenes/*.json name flight-orbit.json beside them).
  static const bool paths = [] {
    const char* path = R"({"frames": 3, "camera_path": {"keyframes": [{"eye": [0, 0, 0], "target": [1, 1, 1]},
                          {"eye": [1, 0, 0], "target": [0, 1, 1]}]}})";
    fuzz::write_temp("path.json", path);
    fuzz::write_temp("flight-orbit.json", path);
    return true;
  }();
  (void)paths;
  return fuzz::run_one([&] {
    Scene s = parse_scene(text, file);
    normalize_values(s, -1.0, 2.0);
    const int frames = s.frames();
    for (int f : {0, 1, frames / 2, frames - 1}) {
      if (f < 0 || f >= frames) continue;
      (void)s.step_of(f);
      (void)s.camera.at(f);
    }
    (void)s.value_range_visible(0.0, 1.0);
    (void)s.value_range_visible(-1e30, 1e30);
  });
}
