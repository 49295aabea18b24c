#pragma once
/// @file store_lock.h
/// @brief One writer per store: an exclusive flock(2) on `.NAME.lock` beside the store's
/// directory NAME, for every process that writes a store (the builders, build-octree).
///
/// The lock lives beside the directory, not in it, for two reasons: it is needed before the
/// directory exists (a first import), and a rebuild swaps a new directory into NAME's place
/// (StoreBuildTarget), which must not swap the lock with it. Readers take no lock; an LMDB
/// store is safe to read while it is written, and a reader of a store being rebuilt beside
/// keeps the old one until it closes it.
///
/// Contracts:
/// - The lock is held by an open file description, so a second StoreWriteLock on the same
///   store fails in the same process as in another one; it is released when the holder's
///   destructor runs or its process dies (the kernel drops it: a killed writer never leaves a
///   store locked).
/// - The holder writes its pid into the lock file; a writer refused names it.
/// - The holder removes the lock file before it releases it. A process that locked the removed
///   file in that instant finds the path now names another file, or none, and tries again, so
///   two writers never both believe they hold the store.
/// - The lock is advisory: it binds brickyard's writers, not other programs.

#include <cstdint>
#include <optional>
#include <string>

namespace brickyard {

class StoreWriteLock {
 public:
  /// @brief Takes the lock without waiting. @throws Error(io) naming the store when another
  /// writer holds it (with that writer's pid), or when the lock file cannot be created.
  explicit StoreWriteLock(const std::string& dir);
  ~StoreWriteLock();
  StoreWriteLock(const StoreWriteLock&) = delete;
  StoreWriteLock& operator=(const StoreWriteLock&) = delete;

  const std::string& path() const { return lock_path_; }

 private:
  std::string lock_path_;
  int fd_ = -1;
};

/// @brief The store's directory, absolute, with symbolic links resolved (it need not exist).
std::string resolved_store_path(const std::string& dir);

/// @brief `.NAME.<suffix>` in the directory that holds the store NAME (resolved_store_path): the lock file
/// ("lock"), and the directories a rebuild uses beside the store.
std::string store_sibling(const std::string& dir, const std::string& suffix);

/// @brief The pid of the process that holds the store's write lock (0 when it holds it but has
/// not written its pid yet), or nullopt when nothing is writing the store. For messages only:
/// the answer may be stale by the time it is read.
std::optional<int64_t> store_writer_pid(const std::string& dir);

}  // namespace brickyard
