#pragma once
/// @file corner_lanes.h
/// @brief The corner values of 8 trilinear cells of one brick side by side, for a DVR sample
/// run (dvr.cpp, sample_run): AVX2 gathers where the voxels are 16-bit (either sign) or float, one
/// load at a time otherwise.

#include <cstdint>
#include <cstring>
#include <type_traits>

#if defined(__AVX2__)
#include <immintrin.h>
#endif

namespace brickyard::gigavoxels {

/// @brief The 8 corners (index dx + 2 dy + 4 dz) of the 8 cells whose lower corners lie at
/// `offset` in `brick` (rows of e voxels, slices of e^2), per corner then cell, in float.
template <typename Voxel>
inline void load_cell_corners(const Voxel* brick, const int32_t (&offset)[8], int32_t e, float (&corner)[8][8]) {
  const int32_t row[4] = {0, e, e * e, e * e + e};  // the 4 rows of 2 corners along x
#if defined(__AVX2__)
  if constexpr (std::is_same_v<Voxel, uint16_t> || std::is_same_v<Voxel, int16_t>) {
    // A row's two corners in one 32-bit read (low half, high half: x86 is little-endian): 4
    // gathers for 8 corners of 8 cells, against 64 loads. The last read ends at the cell's last
    // corner, inside the brick.
    __m256i at;
    std::memcpy(&at, offset, sizeof at);
    [[maybe_unused]] const __m256i low16 = _mm256_set1_epi32(0xffff);
    for (int r = 0; r < 4; ++r) {
      const __m256i index = _mm256_add_epi32(at, _mm256_set1_epi32(row[r]));
      const __m256i pair = _mm256_i32gather_epi32(reinterpret_cast<const int*>(brick), index, sizeof(Voxel));
      if constexpr (std::is_signed_v<Voxel>) {  // sign-extend each half
        _mm256_storeu_ps(corner[2 * r], _mm256_cvtepi32_ps(_mm256_srai_epi32(_mm256_slli_epi32(pair, 16), 16)));
        _mm256_storeu_ps(corner[2 * r + 1], _mm256_cvtepi32_ps(_mm256_srai_epi32(pair, 16)));
      } else {
        _mm256_storeu_ps(corner[2 * r], _mm256_cvtepi32_ps(_mm256_and_si256(pair, low16)));
        _mm256_storeu_ps(corner[2 * r + 1], _mm256_cvtepi32_ps(_mm256_srli_epi32(pair, 16)));
      }
    }
    return;
  } else if constexpr (std::is_same_v<Voxel, float>) {
    __m256i at;
    std::memcpy(&at, offset, sizeof at);
    for (int r = 0; r < 4; ++r) {
      const __m256i index = _mm256_add_epi32(at, _mm256_set1_epi32(row[r]));
      _mm256_storeu_ps(corner[2 * r], _mm256_i32gather_ps(brick, index, sizeof(float)));
      _mm256_storeu_ps(corner[2 * r + 1], _mm256_i32gather_ps(brick + 1, index, sizeof(float)));
    }
    return;
  }
#endif
  for (int k = 0; k < 8; ++k)
    for (int r = 0; r < 4; ++r) {
      const Voxel* q = brick + offset[k] + row[r];
      corner[2 * r][k] = float(q[0]), corner[2 * r + 1][k] = float(q[1]);
    }
}

}  // namespace brickyard::gigavoxels
