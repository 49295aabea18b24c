#pragma once
/// @file cell_groups.h
/// @brief Empty-space skipping inside a brick: its trilinear cells grouped into cubes of
/// kCellGroup^3, each with its chessboard (L-infinity) distance, in groups, to the nearest
/// group whose voxel values could show something. Distance d > 0 says the (2d - 1)^3 groups
/// centred on it are all clear, so a ray leaps to where it leaves that cube in one step
/// (Cohen and Sheffer's proximity clouds, at group resolution). Clear groups that touch share
/// their boundary voxels, so a connected clear region lies between the same two isovalues:
/// any voxel of the group a ray is in stands for the sign of every value in the cube.

#include <algorithm>
#include <cstdint>

namespace brickyard::gigavoxels {

inline constexpr int kCellGroup = 4;

/// The largest distance kept: farther than any brick is wide in groups (M <= 81).
inline constexpr uint8_t kFarGroup = 255;

/// @brief In place over a g^3 grid (x fastest): 0 stays 0 (visible), anything else becomes the
/// chessboard distance to the nearest 0, or kFarGroup when there is none. Two raster passes
/// over the 26-neighbourhood with unit weights, which is exact for the chessboard metric.
inline void chessboard_distances(int g, uint8_t* d) {
  const auto at = [g](int x, int y, int z) { return (size_t(z) * size_t(g) + size_t(y)) * size_t(g) + size_t(x); };
  for (size_t i = 0, n = size_t(g) * size_t(g) * size_t(g); i < n; ++i)
    if (d[i]) d[i] = kFarGroup;
  // Forward: the 13 neighbours before a group in raster order; backward: the 13 after it.
  for (int pass = 0; pass < 2; ++pass) {
    const int s = pass == 0 ? -1 : 1;
    for (int zi = 0; zi < g; ++zi)
      for (int yi = 0; yi < g; ++yi)
        for (int xi = 0; xi < g; ++xi) {
          const int x = pass == 0 ? xi : g - 1 - xi, y = pass == 0 ? yi : g - 1 - yi, z = pass == 0 ? zi : g - 1 - zi;
          uint8_t& v = d[at(x, y, z)];
          if (v == 0) continue;
          int best = v;
          for (int dz = 0; dz <= 1; ++dz)
            for (int dy = dz ? -1 : 0; dy <= 1; ++dy)
              for (int dx = (dz || dy) ? -1 : 1; dx <= 1; ++dx) {
                const int nx = x + s * dx, ny = y + s * dy, nz = z + s * dz;
                if (nx < 0 || ny < 0 || nz < 0 || nx >= g || ny >= g || nz >= g) continue;
                best = std::min(best, int(d[at(nx, ny, nz)]) + 1);
              }
          v = uint8_t(std::min(best, int(kFarGroup)));
        }
  }
}

}  // namespace brickyard::gigavoxels
