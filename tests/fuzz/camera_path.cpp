// Camera-path files (core/camera.h, as `brickyard flight` reads them): CameraPath::load over
// untrusted JSON, then every frame's camera placed in a world box and set up for an image, as
// a flight does. A camera the reader accepts must give finite rays: renderers turn ray
// positions into voxel indices.

#include <cmath>
#include <cstdio>
#include <cstdlib>

#include "core/camera.h"
#include "tests/fuzz/fuzz_util.h"

using namespace brickyard;

namespace {
bool finite(const Vec3d& v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = fuzz::write_temp("path.json", data, size);
  return fuzz::run_one([&] {
    const CameraPath p = CameraPath::load(path);
    const Box3d world(Vec3d(0.0), Vec3d(63.0, 31.0, 15.0));
    const int frames = p.frames;
    for (int f : {0, 1, frames / 3, frames / 2, frames - 1}) {
      if (f < 0 || f >= frames) continue;
      const Camera c = p.at(f);
      const ImageRays rays(c, p.width, p.height);
      const Rayd r = rays.ray(0.5 * p.width, 0.5 * p.height);
      if (!finite(r.org) || !finite(r.dir)) {
        std::fprintf(stderr, "fuzz: frame %d of an accepted camera path gives a ray that is not finite\n", f);
        std::abort();
      }
      (void)c.in_box(world).may_see(world, p.width, p.height);
    }
  });
}
