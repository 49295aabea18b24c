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

#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>
#include <utility>

#include "core/resources.h"
#include "preprocess/octree_builder.h"
#include "storage/brick_codec.h"
#include "storage/lmdb_env.h"
#include "storage/manifest.h"
#include "storage/store_lock.h"

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
  /// How coarser levels are made; unset: Downsample::min for level sets, else average.
  std::optional<Downsample> downsample;
  /// The data is a level set (`--level-set`; a source whose is_level_set() says so is one
  /// anyway): recorded in the build, and coarser levels keep its zero crossing by default.
  bool level_set = false;
  /// Without a background given, a brick is constant (stored without payload, at the middle of
  /// its range) when max - min over its voxels, apron included, is at most this; with one, only
  /// a brick whose every voxel lies within this of the background is, at the background (empty),
  /// and every other brick stays exact.
  double constant_tolerance = 0.0;
  /// The value of empty space (stored units): constant bricks within constant_tolerance of it
  /// are flagged empty. Unset: the source's (0, or OpenVDB's background).
  std::optional<double> background;
  /// Take the background from the volume's border (estimate_background) instead.
  bool background_auto = false;
  /// Clamp every source value into [lo, hi] (stored units).
  std::optional<std::pair<double, double>> clamp;
  NonFinite nonfinite = NonFinite::reject;
  uint64_t map_size = 0;          ///< initial LMDB map size; 0 picks one from the input size
  bool map_growth = true;
  uint64_t batch_bytes = uint64_t(32) << 20;
  /// Rebuild a complete store whose source or parameters differ (an incomplete one is always
  /// rebuilt; a complete, identical one is left alone).
  bool force = false;
  /// Refuse to start when the free disk is below the store's worst case (estimate_build_needs);
  /// off for data known to compress well. Memory is always checked.
  bool check_disk = true;
  /// At most this many seconds between checkpoints of the build's state (at finest brick-row
  /// boundaries), from which a killed import resumes; a checkpoint waits longer when it would
  /// cost over 5% of the time since the last. 0: after every brick row (tests, crash drills).
  double checkpoint_seconds = 5.0;
  /// Also build the octree volume (import --octree), before the store is put in place: the
  /// store is built beside its path and appears there only with its octree, never as a
  /// complete grid without the octree asked for.
  std::optional<OctreeBuildOptions> octree;
};

struct BuildResult {
  Manifest manifest;
  bool up_to_date = false;  ///< nothing was done: the store was complete and identical
  bool rebuilt_incomplete = false;
  /// The finest slices an interrupted build had done when this one resumed it (0: from the start).
  int64_t resumed_at_slice = 0;
  /// The time step a series build resumed in (0: the first, or from the start).
  int resumed_at_step = 0;
  double seconds = 0;          ///< the bricks' build
  double octree_seconds = 0;   ///< BuildOptions::octree's build, when asked for
  uint64_t input_bytes = 0;
  uint64_t stored_bytes = 0;
  /// What the user should know about the data though the build succeeded (value_range_warnings).
  std::vector<std::string> warnings;
  /// What converting the source's elements did (u32, i32, f64 files), when they were converted.
  std::optional<std::string> conversion;
};

/// @brief Warnings for a value range single precision handles badly: values within a factor of
/// 2 of the largest float (a difference of two voxels of opposite sign may overflow), or every
/// value but zero denormal (below the smallest normal float, where precision runs out).
std::vector<std::string> value_range_warnings(double min_value, double max_value);

/// @brief Where a build writes, and how what it wrote takes the store's place; every builder of
/// a store (grids, meshes) goes through one.
///
/// The constructor takes the store's write lock (storage/store_lock.h), held until the
/// destructor, so a second writer is refused before it looks at the store and never takes a
/// live build for an interrupted one. It reclaims what a killed rebuild left beside the store
/// (below), then decides by what is at `dir`:
/// - nothing (or an empty directory): built in place;
/// - an incomplete store, which with the lock held is an interrupted build: resumed from its
///   last checkpoint when that is of the same source and parameters (resume_state(); not with
///   publish_whole), else removed (result.rebuilt_incomplete) and built in place;
/// - a complete store from the same source and parameters: left alone (up_to_date(),
///   result.manifest is its manifest) unless `force`;
/// - another complete store: refused without `force`; with it, rebuilt beside: path() is
///   `.NAME.rebuilding` next to NAME, and commit() swaps it into NAME's place (one atomic
///   renameat2 exchange where the file system has it, else NAME renamed to `.NAME.replaced` and
///   the rebuild renamed to NAME) and removes the old store. Until then the old store stays
///   complete and readable; a build that fails leaves it as it was, and the destructor removes
///   the unfinished rebuild. (A store that is a mount point of its own cannot be swapped, no
///   rename crossing file systems: it is removed and rebuilt in place.)
/// - anything that is not a store: refused, never overwritten.
///
/// After a kill, the next writer reclaims the siblings: a rebuild is removed; an old store set
/// aside is removed when NAME is there, and when NAME is missing (a kill between the fallback's
/// two renames) the complete rebuild goes into place, or else the old store goes back.
class StoreBuildTarget {
 public:
  /// @param publish_whole build beside the path even when nothing is there, so that the store
  /// appears only once commit() puts it, whole, in place (for work after the bricks: an octree).
  StoreBuildTarget(const std::string& dir, const std::string& source_json, const std::string& build_json, bool force,
                   BuildResult& result, bool publish_whole = false);
  /// @brief Removes a rebuild that commit() did not put in place; releases the lock.
  ~StoreBuildTarget();
  StoreBuildTarget(const StoreBuildTarget&) = delete;
  StoreBuildTarget& operator=(const StoreBuildTarget&) = delete;

  bool up_to_date() const { return up_to_date_; }
  /// @brief The state of an interrupted build of this same import found in place (an incomplete
  /// store whose checkpoint has the same source and parameters): the build resumes from it.
  std::optional<std::vector<std::byte>>& resume_state() { return resume_state_; }
  /// @brief Whether the store or checkpoint in place was built from this same file, checked
  /// then and unchanged since (VolumeSource::verify_content() need not run again): the same
  /// path, size and checksum, and the same "checked_mtime_ns".
  bool source_checked_before(const std::string& source_json) const;
  /// @brief The directory to build in: `dir`, or the rebuild beside it.
  const std::string& path() const { return path_; }
  /// @brief The store's write lock, held until this target is destroyed.
  const StoreWriteLock& lock() const { return lock_; }
  /// @brief Puts the finished store in place; its StoreWriter must be closed. Nothing to do for
  /// a store built in place. @throws Error(io) when a rename fails (the old store is then back).
  void commit();

 private:
  void reclaim();

  StoreWriteLock lock_;
  std::string dir_, real_, path_, rebuilding_, replaced_;
  std::string previous_source_;  // the source description of the store or checkpoint in place
  bool up_to_date_ = false, beside_ = false, committed_ = false;
  std::optional<std::vector<std::byte>> resume_state_;
};

/// @brief What build_store needs for a grid of `dims` `type` values with `options`, on
/// `threads` threads; pure, so that tests give it numbers.
/// - Memory, its peak: every level's ring of M + A + max(A, 1) slices, the finest level's row of
///   bricks as LZ4 leaves them (each at the compress bound), the node table, the writer's queue
///   and batch, and each thread's gather and histogram; an f32 source's pre-pass (one slab) comes
///   before all of them, so the peak is the larger of the two.
/// - Disk, an upper bound (the compressed size cannot be known): every brick of every level
///   stored at LZ4's worst case, its apron included, on whole 4 KiB LMDB pages, plus the node
///   table, plus an eighth for the B-tree and the pages LMDB has freed but not yet reused. Data
///   that compresses needs far less: BuildOptions::check_disk turns its check off.
ResourceNeeds estimate_build_needs(const Vec3s& dims, ValueType type, const BuildOptions& options, int threads);

/// @brief Builds (or rebuilds) the store in `dir` from `source`, through a StoreBuildTarget.
/// Before reading the source, refuses (Errc::resource) a build whose estimate_build_needs do not
/// fit the memory available or, with check_disk, the free disk.
/// @throws Error naming the source or the store; a failed build leaves an incomplete store, or,
/// for a rebuild beside a complete one, the old store as it was.
BuildResult build_store(VolumeSource& source, const std::string& dir, const BuildOptions& options,
                        Progress* progress = nullptr);

/// @brief Builds a store of several time steps of one grid, one source a step (every one of
/// step 0's dims, type, spacing and origin, else Error(format) naming the step's file), as
/// build_store builds one: step after step, each step's records and node table under keys that
/// carry the step (storage/store.h), every step flattened against step 0's background. A killed
/// build resumes within the step it was building; the steps before it are not read again.
/// With one source it is build_store. BuildOptions::octree is refused for several steps.
BuildResult build_series(std::span<VolumeSource* const> sources, const std::string& dir, const BuildOptions& options,
                         Progress* progress = nullptr);

}  // namespace brickyard
