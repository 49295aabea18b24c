#pragma once
/// @file box_filter.h
/// @brief The grid's 2x filter of 8 voxels into one coarser voxel, and rounding into a value
/// type: shared by the brick pyramid's build and the octree's, so that the octree's levels past
/// the store's coarsest are the ones the store would have built.

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <type_traits>

#include "preprocess/builder.h"

namespace brickyard {

/// @brief v rounded into T: floats as they are, integers to nearest and clamped to T's range.
template <typename T>
T round_to(double v) {
  if constexpr (std::is_same_v<T, float>) return static_cast<float>(v);
  else
    return static_cast<T>(
        std::clamp(std::lround(v), long(std::numeric_limits<T>::lowest()), long(std::numeric_limits<T>::max())));
}

/// @brief One coarser voxel from 8 (index dx + 2 dy + 4 dz): their average (floats summed in
/// pairs; integers rounded half up), minimum or maximum.
template <typename T>
T filter_8(const T (&v)[8], Downsample mode) {
  if (mode == Downsample::min) return *std::min_element(v, v + 8);
  if (mode == Downsample::max) return *std::max_element(v, v + 8);
  if constexpr (std::is_same_v<T, float>) {
    return ((v[0] + v[1]) + (v[2] + v[3]) + (v[4] + v[5]) + (v[6] + v[7])) * 0.125f;
  } else {
    int32_t sum = 4;  // round half up (an arithmetic shift floors negative sums too)
    for (T x : v) sum += x;
    return static_cast<T>(sum >> 3);
  }
}

}  // namespace brickyard
