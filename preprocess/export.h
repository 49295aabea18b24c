#pragma once
/// @file export.h
/// @brief Reading a level of a store back out as a dense region: raw files (with sidecar)
/// and OpenVDB grids.

#include <functional>
#include <optional>
#include <span>
#include <string>

#include "core/math.h"
#include "core/raw_volume.h"

namespace brickyard {

class Store;
class Progress;

/// @brief A box of voxels [lo, hi) at one level of a store.
struct VoxelBox {
  Vec3s lo{0}, hi{0};
  Vec3s size() const { return hi - lo; }
};

/// @brief The whole level, or `box` checked against it (Error(invalid_argument) naming --box).
VoxelBox export_region(const Store& store, int level, const std::optional<VoxelBox>& box);

/// @brief Streams the region of time step `step` in z-slabs (x fastest, the store's value
/// type), decoding each brick row once; memory stays at one row of bricks plus one slab.
void for_each_region_slab(const Store& store, int level, const VoxelBox& region,
                          const std::function<void(int64_t z0, int64_t z1, std::span<const std::byte>)>& sink,
                          Progress* progress = nullptr, int step = 0);

/// @brief Writes the region as PATH (raw, little-endian) plus PATH.json; atomic like generate.
RawVolumeInfo export_raw(const Store& store, int level, const VoxelBox& region, const std::string& path,
                         Progress* progress = nullptr, int step = 0);

/// @brief Writes the region as an OpenVDB file with one float grid named `grid_name`
/// (default: the source grid's name, else "density"). Constant bricks become tiles, voxels equal
/// to the background are inactive; a store imported from a level set is written back as one.
/// Error(unsupported) when brickyard was built without OpenVDB.
void export_vdb(const Store& store, int level, const VoxelBox& region, const std::string& path,
                const std::string& grid_name, Progress* progress = nullptr, int step = 0);

}  // namespace brickyard
