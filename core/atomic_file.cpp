#include "core/atomic_file.h"

#include <cerrno>
#include <cstring>
#include <filesystem>

#include <fmt/format.h>

#include "core/error.h"

namespace brickyard {

AtomicFile::AtomicFile(std::string path) : path_(std::move(path)), partial_(path_ + ".partial") {
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
