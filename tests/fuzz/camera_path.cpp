// Camera-path files (core/camera.h, as `brickyard flight` reads them): CameraPath::load over
// untrusted JSON, then frames' cameras placed in a world box and set up for an image, as a
// flight does. Every keyframe the reader accepts must give finite, unit-length rays:
// renderers step along them and turn positions into voxel indices.

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
    for (size_t k = 0; k < p.keyframes.size() && k < 16; ++k) {
      const Rayd r = ImageRays(p.keyframes[k], p.width, p.height).ray(0.5 * p.width, 0.5 * p.height);
      if (!finite(r.org) || !finite(r.dir) || !(std::fabs(length(r.dir) - 1.0) < 1e-6)) {
        std::fprintf(stderr, "fuzz: keyframe %zu of an accepted camera path gives the ray (%g %g %g) + t (%g %g %g)\n", k,
                     r.org.x, r.org.y, r.org.z, r.dir.x, r.dir.y, r.dir.z);
        std::abort();
      }
    }
    const Box3d world(Vec3d(0.0), Vec3d(63.0, 31.0, 15.0));
    const int frames = p.frames;
    for (int f : {0, 1, frames / 3, frames / 2, frames - 1}) {
      if (f < 0 || f >= frames) continue;
      const Camera c = p.at(f).in_box(world);
      (void)ImageRays(c, p.width, p.height).ray(0.5, 0.5);
      (void)c.may_see(world, p.width, p.height);
    }
  });
}
