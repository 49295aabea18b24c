#include "preprocess/export.h"

#include <xxhash.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <limits>
#include <memory>
#include <vector>

#include <fmt/format.h>

#include "core/atomic_file.h"
#include "core/error.h"
#include "core/parallel.h"
#include "core/progress.h"
#include "storage/store.h"

namespace brickyard {

VoxelBox export_region(const Store& store, int level, const std::optional<VoxelBox>& box) {
  if (level < 0 || level >= store.layout().levels)
    throw Error(Errc::invalid_argument,
                fmt::format("level {} does not exist (the store has levels 0 to {})", level, store.layout().levels - 1))
        .with_field("--level");
  const Vec3s dims = store.layout().level_dims(level);
  if (!box) return {Vec3s(0), dims};
  for (int a = 0; a < 3; ++a)
    if (box->lo[a] < 0 || box->hi[a] > dims[a] || box->lo[a] >= box->hi[a])
      throw Error(Errc::invalid_argument,
                  fmt::format("box [{}, {}, {}] - [{}, {}, {}) is empty or outside level {} ({}x{}x{})", box->lo.x,
                              box->lo.y, box->lo.z, box->hi.x, box->hi.y, box->hi.z, level, dims.x, dims.y, dims.z))
          .with_field("--box");
  return *box;
}

void for_each_region_slab(const Store& store, int level, const VoxelBox& region,
                          const std::function<void(int64_t, int64_t, std::span<const std::byte>)>& sink,
                          Progress* progress, int step) {
  (void)store.dataset(step);  // Error(invalid_argument) naming time_step for a step it does not have
  const BrickFormat& f = store.format();
  const int64_t M = f.brick_size, A = f.apron, E = f.edge();
  const size_t vs = size_of(f.type);
  const Vec3s size = region.size();
  const int64_t bx0 = region.lo.x / M, bx1 = (region.hi.x - 1) / M;
  const int64_t by0 = region.lo.y / M, by1 = (region.hi.y - 1) / M;
  const int64_t nbx = bx1 - bx0 + 1, nby = by1 - by0 + 1;
  std::vector<std::byte> bricks(size_t(nbx * nby) * f.bytes());
  std::vector<std::byte> slab;
  for (int64_t bz = region.lo.z / M; bz * M < region.hi.z; ++bz) {
    // Step 1: decode the row of bricks the region touches, in parallel.
    parallel_for<int64_t>(0, nbx * nby, 1, [&](int64_t b0, int64_t b1) {
      auto txn = store.begin_read();
      for (int64_t b = b0; b < b1; ++b) {
        const BrickKey key{uint32_t(level), uint32_t(bx0 + b % nbx), uint32_t(by0 + b / nbx), uint32_t(bz)};
        store.read_brick(txn, key, {bricks.data() + size_t(b) * f.bytes(), f.bytes()}, step);
      }
    });
    // Step 2: copy the interiors into a dense slab of the region.
    const int64_t z0 = std::max(region.lo.z, bz * M), z1 = std::min(region.hi.z, (bz + 1) * M);
    slab.resize(size_t((z1 - z0) * size.x * size.y) * vs);
    for (int64_t z = z0; z < z1; ++z)
      for (int64_t y = region.lo.y; y < region.hi.y; ++y) {
        const int64_t by = y / M - by0;
        std::byte* dst = slab.data() + size_t(((z - z0) * size.y + (y - region.lo.y)) * size.x) * vs;
        for (int64_t x = region.lo.x; x < region.hi.x;) {
          const int64_t bx = x / M;
          const int64_t run = std::min(region.hi.x, (bx + 1) * M) - x;
          const std::byte* brick = bricks.data() + size_t(by * nbx + (bx - bx0)) * f.bytes();
          const int64_t lx = x - bx * M + A, ly = y - (y / M) * M + A, lz = z - bz * M + A;
          std::memcpy(dst, brick + size_t((lz * E + ly) * E + lx) * vs, size_t(run) * vs);
          dst += size_t(run) * vs;
          x += run;
        }
      }
    sink(z0, z1, slab);
    if (progress) progress->advance(uint64_t((z1 - z0) * size.x * size.y));
  }
}

RawVolumeInfo export_raw(const Store& store, int level, const VoxelBox& region, const std::string& path,
                         Progress* progress, int step) {
  (void)store.dataset(step);  // before the file is created
  AtomicFile file(path);
  std::unique_ptr<XXH3_state_t, decltype(&XXH3_freeState)> hash(XXH3_createState(), XXH3_freeState);
  XXH3_64bits_reset(hash.get());
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  uint64_t written = 0;
  const ValueType type = store.format().type;
  for_each_region_slab(
      store, level, region,
      [&](int64_t, int64_t, std::span<const std::byte> bytes) {
        file.write(bytes.data(), bytes.size());
        written += bytes.size();
        XXH3_64bits_update(hash.get(), bytes.data(), bytes.size());
        extend_range(bytes, type, lo, hi);
      },
      progress, step);
  file.commit();
  const Manifest& m = store.manifest();
  const double scale = double(int64_t(1) << store.layout().steps(level));
  RawVolumeInfo info;
  info.dims = region.size();
  info.type = type;
  info.spacing = m.spacing * scale;
  // Coarse voxel i is centred at finest coordinate (i + 0.5) * scale - 0.5.
  info.origin = m.origin + m.spacing * (Vec3d(region.lo) * scale + Vec3d((scale - 1) / 2));
  info.min_value = lo;
  info.max_value = hi;
  info.source = store.time_steps() > 1 ? fmt::format("store {} level {} time step {}", store.path(), level, step)
                                        : fmt::format("store {} level {}", store.path(), level);
  info.bytes = written;
  info.xxh3_64 = XXH3_64bits_digest(hash.get());
  write_raw_sidecar(raw_sidecar_path(path), info);
  return info;
}

}  // namespace brickyard
