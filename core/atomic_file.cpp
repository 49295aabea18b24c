#include "core/atomic_file.h"

#include <cerrno>
#include <cstring>
#include <filesystem>

#include <fmt/format.h>

#include "core/error.h"

namespace brickyard {

namespace {
const char* non_regular_kind(const std::filesystem::file_status& st) {
  return std::filesystem::is_directory(st)          ? "a directory"
         : std::filesystem::is_character_file(st)   ? "a character device"
         : std::filesystem::is_block_file(st)       ? "a block device"
         : std::filesystem::is_fifo(st)             ? "a FIFO"
         : std::filesystem::is_socket(st)           ? "a socket"
                                                    : "not a regular file";
}
}  // namespace

void check_readable_file(const std::string& path) {
  std::error_code ec;
  const std::filesystem::file_status st = std::filesystem::status(path, ec);
  if (st.type() == std::filesystem::file_type::not_found)
    throw Error(Errc::io, "cannot open: No such file or directory").with_file(path);
  if (ec || std::filesystem::is_regular_file(st)) return;  // (permissions show when it is opened)
  throw Error(Errc::io, fmt::format("is {}, not a file: inputs are read from regular files", non_regular_kind(st)))
      .with_file(path);
}

void refuse_to_replace_non_regular(const std::string& path) {
  std::error_code ec;
  const std::filesystem::file_status st = std::filesystem::status(path, ec);
  if (ec || !std::filesystem::exists(st) || std::filesystem::is_regular_file(st)) return;  // absent, or a file
  const char* what = non_regular_kind(st);
  throw Error(Errc::io, fmt::format("exists and is {}: outputs replace only regular files; choose a file path", what))
      .with_file(path);
}

void check_writable(const std::string& path) {
  namespace fs = std::filesystem;
  refuse_to_replace_non_regular(path);
  const fs::path parent = fs::path(path).parent_path();
  const fs::path dir = parent.empty() ? fs::path(".") : parent;
  std::error_code ec;
  const fs::file_status st = fs::status(dir, ec);
  if (st.type() == fs::file_type::not_found)
    throw Error(Errc::not_found, fmt::format("its directory {} does not exist", dir.string())).with_file(path);
  if (!ec && !fs::is_directory(st))
    throw Error(Errc::io, fmt::format("{} is not a directory", dir.string())).with_file(path);
  // Other failures (permissions, /proc) show only when a file is created: create the writer's
  // own partial file, which it removes when it is never committed.
  AtomicFile probe(path);
}

AtomicFile::AtomicFile(std::string path) : path_(std::move(path)), partial_(path_ + ".partial") {
  refuse_to_replace_non_regular(path_);
  file_ = std::fopen(partial_.c_str(), "wb");
  if (!file_) throw Error(Errc::io, fmt::format("cannot create: {}", std::strerror(errno))).with_file(path_);
}

AtomicFile::~AtomicFile() {
  if (file_) {
    std::fclose(file_);
    std::remove(partial_.c_str());
  }
}

void AtomicFile::write(const void* data, size_t bytes) {
  if (bytes && std::fwrite(data, 1, bytes, file_) != bytes)
    throw Error(Errc::io, fmt::format("write failed: {}", std::strerror(errno))).with_file(path_);
}

void AtomicFile::commit() {
  const bool flushed = std::fflush(file_) == 0 && !std::ferror(file_);
  const int err = errno;
  std::fclose(file_);
  file_ = nullptr;
  if (!flushed) {
    std::remove(partial_.c_str());
    throw Error(Errc::io, fmt::format("write failed: {}", std::strerror(err))).with_file(path_);
  }
  std::error_code ec;
  std::filesystem::rename(partial_, path_, ec);
  if (ec) {
    std::remove(partial_.c_str());
    throw Error(Errc::io, fmt::format("cannot move into place: {}", ec.message())).with_file(path_);
  }
}

}  // namespace brickyard
