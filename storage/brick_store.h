#pragma once
/// @file brick_store.h
/// @brief A multiresolution brick store on disk: one LMDB environment per dataset directory
/// with the databases `manifest` (JSON), `nodes` (the node table) and `bricks` (brick records
/// keyed by the big-endian level-major Morton code of their BrickKey).
///
/// BrickStore opens a store for reading. It loads the manifest and the whole node table at
/// open, after which every member is const and safe to call from many threads; each thread
/// (or task) that reads records zero-copy takes its own ReadTxn. StoreWriter builds one.

#include <cstddef>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "storage/brick_codec.h"
#include "storage/layout.h"
#include "storage/lmdb_env.h"
#include "storage/manifest.h"

namespace brickyard {

inline constexpr const char* kManifestDb = "manifest";
inline constexpr const char* kNodesDb = "nodes";
inline constexpr const char* kBricksDb = "bricks";

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

class BrickStore {
 public:
  struct OpenOptions {
    bool allow_incomplete = false;  ///< for `info` and `verify`, which report incomplete stores
  };

  /// @throws Error(not_found) no such directory; Error(format) not a store or incomplete;
  ///         Error(unsupported) a newer format version.
  explicit BrickStore(const std::string& dir, OpenOptions options);
  explicit BrickStore(const std::string& dir) : BrickStore(dir, OpenOptions{}) {}
  ~BrickStore();

  const std::string& path() const { return path_; }
  const Manifest& manifest() const { return manifest_; }
  const StoreLayout& layout() const { return layout_; }
  const BrickFormat& format() const { return manifest_.format; }
  const NodeTable& nodes() const { return nodes_; }

  /// @brief A read snapshot for zero-copy record access from the calling thread.
  lmdb::ReadTxn begin_read() const { return lmdb::ReadTxn(*env_); }
  /// @brief The stored record of a brick (nullopt for constant nodes, which have none).
  std::optional<std::span<const std::byte>> record(const lmdb::ReadTxn& txn, const BrickKey& key) const;
  /// @brief Decodes a brick into `out` (format().bytes()); constant nodes are filled with their
  /// value. Errors name the key: not_found outside the layout or for a missing record,
  /// corrupt for a record that fails its checks.
  void read_brick(const lmdb::ReadTxn& txn, const BrickKey& key, std::span<std::byte> out) const;
  void read_brick(const BrickKey& key, std::span<std::byte> out) const;
  /// @brief Calls f(key, record) for every stored brick record in key order.
  void for_each_record(const lmdb::ReadTxn& txn,
                       const std::function<bool(const BrickKey&, std::span<const std::byte>)>& f) const;
  uint64_t record_count() const;

 private:
  std::string path_;
  std::unique_ptr<lmdb::Env> env_;
  lmdb::Database manifest_db_, nodes_db_, bricks_db_;
  Manifest manifest_;
  StoreLayout layout_;
  NodeTable nodes_;
};

/// @brief Writes a new store. The constructor commits a manifest with complete = false before
/// anything else; finish() commits the node table and the final manifest (complete = true) in
/// the last transaction, after everything before it is on disk.
class StoreWriter {
 public:
  StoreWriter(const std::string& dir, const Manifest& initial, const lmdb::EnvOptions& options,
              uint64_t batch_bytes = uint64_t(32) << 20);
  ~StoreWriter();

  void put_brick(const BrickKey& key, std::vector<std::byte>&& record);
  void finish(const Manifest& final_manifest, const NodeTable& nodes);

  lmdb::Env& env() { return *env_; }
  uint64_t bytes_written() const { return writer_->committed_bytes() + writer_->pending_bytes(); }

 private:
  std::unique_ptr<lmdb::Env> env_;
  lmdb::Database manifest_db_, nodes_db_, bricks_db_;
  std::unique_ptr<lmdb::BatchWriter> writer_;
};

/// @brief Reads the manifest of a store without loading anything else (allowing incomplete).
Manifest read_manifest(const std::string& dir);

}  // namespace brickyard
