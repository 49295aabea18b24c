#pragma once
/// @file atomic_file.h
/// @brief Writing a file so that readers never see half of it: the bytes go to PATH.partial,
/// which commit() flushes and renames over PATH; if commit() is never reached (an error, an
/// exception), the partial file is removed.

#include <cstddef>
#include <cstdio>
#include <string>

namespace brickyard {

/// @brief Refuses an input path that is missing, or is a directory, a FIFO (whose open would
/// wait for a writer forever), a device or a socket. @throws Error(io) naming the path.
void check_readable_file(const std::string& path);

/// @brief Refuses an output path that exists and is not a regular file (a directory, a device
/// such as /dev/null, a FIFO, a socket, or a link to one): every writer puts its bytes in a
/// temporary file renamed over the path, which would replace such a thing with a regular file
/// (run as root, `-o /dev/null` replaced the device). @throws Error(io) naming the path.
void refuse_to_replace_non_regular(const std::string& path);

/// @brief Fails now where an AtomicFile for `path` would fail later: the path is not a regular
/// file, its directory is missing or is not a directory, or nothing can be created there
/// (permissions, a read-only or pseudo file system such as /proc). For outputs written only
/// after long work (a flight's trace, a replay's CSV), so that the work is not done for
/// nothing. Leaves nothing behind. @throws Error(not_found) or Error(io) naming the path.
void check_writable(const std::string& path);

class AtomicFile {
 public:
  /// @throws Error(io) naming `path` when PATH.partial cannot be created, or when `path` is
  /// not a regular file (refuse_to_replace_non_regular).
  explicit AtomicFile(std::string path);
  ~AtomicFile();
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;

  /// @brief The open stream, for libraries that write through a FILE* (libpng).
  std::FILE* stream() { return file_; }
  /// @throws Error(io) naming the path, with the system's reason.
  void write(const void* data, size_t bytes);
  /// @brief Flushes, closes and renames into place. @throws Error(io).
  void commit();
  const std::string& path() const { return path_; }

 private:
  std::string path_, partial_;
  std::FILE* file_ = nullptr;
};

}  // namespace brickyard
