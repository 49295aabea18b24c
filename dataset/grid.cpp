#include "dataset/grid.h"

#include <algorithm>

#include <fmt/format.h>

namespace brickyard {

namespace {
int64_t ceil_div(int64_t a, int64_t b) { return (a + b - 1) / b; }
}  // namespace

int resolving_steps(const Vec3s& dims) {
  int s = 0;
  for (;; ++s) {
    if (s >= 62) return s;  // every axis is down to one voxel long before
    bool resolves = true;
    for (int a = 0; a < 3; ++a)
      resolves = resolves && ceil_div(dims[a], int64_t(1) << (s + 1)) >= std::min(dims[a], kResolvingVoxels);
    if (!resolves) return s;
  }
}

GridLayout GridLayout::make(const Vec3s& dims, int brick_size) {
  if (dims.x < 1 || dims.y < 1 || dims.z < 1)
    throw Error(Errc::invalid_argument, fmt::format("volume {}x{}x{} is empty", dims.x, dims.y, dims.z)).with_field("dims");
  if (brick_size < 8 || brick_size > 128 || (brick_size & (brick_size - 1)) != 0)
    throw Error(Errc::invalid_argument, fmt::format("brick size {} is not a power of two in [8, 128]", brick_size))
        .with_field("brick_size");
  GridLayout l;
  l.dims = dims;
  l.brick_size = brick_size;
  l.levels = 1;
  Vec3s d = dims;
  while (max_component(d) > brick_size) {
    d = {ceil_div(d.x, 2), ceil_div(d.y, 2), ceil_div(d.z, 2)};
    ++l.levels;
  }
  const Vec3s finest_bricks = l.level_bricks(l.finest());
  if (max_component(finest_bricks) > int64_t(kMaxBrickCoord) + 1 || l.levels > kMaxLevel)
    throw Error(Errc::invalid_argument,
                fmt::format("volume {}x{}x{} needs {} bricks along an axis; keys hold at most {}", dims.x, dims.y,
                            dims.z, max_component(finest_bricks), kMaxBrickCoord + 1))
        .with_field("dims");
  return l;
}

int GridLayout::coarsest_resolving() const { return std::max(0, finest() - resolving_steps(dims)); }

Vec3s GridLayout::level_dims(int level) const {
  const int s = steps(level);
  return {ceil_div(dims.x, int64_t(1) << s), ceil_div(dims.y, int64_t(1) << s), ceil_div(dims.z, int64_t(1) << s)};
}

Vec3s GridLayout::level_bricks(int level) const {
  const Vec3s d = level_dims(level);
  return {ceil_div(d.x, brick_size), ceil_div(d.y, brick_size), ceil_div(d.z, brick_size)};
}

int64_t GridLayout::total_bricks() const {
  int64_t n = 0;
  for (int l = 0; l < levels; ++l) n += brick_count(l);
  return n;
}

bool GridLayout::contains(const BrickKey& k) const {
  if (int(k.level) >= levels) return false;
  const Vec3s b = level_bricks(int(k.level));
  return k.x < b.x && k.y < b.y && k.z < b.z;
}

int64_t GridLayout::linear_index(const BrickKey& k) const {
  const Vec3s b = level_bricks(int(k.level));
  return (int64_t(k.z) * b.y + k.y) * b.x + k.x;
}

BrickKey GridLayout::key_at(int level, int64_t linear) const {
  const Vec3s b = level_bricks(level);
  return {uint32_t(level), uint32_t(linear % b.x), uint32_t((linear / b.x) % b.y), uint32_t(linear / (b.x * b.y))};
}

NodeTable::NodeTable(const GridLayout& layout) : layout_(layout) {
  levels_.resize(size_t(layout.levels));
  for (int l = 0; l < layout.levels; ++l) levels_[size_t(l)].resize(size_t(layout.brick_count(l)));
}

Box3d GridView::brick_world_box(const BrickKey& key) const {
  const GridLayout& l = layout();
  const double scale = double(int64_t(1) << l.steps(int(key.level)));
  const double M = l.brick_size;
  Box3d box;
  for (int a = 0; a < 3; ++a) {
    const double lo = double(key.coords()[a]) * M * scale;
    const double hi = std::min(double(l.dims[a] - 1), (double(key.coords()[a]) + 1) * M * scale);
    box.lo[a] = origin_[a] + std::min(lo, hi) * spacing_[a];
    box.hi[a] = origin_[a] + hi * spacing_[a];
  }
  return box;
}

double GridView::brick_voxel_pixels(const Camera& cam, const BrickKey& key, const Box3d& world_box, int height) const {
  const double voxel = max_component(spacing_) * double(int64_t(1) << layout().steps(int(key.level)));
  return cam.projected_pixels(voxel, distance(world_box, cam.eye), height);
}

size_t NodeTable::bytes() const {
  size_t n = 0;
  for (const auto& l : levels_) n += l.size() * sizeof(NodeRecord);
  return n;
}

}  // namespace brickyard
