#pragma once
/// @file store.h
/// @brief A dataset's store on disk: one LMDB environment per dataset directory. The database
/// `manifest` (JSON) says what the dataset is (its kind); the others hold its records:
/// - a grid (kind `structured`): `nodes` (the node table) and `bricks` (brick records keyed by
///   the big-endian level-major Morton code of their BrickKey); a grid of several time steps
///   (format version 3) has a node table per step and keys that start with the big-endian step,
///   so that each step's records are contiguous;
///   and, once build-octree has run, `octree` (octree volume pages keyed by the big-endian id
///   of dataset/octree.h);
/// - a tetrahedral mesh: `tet_clusters` (the cluster table) and `tets` (cluster page records
///   keyed by the big-endian cluster index).
///
/// Store opens a store for reading. It loads the manifest and the whole node or cluster table
/// at open, after which every member is const and safe to call from many threads; each thread
/// (or task) that reads records zero-copy takes its own ReadTxn. Store is the PageSource the
/// cache reads through, and hands out the Dataset (generic part and typed views) that back
/// ends see; both stay valid while the Store lives. StoreWriter builds one.

#include <cstddef>
#include <memory>
#include <atomic>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "dataset/dataset.h"
#include "dataset/grid.h"
#include "dataset/pages.h"
#include "storage/brick_codec.h"
#include "storage/lmdb_env.h"
#include "storage/manifest.h"

namespace brickyard {

inline constexpr const char* kManifestDb = "manifest";
inline constexpr const char* kNodesDb = "nodes";
inline constexpr const char* kBricksDb = "bricks";
inline constexpr const char* kTetClustersDb = "tet_clusters";
inline constexpr const char* kTetsDb = "tets";
inline constexpr const char* kOctreeDb = "octree";

/// @brief Whether `dir` holds an LMDB environment (data.mdb), complete or not.
bool is_store_directory(const std::string& dir);
enum class StoreState {
  absent,       ///< no directory, or an empty one
  not_a_store,  ///< something else is there: never overwrite it
  incomplete,   ///< a store whose build did not finish (or never wrote its manifest)
  complete,
};
/// @brief What is at `dir`, for deciding whether a build may (re)write it.
StoreState probe_store(const std::string& dir);

/// @brief Deletes a store's LMDB files (data.mdb, lock.mdb) and nothing else.
void remove_store_files(const std::string& dir);

class Store : public PageSource {
 public:
  struct OpenOptions {
    bool allow_incomplete = false;  ///< for `info` and `verify`, which report incomplete stores
    bool writable = false;          ///< for build-octree, which adds a database (OctreeWriter)
  };

  /// @throws Error(not_found) no such directory; Error(format) not a store or incomplete;
  ///         Error(unsupported) a newer format version.
  explicit Store(const std::string& dir, OpenOptions options);
  explicit Store(const std::string& dir) : Store(dir, OpenOptions{}) {}
  ~Store() override;
  Store(const Store&) = delete;  // its Dataset points into it
  Store& operator=(const Store&) = delete;

  const std::string& path() const { return path_; }
  const Manifest& manifest() const { return manifest_; }
  DataKind kind() const { return manifest_.kind; }
  /// @brief What back ends see: the generic part and the typed view of the store's kind (a grid
  /// of several time steps: step 0's).
  const Dataset& dataset() const { return *datasets_.front(); }
  /// @brief Time step `step` of a grid of several (its node table; its value range is the whole
  /// series', so that a transfer function means the same at every step); a mesh's one dataset
  /// holds all its steps. @throws Error(invalid_argument) naming `time_step` outside the steps.
  const Dataset& dataset(int step) const;
  /// @brief The records of time step `step` as a PageSource (the cache's L3 while that step is
  /// shown): the store itself for step 0 and for meshes. @throws as dataset(step).
  const PageSource& step_pages(int step) const;
  int time_steps() const { return manifest_.time_steps; }
  // Grid stores:
  const GridLayout& layout() const { return layout_; }
  const BrickFormat& format() const { return manifest_.format; }
  const NodeTable& nodes() const { return nodes_.front(); }
  /// @brief Time step `step`'s node table, loaded on first use (thread-safe).
  /// @throws Error(invalid_argument) for a step the store does not have; Error(corrupt) for a
  /// damaged table, naming the chunk and the step.
  const NodeTable& nodes(int step) const;
  // Tetrahedral stores:
  const std::vector<TetCluster>& clusters() const { return clusters_; }
  /// @brief Clusters x steps scalar ranges (cluster-major); empty for one time step.
  const std::vector<TetStepRange>& step_ranges() const { return step_ranges_; }
  // Grid stores with an octree volume:
  bool has_octree() const { return manifest_.octree.has_value(); }
  const std::vector<OctreePageRange>& octree_pages() const { return octree_pages_; }
  /// @brief The octree's geometry (any grid store: build-octree asks before there is one).
  OctreeLayout octree_layout() const { return OctreeLayout::make(manifest_.dims, manifest_.format.type); }

  // PageSource: bricks of a grid store, cluster pages of a tetrahedral one.
  const std::string& source_name() const override { return path_; }
  std::vector<PageKindInfo> page_kinds() const override;
  std::unique_ptr<PageReader> open_reader() const override;
  std::string describe(const PageKey& key) const override;
  /// @brief Decodes any page (of time step `step`) into `out` (its kind's page size); errors as
  /// read_brick's.
  PageRead read_page(const lmdb::ReadTxn& txn, const PageKey& key, std::span<std::byte> out, int step = 0) const;

  /// @brief A read snapshot for zero-copy record access from the calling thread.
  lmdb::ReadTxn begin_read() const { return lmdb::ReadTxn(*env_); }
  /// @brief The stored record of a brick of time step `step` (nullopt for constant nodes, which
  /// have none).
  std::optional<std::span<const std::byte>> record(const lmdb::ReadTxn& txn, const BrickKey& key, int step = 0) const;
  /// @brief Decodes a brick into `out` (format().bytes()); constant nodes are filled with their
  /// value. Errors name the key: not_found outside the layout or for a missing record,
  /// corrupt for a record that fails its checks.
  void read_brick(const lmdb::ReadTxn& txn, const BrickKey& key, std::span<std::byte> out, int step = 0) const;
  void read_brick(const BrickKey& key, std::span<std::byte> out, int step = 0) const;
  /// @brief Calls f(key, record) for every stored page record of a kind, in key order.
  void for_each_page(const lmdb::ReadTxn& txn, RecordKind kind,
                     const std::function<bool(const PageKey&, std::span<const std::byte>)>& f) const;
  /// @brief Calls f(key, record) for every stored brick record in key order (of every time step).
  void for_each_record(const lmdb::ReadTxn& txn,
                       const std::function<bool(const BrickKey&, std::span<const std::byte>)>& f) const;
  /// @brief Calls f(step, key, record) for every stored brick record, in step then key order.
  void for_each_step_record(const lmdb::ReadTxn& txn,
                            const std::function<bool(int, const BrickKey&, std::span<const std::byte>)>& f) const;
  /// @brief Stored records of the store's page kind (bricks, or cluster pages).
  uint64_t record_count() const;

 private:
  friend class OctreeWriter;
  // Each reads from `txn`, the constructor's one snapshot of the store (see Store::Store).
  void load_node_table(const lmdb::ReadTxn& txn, int step) const;
  void check_step(int step) const;
  void load_cluster_table(const lmdb::ReadTxn& txn);
  void load_octree_table(const lmdb::ReadTxn& txn);
  PageRead read_octree_page(const lmdb::ReadTxn& txn, const PageKey& key, std::span<std::byte> out) const;

  std::string path_;
  std::unique_ptr<lmdb::Env> env_;
  lmdb::Database manifest_db_, nodes_db_, bricks_db_, clusters_db_, tets_db_, octree_db_;
  Manifest manifest_;
  GridLayout layout_;
  /// One per time step of a grid, sized at open, never after; each filled once under
  /// steps_mutex_ (step 0 at open, the others when first asked for), then read-only: its
  /// steps_loaded_ flag, set after, is what readers check.
  mutable std::vector<NodeTable> nodes_;
  std::unique_ptr<std::atomic<bool>[]> steps_loaded_;
  mutable std::mutex steps_mutex_;
  std::vector<TetCluster> clusters_;
  std::vector<TetStepRange> step_ranges_;
  std::vector<OctreePageRange> octree_pages_;
  std::vector<std::unique_ptr<Dataset>> datasets_;        ///< one per time step of a grid
  std::vector<std::unique_ptr<PageSource>> step_sources_;  ///< steps 1 and later of a grid
};

/// @brief Writes a new store of the initial manifest's kind. The constructor commits a manifest
/// with complete = false before anything else; finish() commits the node or cluster table and
/// the final manifest (complete = true) in the last transaction, after everything before it is
/// on disk.
class StoreWriter {
 public:
  StoreWriter(const std::string& dir, const Manifest& initial, const lmdb::EnvOptions& options,
              uint64_t batch_bytes = uint64_t(32) << 20);
  ~StoreWriter();

  /// @brief Reopens the incomplete grid store a killed build left, to resume it from its last
  /// checkpoint: its manifest stays incomplete until finish().
  static std::unique_ptr<StoreWriter> reopen(const std::string& dir, const lmdb::EnvOptions& options,
                                             uint64_t batch_bytes = uint64_t(32) << 20);
  /// @brief Commits everything put so far and, in the same transaction, the build's state
  /// (LZ4-compressed, checksummed, opaque here): a killed build resumes from the last one.
  /// finish() removes it in the last transaction.
  void put_checkpoint(std::span<const std::byte> state);

  /// @brief A grid store's encoded brick record (encode_brick), of time step `step`.
  void put_brick(const BrickKey& key, std::vector<std::byte>&& record, int step = 0);
  /// @brief A grid of several time steps: the node table of a step, written when the step is
  /// built (committed with the next checkpoint); finish_series() then commits the manifest.
  void put_step_nodes(int step, const NodeTable& nodes);
  /// @brief A tetrahedral store's cluster page (its used bytes; encoded here).
  void put_cluster(uint64_t cluster, std::span<const std::byte> page);
  /// @brief A cluster page already encoded (encode_page), for builders that compress in parallel.
  void put_cluster_record(uint64_t cluster, std::vector<std::byte>&& record);
  void finish(const Manifest& final_manifest, const NodeTable& nodes);
  /// @brief A grid of several time steps, every step's node table put: the final manifest.
  void finish_series(const Manifest& final_manifest);
  /// @param step_ranges  clusters x time steps ranges (cluster-major) for more than one step.
  void finish(const Manifest& final_manifest, const std::vector<TetCluster>& clusters,
              const std::vector<TetStepRange>& step_ranges = {});

  lmdb::Env& env() { return *env_; }
  uint64_t bytes_written() const { return writer_->committed_bytes() + writer_->pending_bytes(); }

 private:
  StoreWriter() = default;
  void commit_final(Manifest m);

  DataKind kind_ = DataKind::structured;
  int time_steps_ = 1;
  std::unique_ptr<lmdb::Env> env_;
  lmdb::Database manifest_db_, nodes_db_, bricks_db_, clusters_db_, tets_db_;
  std::unique_ptr<lmdb::BatchWriter> writer_;
};

/// @brief Writes an octree volume into a grid store opened writable: the constructor removes any
/// octree the store had (its manifest entry first, then its pages), so an interrupted build
/// leaves a grid without an octree, never a half one; finish() records the summary in the
/// manifest in the last transaction, after every page is durable.
///
/// Not thread-safe; reads of the store may go on beside it on other threads, each in short
/// transactions (the map may grow when a batch commits, which needs no read open).
class OctreeWriter {
 public:
  explicit OctreeWriter(Store& store, uint64_t batch_bytes = uint64_t(32) << 20);
  ~OctreeWriter();
  /// @brief A page's used bytes (encoded here); returns the record's size.
  size_t put_page(uint64_t id, std::span<const std::byte> page);
  /// @brief Commits the page table (every page written, sorted by id here) and records
  /// `summary` (its build parameters included) in the manifest, in the last transaction.
  void finish(const OctreeSummary& summary, std::vector<OctreePageRange> pages);

 private:
  Store& store_;
  std::unique_ptr<lmdb::BatchWriter> writer_;
};

/// @brief Reads the manifest of a store without loading anything else (allowing incomplete).
Manifest read_manifest(const std::string& dir);

/// @brief The build state of an incomplete store's last checkpoint (StoreWriter::put_checkpoint),
/// decoded; nullopt when it has none, or one that fails its checksum (the build then starts over).
std::optional<std::vector<std::byte>> read_build_checkpoint(const std::string& dir);

}  // namespace brickyard
