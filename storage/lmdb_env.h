#pragma once
/// @file lmdb_env.h
/// @brief A thin, safe wrapper over one LMDB environment: named databases, read transactions
/// with zero-copy reads, and batched writes that grow the map on MDB_MAP_FULL.
///
/// Only storage/*.cpp include <lmdb.h>; this header forward-declares LMDB's handles.
///
/// Contracts (from lmdb.h, restated because callers rely on them):
/// - One Env per dataset directory per process; never open the same directory twice.
/// - ReadTxn: the environment is opened with MDB_NOTLS, so a read transaction is not tied to
///   the thread that began it and many may be open at once, one per thread or per task. A
///   single ReadTxn must not be used by two threads at the same time. Values returned by
///   get() point into the memory map and stay valid until that transaction ends; keep read
///   transactions short, since a long one pins old pages and makes the file grow.
/// - Writes go through BatchWriter: one writer at a time (LMDB serialises writers), records
///   buffered in memory and committed every `batch_bytes`. On MDB_MAP_FULL the batch is
///   aborted, the map doubled (up to max_map_size) and the batch replayed, so callers never
///   see a full map unless growth is disabled or exhausted.
/// - Every LMDB error becomes brickyard::Error naming the environment path, the database and
///   the key; LMDB return codes are turned into text in one place (lmdb_env.cpp).

#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

struct MDB_env;
struct MDB_txn;

namespace brickyard::lmdb {

using Bytes = std::span<const std::byte>;

/// @brief Views a trivially copyable object or a string as bytes.
inline Bytes as_bytes(std::string_view s) { return {reinterpret_cast<const std::byte*>(s.data()), s.size()}; }

struct EnvOptions {
  uint64_t map_size = uint64_t(1) << 30;      ///< initial map size (a sparse file reserves nothing)
  uint64_t max_map_size = uint64_t(1) << 44;  ///< growth stops here (16 TiB)
  bool growth = true;                         ///< false: MDB_MAP_FULL is an error
  bool read_only = false;
  bool no_sync = false;  ///< bulk builds: skip fsync per commit; call sync() before declaring success
  bool random_access = true;  ///< MDB_NORDAHEAD: no kernel read-ahead (bricks are read at random)
  unsigned max_dbs = 8;
  unsigned max_readers = 254;
};

/// @brief A database handle inside an environment, with its name for error messages.
struct Database {
  unsigned dbi = 0;
  std::string name;
};

class Env {
 public:
  /// @brief Opens (or, unless read_only, creates) the environment in directory `dir`.
  Env(const std::string& dir, const EnvOptions& options);
  ~Env();
  Env(const Env&) = delete;
  Env& operator=(const Env&) = delete;

  /// @brief Opens a named database; creates it when the environment is writable and
  /// `create` is set. A missing database in read-only mode is Error(not_found).
  Database open_database(const std::string& name, bool create);
  /// @brief Deletes every record of a database in one committed transaction (mdb_drop).
  void clear_database(const Database& db);
  /// @brief Whether a named database exists.
  bool has_database(const std::string& name);
  /// @brief Names of the named databases, and whether the main database holds anything else.
  std::vector<std::string> database_names(bool* other_records = nullptr);

  /// @brief Flushes the map to disk (fsync), even when opened with no_sync.
  void sync();
  /// @brief Turns per-commit syncing on or off for later commits.
  void set_no_sync(bool no_sync);
  uint64_t map_size() const;
  /// @brief Doubles the map (bounded by max_map_size); false when growth is not possible.
  /// Requires that this process has no transaction open in the environment.
  bool grow();

  const std::string& path() const { return path_; }
  const EnvOptions& options() const { return options_; }
  MDB_env* handle() const { return env_; }

 private:
  std::string path_;
  EnvOptions options_;
  MDB_env* env_ = nullptr;
};

/// @brief A read-only snapshot. See the contract at the top of this file.
class ReadTxn {
 public:
  explicit ReadTxn(Env& env);
  ~ReadTxn();
  ReadTxn(ReadTxn&& other) noexcept : env_(other.env_), txn_(other.txn_) { other.txn_ = nullptr; }
  ReadTxn(const ReadTxn&) = delete;
  ReadTxn& operator=(const ReadTxn&) = delete;

  /// @brief Zero-copy lookup: the bytes live in the map until this transaction ends.
  std::optional<Bytes> get(const Database& db, Bytes key) const;
  /// @brief Calls f(key, value) for every record in key order; f returns false to stop.
  void for_each(const Database& db, const std::function<bool(Bytes key, Bytes value)>& f) const;
  /// @brief Number of records in a database.
  uint64_t count(const Database& db) const;

 private:
  Env* env_;
  MDB_txn* txn_ = nullptr;
};

/// @brief Buffers puts and commits them in batches; see the contract at the top of this file.
/// Not thread-safe: one thread (the store's writer) owns it.
class BatchWriter {
 public:
  BatchWriter(Env& env, uint64_t batch_bytes = uint64_t(32) << 20);
  /// @brief Discards uncommitted records (a failed build must not commit half a batch).
  ~BatchWriter() = default;

  void put(const Database& db, Bytes key, Bytes value);
  void put(const Database& db, Bytes key, std::vector<std::byte>&& value);
  /// @brief Deletes a key (no error if absent), in the current batch.
  void erase(const Database& db, Bytes key);
  /// @brief Commits everything buffered so far as one transaction.
  void commit();

  uint64_t committed_bytes() const { return committed_bytes_; }
  uint64_t commits() const { return commits_; }
  uint64_t pending_bytes() const { return pending_bytes_; }

 private:
  struct Op {
    const Database* db;
    std::vector<std::byte> key;
    std::vector<std::byte> value;
    bool erase = false;
  };
  Env& env_;
  uint64_t batch_bytes_;
  std::vector<Op> pending_;
  uint64_t pending_bytes_ = 0, committed_bytes_ = 0, commits_ = 0;
};

/// @brief Text of an LMDB return code (mdb_strerror), for messages outside storage/.
std::string error_text(int rc);

}  // namespace brickyard::lmdb
