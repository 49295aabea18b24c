// Where a build writes, and how what it wrote takes the store's place (StoreBuildTarget,
// declared in builder.h): the write lock, reclaiming what a killed rebuild left, rebuilding
// beside a complete store and swapping it in.

#include <fcntl.h>  // AT_FDCWD, for renameat2
#include <sys/stat.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "preprocess/build_state.h"
#include "preprocess/builder.h"
#include "storage/store.h"

namespace brickyard {
namespace {

namespace fs = std::filesystem;

// The generator (what made a raw file, from its sidecar) describes the data but is not its
// identity: stores built before it was recorded stay up to date.
std::string source_identity(const std::string& json) {
  nlohmann::json j = nlohmann::json::parse(json);
  const auto strip = [](nlohmann::json& o) {
    if (o.is_object()) o.erase("generator"), o.erase("checked_mtime_ns");
  };
  strip(j);
  if (j.is_object() && j.contains("steps") && j["steps"].is_array())  // a time series: each step's own
    for (auto& step : j["steps"]) strip(step);
  return j.dump();
}

/// Whether `before` describes the same file as `now`, checked then and unchanged since.
bool same_checked_file(const nlohmann::json& before, const nlohmann::json& now) {
  if (!before.is_object() || !now.is_object() || !now.contains("checked_mtime_ns")) return false;
  for (const char* key : {"kind", "path", "bytes", "xxh3_64", "checked_mtime_ns"})
    if (before.value(key, nlohmann::json()) != now.value(key, nlohmann::json())) return false;
  return true;
}

/// The checkpoint an interrupted build of this same import left (same source, same parameters,
/// same checkpoint format), to resume from; anything else is started over.
std::optional<std::vector<std::byte>> resumable_state(const std::string& dir, const std::string& source_json,
                                                      const std::string& build_json, std::string& checkpoint_source) {
  try {
    auto state = read_build_checkpoint(dir);
    if (!state) return std::nullopt;
    StateReader r(*state);
    const auto id = get_identity(r);
    if (!id || source_identity(id->source_json) != source_identity(source_json) || id->build_json != build_json)
      return std::nullopt;
    checkpoint_source = id->source_json;
    return state;
  } catch (const Error&) {
    return std::nullopt;  // unreadable: the build starts over, as before checkpoints
  }
}

[[noreturn]] void fail_io(const std::string& what, const std::error_code& ec, const std::string& dir) {
  throw Error(Errc::io, fmt::format("{}: {}", what, ec.message())).with_file(dir);
}

// A sibling a rebuild left behind is removed only when it holds a store (or nothing): a user's
// directory of that name is not ours to delete.
void remove_leftover(const std::string& path, const std::string& dir) {
  std::error_code ec;
  if (!fs::exists(fs::symlink_status(path, ec))) return;
  if (probe_store(path) == StoreState::not_a_store)
    throw Error(Errc::invalid_argument,
                fmt::format("{} is in the way of rebuilding this store and is not a brickyard store; move it away", path))
        .with_file(dir);
  fs::remove_all(path, ec);
  if (ec) fail_io(fmt::format("cannot remove {}", path), ec, dir);
}

bool same_file_system(const std::string& a, const std::string& b) {
  struct stat sa {}, sb {};
  return ::stat(a.c_str(), &sa) == 0 && ::stat(b.c_str(), &sb) == 0 && sa.st_dev == sb.st_dev;
}

/// Swaps two directories in one step; false where the file system cannot (the caller renames twice).
bool exchange_directories(const std::string& a, const std::string& b, const std::string& dir) {
#ifdef RENAME_EXCHANGE
  if (::renameat2(AT_FDCWD, a.c_str(), AT_FDCWD, b.c_str(), RENAME_EXCHANGE) == 0) return true;
  if (errno != EINVAL && errno != ENOSYS && errno != ENOTSUP)
    throw Error(Errc::io, fmt::format("cannot swap {} into place: {}", a, std::strerror(errno))).with_file(dir);
#endif
  (void)a, (void)b, (void)dir;
  return false;
}

}  // namespace

StoreBuildTarget::StoreBuildTarget(const std::string& dir, const std::string& source_json, const std::string& build_json,
                                   bool force, BuildResult& result, bool publish_whole)
    : lock_(dir), dir_(dir), real_(resolved_store_path(dir)), path_(dir), rebuilding_(store_sibling(dir, "rebuilding")),
      replaced_(store_sibling(dir, "replaced")) {
  reclaim();
  switch (probe_store(dir)) {
    case StoreState::absent: break;
    case StoreState::not_a_store:
      throw Error(Errc::invalid_argument, "exists and is not a brickyard store; refusing to overwrite it").with_file(dir);
    case StoreState::incomplete:
      if (!publish_whole && (resume_state_ = resumable_state(dir, source_json, build_json, previous_source_))) break;
      result.rebuilt_incomplete = true;
      remove_store_files(dir);
      break;
    case StoreState::complete: {
      const Manifest old = read_manifest(dir);
      previous_source_ = old.source;
      if (source_identity(old.source) == source_identity(source_json) && old.build == build_json && !force) {
        result.manifest = old;
        up_to_date_ = true;
        return;
      }
      if (!force)
        throw Error(Errc::invalid_argument,
                    "a complete store from a different source or with different parameters is there; "
                    "pass --force to rebuild it")
            .with_file(dir);
      if (!same_file_system(real_, fs::path(real_).parent_path().string())) {
        remove_store_files(dir);  // a store that is a mount point of its own: no rename can cross
        break;
      }
      beside_ = true;
      path_ = rebuilding_;
      break;
    }
  }
  if (publish_whole && !beside_) {
    std::error_code ec;
    const fs::path parent = fs::path(real_).has_parent_path() ? fs::path(real_).parent_path() : fs::path(".");
    fs::create_directories(parent, ec);
    if (ec) fail_io("cannot create the store's directory", ec, dir_);
    // Nothing there, or an incomplete store's directory that is not a mount point of its own.
    if (!fs::exists(fs::symlink_status(real_, ec)) || same_file_system(real_, parent.string())) {
      beside_ = true;
      path_ = rebuilding_;
    }
  }
}

bool StoreBuildTarget::source_checked_before(const std::string& source_json) const {
  if (previous_source_.empty()) return false;
  try {
    const nlohmann::json before = nlohmann::json::parse(previous_source_), now = nlohmann::json::parse(source_json);
    if (now.is_object() && now.value("kind", "") == "time_series") {  // every step's file
      if (!before.is_object() || before.value("kind", "") != "time_series") return false;
      const nlohmann::json &b = before.value("steps", nlohmann::json()), &n = now.value("steps", nlohmann::json());
      if (!b.is_array() || !n.is_array() || b.size() != n.size()) return false;
      for (size_t i = 0; i < n.size(); ++i)
        if (!same_checked_file(b[i], n[i])) return false;
      return true;
    }
    return same_checked_file(before, now);
  } catch (const nlohmann::json::exception&) {
    return false;
  }
}

StoreBuildTarget::~StoreBuildTarget() {
  if (!beside_ || committed_) return;
  std::error_code ec;
  fs::remove_all(rebuilding_, ec);  // else the next writer reclaims it
}

void StoreBuildTarget::reclaim() {
  std::error_code ec;
  if (fs::exists(fs::symlink_status(replaced_, ec))) {
    if (fs::exists(fs::symlink_status(real_, ec))) {
      remove_leftover(replaced_, dir_);
    } else {
      const bool rebuilt = probe_store(rebuilding_) == StoreState::complete;
      fs::rename(rebuilt ? rebuilding_ : replaced_, real_, ec);
      if (ec) fail_io(fmt::format("cannot put {} back in place", rebuilt ? rebuilding_ : replaced_), ec, dir_);
      if (rebuilt) remove_leftover(replaced_, dir_);
    }
  }
  remove_leftover(rebuilding_, dir_);
}

void StoreBuildTarget::commit() {
  if (!beside_ || committed_) return;
  std::error_code ec;
  if (!fs::exists(fs::symlink_status(real_, ec))) {  // nothing there (publish_whole): it appears whole
    fs::rename(rebuilding_, real_, ec);
    if (ec) fail_io(fmt::format("cannot move {} into place", rebuilding_), ec, dir_);
    committed_ = true;
    return;
  }
  std::string old = rebuilding_;  // where the old store is once the new one is in place
  if (!exchange_directories(rebuilding_, real_, dir_)) {
    fs::rename(real_, replaced_, ec);
    if (ec) fail_io(fmt::format("cannot move the old store aside to {}", replaced_), ec, dir_);
    fs::rename(rebuilding_, real_, ec);
    if (ec) {
      std::error_code back;
      fs::rename(replaced_, real_, back);
      fail_io(fmt::format("cannot move {} into place", rebuilding_), ec, dir_);
    }
    old = replaced_;
  }
  committed_ = true;
  fs::remove_all(old, ec);  // the new store is in place; a failure here is reclaimed next time
}


}  // namespace brickyard
