#pragma once
/// @file builder.h
/// @brief The streaming, parallel multiresolution build: a VolumeSource in, a complete brick
/// store out.
///
/// One pass over the source, in z order. Each level keeps a ring of M + A + max(A, 1) slices
/// (one brick row with its aprons and forward neighbours) and feeds every pair of its slices,
/// 2x filtered, to the next coarser level, so all levels are built at once and memory is a
/// few brick slabs per level whatever the volume size. Bricks of a row are cut, summarised
/// and compressed in parallel (TBB); a writer thread commits them to LMDB in batches. The
/// store claims to be complete only in its very last transaction.

#include <cstdint>
#include <optional>
#include <string>
#include <vector>
#include <utility>

#include "storage/brick_codec.h"
#include "storage/lmdb_env.h"
#include "storage/manifest.h"

namespace brickyard {

class Progress;
class VolumeSource;

enum class Downsample { average, min, max };
enum class NonFinite { reject, zero, clamp };
std::string_view to_string(Downsample d);
std::string_view to_string(NonFinite n);
Downsample parse_downsample(std::string_view s);
NonFinite parse_nonfinite(std::string_view s);

struct BuildOptions {
  int brick_size = 32;
  int apron = 1;
  Codec codec = Codec::lz4;
  int hc_level = 9;
  bool shuffle = true;
  Downsample downsample = Downsample::average;
  /// A brick is constant (stored without payload) when max - min over its voxels, apron
  /// included, is at most this.
  double constant_tolerance = 0.0;
  /// Clamp every source value into [lo, hi] (stored units).
  std::optional<std::pair<double, double>> clamp;
  NonFinite nonfinite = NonFinite::reject;
  uint64_t map_size = 0;          ///< initial LMDB map size; 0 picks one from the input size
  bool map_growth = true;
  uint64_t batch_bytes = uint64_t(32) << 20;
  /// Rebuild a complete store whose source or parameters differ (an incomplete one is always
  /// rebuilt; a complete, identical one is left alone).
  bool force = false;
};

struct BuildResult {
  Manifest manifest;
  bool up_to_date = false;  ///< nothing was done: the store was complete and identical
  bool rebuilt_incomplete = false;
  double seconds = 0;
  uint64_t input_bytes = 0;
  uint64_t stored_bytes = 0;
  /// What the user should know about the data though the build succeeded (value_range_warnings).
  std::vector<std::string> warnings;
};

/// @brief Warnings for a value range single precision handles badly: values within a factor of
/// 2 of the largest float (a difference of two voxels of opposite sign may overflow), or every
/// value but zero denormal (below the smallest normal float, where precision runs out).
std::vector<std::string> value_range_warnings(double min_value, double max_value);

/// @brief Decides what to do with whatever is at `dir` before a build: nothing there goes
/// ahead; an incomplete store is removed (result.rebuilt_incomplete); a complete one from the
/// same source and parameters is left alone (returns true: up to date, result.manifest is
/// its manifest) unless `force`, in which case, as for a different one, it is removed; a
/// different complete store without `force` and anything that is not a store are refused.
bool prepare_store_directory(const std::string& dir, const std::string& source_json, const std::string& build_json,
                             bool force, BuildResult& result);

/// @brief Builds (or rebuilds) the store in `dir` from `source`.
/// @throws Error naming the source or the store; a failed build leaves an incomplete store.
BuildResult build_store(VolumeSource& source, const std::string& dir, const BuildOptions& options,
                        Progress* progress = nullptr);

}  // namespace brickyard
