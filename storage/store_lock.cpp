#include "storage/store_lock.h"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <thread>

#include <fmt/format.h>

#include "core/error.h"

namespace brickyard {
namespace {

namespace fs = std::filesystem;

std::string read_pid(int fd) {
  char text[32] = {};
  const ssize_t n = ::pread(fd, text, sizeof(text) - 1, 0);
  std::string pid;
  for (ssize_t i = 0; i < n && text[i] >= '0' && text[i] <= '9'; ++i) pid += text[i];
  return pid;
}

bool same_file(int fd, const std::string& path) {
  struct stat held {}, named {};
  return ::fstat(fd, &held) == 0 && ::stat(path.c_str(), &named) == 0 && held.st_dev == named.st_dev &&
         held.st_ino == named.st_ino;
}

}  // namespace

std::string resolved_store_path(const std::string& dir) {
  std::error_code ec;
  // Symbolic links resolved: a store named through two paths has one lock, and a rebuild swaps
  // the real directory, not a link to it.
  fs::path p = fs::weakly_canonical(fs::path(dir), ec);
  if (ec) p = fs::absolute(fs::path(dir), ec).lexically_normal();
  if (!p.has_filename()) p = p.parent_path();
  return p.string();
}

std::string store_sibling(const std::string& dir, const std::string& suffix) {
  const fs::path p = resolved_store_path(dir);
  return (p.parent_path() / ("." + p.filename().string() + "." + suffix)).string();
}

StoreWriteLock::StoreWriteLock(const std::string& dir) : lock_path_(store_sibling(dir, "lock")) {
  // A reader asking who writes the store (store_writer_pid) holds a shared lock for an instant:
  // a writer that meets it tries again rather than report a writer that is not there.
  constexpr int kBusyTries = 5;
  int busy = 0, replaced = 0;
  std::error_code ec;
  fs::create_directories(fs::path(lock_path_).parent_path(), ec);  // as a store's own directory would be
  while (true) {
    const int fd = ::open(lock_path_.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
    if (fd < 0)
      throw Error(Errc::io, fmt::format("cannot create the store's lock file {}: {}", lock_path_, std::strerror(errno)))
          .with_file(dir);
    if (::flock(fd, LOCK_EX | LOCK_NB) != 0) {
      const int err = errno;
      const std::string pid = read_pid(fd);
      ::close(fd);
      if (err == EWOULDBLOCK && ++busy < kBusyTries) {
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
        continue;
      }
      if (err == EWOULDBLOCK)
        throw Error(Errc::io, fmt::format("another writer{} holds this store; wait for it to finish (its lock: {})",
                                          pid.empty() ? "" : " (pid " + pid + ")", lock_path_))
            .with_file(dir);
      throw Error(Errc::io, fmt::format("cannot lock {}: {}", lock_path_, std::strerror(err))).with_file(dir);
    }
    if (same_file(fd, lock_path_)) {
      fd_ = fd;
      break;
    }
    ::close(fd);  // its holder removed the file as we locked it: the lock is the path's new file
    if (++replaced > 100) throw Error(Errc::io, fmt::format("the lock file {} keeps being replaced", lock_path_)).with_file(dir);
  }
  // Only a refused writer's message reads the pid: the lock is held whether or not it is written.
  const std::string pid = fmt::format("{}\n", ::getpid());
  if (::ftruncate(fd_, 0) == 0) (void)!::pwrite(fd_, pid.data(), pid.size(), 0);
}

StoreWriteLock::~StoreWriteLock() {
  if (fd_ < 0) return;
  // Removed while still held, so that whoever locks the old file next sees it is gone.
  ::unlink(lock_path_.c_str());
  ::close(fd_);
}

std::optional<int64_t> store_writer_pid(const std::string& dir) {
  const std::string path = store_sibling(dir, "lock");
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return std::nullopt;
  std::optional<int64_t> pid;
  if (::flock(fd, LOCK_SH | LOCK_NB) == 0) {
    ::flock(fd, LOCK_UN);
  } else if (errno == EWOULDBLOCK) {
    const std::string text = read_pid(fd);
    pid = text.empty() || text.size() > 18 ? 0 : std::stoll(text);
  }
  ::close(fd);
  return pid;
}

}  // namespace brickyard
