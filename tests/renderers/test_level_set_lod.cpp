// Level sets keep their thin parts at every level of detail (issue 41, item 5). A one-voxel
// thick open shell (a hemisphere's surface, thickened by half a voxel on each side) is a level
// set whose inside is a single voxel across: averaging 2x2x2 blocks mixes it with the outside,
// so the coarser levels lose the shell in holes and level-of-detail back ends draw them; the
// minimum of each block (the default for level sets) keeps every block that holds some inside.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "array_scene.h"
#include "preprocess/export.h"
#include "storage/store.h"
#include "renderers/common/metrics.h"
#include "test_util.h"

namespace brickyard {
namespace {

using testing::look;
using testing::make_scene;
using testing::render_world;

constexpr double kBand = 3.0;  // narrow band, in voxels, as OpenVDB's default half width

/// The unsigned distance to the upper hemisphere of radius r about c (its rim at z = c.z is
/// open), minus half a voxel, clamped to the band: negative within half a voxel of the surface.
std::vector<float> open_shell(const Vec3s& dims, const Vec3d& c, double r) {
  std::vector<float> v;
  v.reserve(size_t(volume(dims)));
  for (int64_t z = 0; z < dims.z; ++z)
    for (int64_t y = 0; y < dims.y; ++y)
      for (int64_t x = 0; x < dims.x; ++x) {
        const Vec3d d = Vec3d(double(x), double(y), double(z)) - c;
        double distance;
        if (d.z >= 0) {
          distance = std::abs(length(d) - r);
        } else {  // below the rim: the nearest point is on the rim circle
          const double rho = std::sqrt(d.x * d.x + d.y * d.y);
          distance = std::sqrt((rho - r) * (rho - r) + d.z * d.z);
        }
        v.push_back(float(std::clamp(distance - 0.5, -kBand, kBand)));
      }
  return v;
}

std::string build_shell(const testing::TempDir& dir, const std::string& name, const Vec3s& dims,
                        const std::vector<float>& values, Downsample downsample) {
  testing::ArraySource src(dims, values);
  BuildOptions o;
  o.brick_size = 16;
  o.downsample = downsample;
  o.level_set = downsample == Downsample::min;
  build_store(src, dir.file(name), o);
  build_octree(dir.file(name), {});
  return dir.file(name);
}

TEST(LevelSetLod, AThinOpenShellSurvivesEveryLevelOfDetailWithMinDownsampling) {
  testing::TempDir dir;
  const Vec3s dims{96, 96, 96};
  const Vec3d centre(47.5, 47.5, 30.0);
  const std::vector<float> shell = open_shell(dims, centre, 40.0);
  const std::string averaged = build_shell(dir, "average", dims, shell, Downsample::average);
  const std::string minimum = build_shell(dir, "min", dims, shell, Downsample::min);
  // Seen from above and aside at about 3 voxels a pixel, where the footprint asks for the
  // levels two and four times coarser than the finest.
  const Camera cam = look(centre + Vec3d(150, -190, 170), centre + Vec3d(0, 0, 15), {0, 0, 1}, 30);
  const int size = 64;
  for (const std::string backend : {"gobbetti", "gigavoxels", "octree_cgt"}) {
    ImageError before, after;
    int shown = 0;
    for (const std::string& store : {averaged, minimum}) {
      Scene s = make_scene(store, backend, RenderMode::iso, size);
      s.quality.lod_ratio = Quality{}.lod_ratio;  // the default level of detail, not the finest
      if (backend == std::string("octree_cgt")) s.backend_params = {{"dpdv", 1.0}};
      s.isosurfaces = {Isosurface{0.0}};
      Scene ref = s;
      ref.backend = "reference";
      ref.backend_params.clear();
      const testing::Rendered truth = render_world(ref, cam), test = render_world(s, cam);
      shown = 0;
      for (int i = 0; i < size * size; ++i) shown += std::isfinite(truth.fb.depth.data()[i]);
      ASSERT_GT(shown, size * size / 8) << "the reference must show the shell";
      (store == averaged ? before : after) = compare_frames(test.fb, truth.fb, 1.0);
    }
    SCOPED_TRACE(backend + " average: " + before.to_json() + "\nmin: " + after.to_json());
    // Averaged levels drop the shell in holes: many of the reference's pixels go missing.
    EXPECT_LT(after.rmse, 0.5 * before.rmse);
    EXPECT_LT(double(after.coverage_mismatch), 0.05 * shown);
    EXPECT_GT(double(before.coverage_mismatch), double(after.coverage_mismatch));
  }
}

TEST(LevelSetLod, MinDownsamplingKeepsEveryCoarseVoxelThatHoldsTheInside) {
  testing::TempDir dir;
  const Vec3s dims{64, 64, 64};
  const std::vector<float> shell = open_shell(dims, {31.5, 31.5, 20.0}, 26.0);
  Store avg(build_shell(dir, "average", dims, shell, Downsample::average));
  Store min(build_shell(dir, "min", dims, shell, Downsample::min));
  EXPECT_NE(min.manifest().build.find("\"level_set\":true"), std::string::npos) << min.manifest().build;
  EXPECT_EQ(avg.manifest().build.find("level_set"), std::string::npos) << avg.manifest().build;
  // At each coarser level: the voxels inside the shell (negative), counted.
  for (int level = min.layout().finest() - 1; level >= min.layout().finest() - 2; --level) {
    auto inside = [&](const Store& s) {
      int64_t n = 0;
      for_each_region_slab(s, level, export_region(s, level, std::nullopt), [&](int64_t, int64_t, std::span<const std::byte> b) {
        const float* p = reinterpret_cast<const float*>(b.data());
        for (size_t i = 0; i < b.size() / sizeof(float); ++i) n += p[i] < 0;
      });
      return n;
    };
    const int64_t kept = inside(min), averaged = inside(avg);
    // The shell's area in voxels of this level, 2 pi r^2 (plus the rim), is at least what a
    // closed one-voxel layer of it holds; averaging leaves a fraction of it.
    const double step = std::pow(2.0, min.layout().finest() - level);
    const double area = 2 * kPi * (26.0 / step) * (26.0 / step);
    EXPECT_GT(double(kept), 0.9 * area) << "level " << level;
    EXPECT_LT(double(averaged), 0.5 * double(kept)) << "level " << level;
  }
}

}  // namespace
}  // namespace brickyard
