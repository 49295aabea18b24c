#pragma once
/// @file fuzz_util.h
/// @brief What every fuzz target shares: the rule for what counts as a finding, temporary
/// files for readers that take a path, and splitting one input into several files.
///
/// A target feeds untrusted bytes to a real reader. brickyard::Error is the expected, clean
/// rejection and is swallowed, except Errc::internal (a broken invariant: a bug) which aborts.
/// Anything else escapes and crashes the process: an uncaught std::exception other than Error
/// (nlohmann's type_error, std::out_of_range from std::stoll, std::length_error) is what a user
/// would see as a bare message, and counts as a finding, as do ASan and UBSan reports.
///
/// Not thread-safe: one fuzzing process runs one input at a time.

#include <unistd.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <string_view>
#include <vector>

#include "core/error.h"

namespace brickyard::fuzz {

/// @brief Runs one input through `f`: Error is a clean rejection, Errc::internal a finding.
template <typename F>
int run_one(F&& f) {
  try {
    f();
  } catch (const Error& e) {
    // BRICKYARD_FUZZ_VERBOSE=1 prints every rejection (to check that seeds are accepted).
    static const bool verbose = std::getenv("BRICKYARD_FUZZ_VERBOSE") != nullptr;
    if (verbose) std::fprintf(stderr, "fuzz: rejected: %s\n", e.what());
    if (e.code() == Errc::internal) {
      std::fprintf(stderr, "fuzz: brickyard::Error(internal) on untrusted input: %s\n", e.what());
      std::abort();
    }
    if (std::string_view(e.what()).empty()) {
      std::fprintf(stderr, "fuzz: brickyard::Error without a message\n");
      std::abort();
    }
  }
  return 0;
}

/// @brief A directory of this process's own (removed at exit): TMPDIR/brickyard-fuzz-PID.
inline const std::filesystem::path& temp_dir() {
  static const std::filesystem::path dir = [] {
    const char* base = std::getenv("TMPDIR");
    std::filesystem::path d = std::filesystem::path(base && *base ? base : "/tmp") /
                              ("brickyard-fuzz-" + std::to_string(::getpid()));
    std::filesystem::create_directories(d);
    static struct Remover {
      std::filesystem::path p;
      ~Remover() {
        std::error_code ec;
        std::filesystem::remove_all(p, ec);
      }
    } remover{d};
    return d;
  }();
  return dir;
}

/// @brief Writes bytes to temp_dir()/name (replacing it) and returns its path.
inline std::string write_temp(const std::string& name, const void* data, size_t size) {
  const std::filesystem::path p = temp_dir() / name;
  std::ofstream out(p, std::ios::binary | std::ios::trunc);
  out.write(static_cast<const char*>(data), std::streamsize(size));
  out.close();
  if (!out) {
    std::fprintf(stderr, "fuzz: cannot write %s\n", p.c_str());
    std::abort();
  }
  return p.string();
}
inline std::string write_temp(const std::string& name, std::string_view bytes) {
  return write_temp(name, bytes.data(), bytes.size());
}

/// @brief Splits an input into at most `parts` pieces at each occurrence of `separator` (the
/// last piece keeps any further separators); missing pieces are empty. Seeds of multi-file
/// formats (TetGen's .node and .ele, a .pvd and its .vtu files) are the files joined by it.
inline std::vector<std::string_view> split(std::string_view input, std::string_view separator, size_t parts) {
  std::vector<std::string_view> out;
  while (out.size() + 1 < parts) {
    const size_t at = input.find(separator);
    if (at == std::string_view::npos) break;
    out.push_back(input.substr(0, at));
    input.remove_prefix(at + separator.size());
  }
  out.push_back(input);
  out.resize(parts);
  return out;
}

/// @brief The separator of multi-file seeds: a line of its own.
inline constexpr std::string_view kFileSeparator = "\n--8<-- next file --8<--\n";

/// @brief Reads bytes off the front of an input (for targets that take a few parameters
/// before the payload); past the end it returns zeros.
class Prefix {
 public:
  Prefix(const uint8_t* data, size_t size) : data_(data), size_(size) {}
  uint8_t u8() { return pos_ < size_ ? data_[pos_++] : 0; }
  uint32_t u32() {
    uint32_t v = 0;
    for (int i = 0; i < 4; ++i) v |= uint32_t(u8()) << (8 * i);
    return v;
  }
  const uint8_t* rest() const { return data_ + std::min(pos_, size_); }
  size_t rest_size() const { return size_ - std::min(pos_, size_); }

 private:
  const uint8_t* data_;
  size_t size_;
  size_t pos_ = 0;
};

}  // namespace brickyard::fuzz

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size);
