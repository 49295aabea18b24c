#pragma once
/// @file face_lighting.h
/// @brief How much of a lit DVR segment each end's lighting stands for. The analytic gradient
/// of the trilinear interpolant, and so the lighting, is smooth inside a cell and jumps at its
/// faces; shading a segment with the mean of its ends' lighting errs by the share of the
/// segment on the wrong side of a face, which made lit DVR converge to first order in the
/// step. Each end's lighting stands instead for the part of the segment in its own cell: up to
/// the first face crossed, and from the last one; the cells between, where the ray takes no
/// sample, take the lighting at their middle (gigavoxels' middle_lighting) or the ends' mean. For analytic normals alone: difference normals are
/// continuous across cell faces.

#include <algorithm>
#include <cstdint>
#include <cstring>

namespace brickyard::gigavoxels {

/// @brief Where a sample fell among its brick's trilinear cells: the cell (its lower corner,
/// in brick voxels) and the position in it, each in [0, 1].
struct CellPoint {
  int32_t cell[3] = {};
  float u[3] = {};
};

/// @brief The first and last cell faces a segment crosses, as fractions of it, each in [0, 1]
/// with first <= last; first = 1 and last = 0 when it crosses none. Between them lie the cells
/// where the ray takes no sample; first < last when there are any (two faces crossed or more).
struct FaceCrossings {
  float first = 1, last = 0;
  /// The fraction of the segment where the cells between are, and its middle.
  bool has_middle() const { return first < last; }
  float middle() const { return 0.5f * (first + last); }
  /// The front end's share when the cells between take the ends' mean (1/2: none crossed).
  float front_weight() const { return has_middle() || first == last ? middle() : 0.5f; }
};

/// @brief FaceCrossings of the segment from a to b (points of one brick's cells).
inline FaceCrossings face_crossings(const CellPoint& a, const CellPoint& b) {
  float first = 1, last = 0;
  for (int k = 0; k < 3; ++k) {
    const int32_t c0 = a.cell[k], c1 = b.cell[k];
    if (c0 == c1) continue;
    // Faces lie at whole coordinates; the span is nonzero, as b lies in another cell.
    const float l0 = float(c0) + a.u[k], inv_span = 1 / (float(c1 - c0) + (b.u[k] - a.u[k]));
    const float first_face = float(c1 > c0 ? c0 + 1 : c0), last_face = float(c1 > c0 ? c1 : c1 + 1);
    first = std::min(first, (first_face - l0) * inv_span);
    last = std::max(last, (last_face - l0) * inv_span);
  }
  if (last < first) return {};  // none crossed
  // A reciprocal's rounding can pass 0 or 1.
  first = std::clamp(first, 0.0f, 1.0f);
  return {first, std::clamp(last, first, 1.0f)};
}

/// @brief face_crossings() for the 8 segments from point k to point k + 1 of a run of 9 points
/// (cells and positions per axis, then point), side by side in 8-lane vectors (GCC's vector
/// extension: AVX2 where the target has it; GCC 12 left the same loop scalar), with the same
/// arithmetic, and so the same results.
inline void face_crossings(const int32_t (&cell)[3][9], const float (&u)[3][9], FaceCrossings (&crossings)[8]) {
  using Floats = float __attribute__((vector_size(32)));
  using Ints = int32_t __attribute__((vector_size(32)));
  Floats first = Floats{} + 1.0f, last = Floats{};
  for (int a = 0; a < 3; ++a) {
    Ints c0, c1;  // (copied into locals: no vector passes through a call, whose ABI differs without AVX)
    Floats u0, u1;
    std::memcpy(&c0, &cell[a][0], sizeof c0), std::memcpy(&c1, &cell[a][1], sizeof c1);
    std::memcpy(&u0, &u[a][0], sizeof u0), std::memcpy(&u1, &u[a][1], sizeof u1);
    const Floats l0 = __builtin_convertvector(c0, Floats) + u0;
    // Where the cell stays the same, the span may be 0 and its quotients infinite or NaN: they
    // are not used (a float division by zero is not undefined: IEEE 754, and UBSan's
    // -fsanitize=undefined leaves it alone).
    const Floats inv_span = 1.0f / (__builtin_convertvector(c1 - c0, Floats) + (u1 - u0));
    const Ints up = (c1 > c0) & 1;  // the first face crossed is c0 + 1 going up, c0 going down; the last c1 or c1 + 1
    const Floats to_first = (__builtin_convertvector(c0 + up, Floats) - l0) * inv_span;
    const Floats to_last = (__builtin_convertvector(c1 + (1 - up), Floats) - l0) * inv_span;
    const Ints same = c0 == c1;
    first = same ? first : (to_first < first ? to_first : first);  // std::min
    last = same ? last : (last < to_last ? to_last : last);        // std::max
  }
  const Ints none = last < first;
  first = first < 0.0f ? Floats{} : (1.0f < first ? Floats{} + 1.0f : first);  // std::clamp
  last = last < first ? first : (1.0f < last ? Floats{} + 1.0f : last);
  first = none ? Floats{} + 1.0f : first;
  last = none ? Floats{} : last;
  for (int k = 0; k < 8; ++k) crossings[k] = {first[k], last[k]};
}

}  // namespace brickyard::gigavoxels
