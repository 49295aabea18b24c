#pragma once
/// @file text_scanner.h
/// @brief Internal to the mesh readers (legacy VTK, gmsh, TetGen): a whole file in memory read
/// as whitespace-separated tokens, lines and big- or little-endian binary values, with errors
/// (Errc::format) that name the file and the line or byte offset. Not a public header.
///
/// Every count a file gives is checked against the bytes left (check_count) before anything is
/// reserved, so a lying header costs an error, never an allocation.

#include <algorithm>
#include <bit>
#include <cctype>
#include <charconv>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <limits>
#include <optional>
#include <string>
#include <string_view>
#include <type_traits>

#include <fmt/format.h>

#include "core/atomic_file.h"
#include "core/error.h"
#include "preprocess/mesh_data.h"

namespace brickyard::mesh_io {

/// @brief ASCII case-insensitive equality (file keywords: "POINTS", "points").
inline bool iequals(std::string_view a, std::string_view b) {
  return a.size() == b.size() && std::equal(a.begin(), a.end(), b.begin(), [](char x, char y) {
           return std::tolower(static_cast<unsigned char>(x)) == std::tolower(static_cast<unsigned char>(y));
         });
}

/// @brief A value of type T from the bytes at p, swapped when the file's order is not ours.
template <typename T>
T load_binary(const char* p, bool swap) {
  char b[sizeof(T)];
  std::memcpy(b, p, sizeof(T));
  if (swap) std::reverse(b, b + sizeof(T));
  T v;
  std::memcpy(&v, b, sizeof(T));
  return v;
}

inline constexpr bool host_is_big_endian() {
  return std::endian::native == std::endian::big;
}

/// @brief One file held whole; a cursor over it. Not thread-safe (one per reader call).
class Scanner {
 public:
  /// @brief Reads the whole file. hash_comments: '#' starts a comment to the end of the line
  /// (TetGen). @throws Error(io) when the file cannot be opened or read.
  explicit Scanner(const std::string& path, bool hash_comments = false) : path_(path), comments_(hash_comments) {
    check_readable_file(path);
    std::ifstream in(path, std::ios::binary);
    if (!in) throw Error(Errc::io, "cannot open the file").with_file(path);
    in.seekg(0, std::ios::end);
    const std::streamoff size = in.tellg();
    if (size < 0) throw Error(Errc::io, "cannot read the file").with_file(path);
    in.seekg(0, std::ios::beg);
    data_.resize(size_t(size));
    if (size > 0 && !in.read(data_.data(), size)) throw Error(Errc::io, "cannot read the file").with_file(path);
  }

  const std::string& path() const { return path_; }
  size_t pos() const { return pos_; }
  size_t remaining() const { return data_.size() - pos_; }

  /// @brief The 1-based line of the cursor (counted on demand, for messages).
  uint64_t line_number() const {
    return 1 + uint64_t(std::count(data_.begin(), data_.begin() + std::ptrdiff_t(pos_), '\n'));
  }

  /// @brief Error(format) "line N: MESSAGE" naming the file.
  [[noreturn]] void fail(const std::string& message) const {
    throw Error(Errc::format, fmt::format("line {}: {}", line_number(), message)).with_file(path_);
  }
  /// @brief Error(format) "byte B: MESSAGE", for binary data where lines mean nothing.
  [[noreturn]] void fail_binary(const std::string& message) const {
    throw Error(Errc::format, fmt::format("byte {}: {}", pos_, message)).with_file(path_);
  }

  /// @brief Skips whitespace (and comments); whether the file ends there.
  bool at_end() {
    skip_space();
    return pos_ >= data_.size();
  }

  /// @brief The next token; Error naming `what` when the file ends first.
  std::string_view token(std::string_view what) {
    skip_space();
    if (pos_ >= data_.size()) fail(fmt::format("the file ends where {} was expected", what));
    const size_t start = pos_;
    while (pos_ < data_.size() && !is_space(data_[pos_]) && !(comments_ && data_[pos_] == '#')) ++pos_;
    return std::string_view(data_).substr(start, pos_ - start);
  }

  /// @brief The next token without consuming it (nullopt at the end).
  std::optional<std::string_view> peek_token() {
    const size_t saved = pos_;
    if (at_end()) return std::nullopt;
    std::string_view t = token("a token");
    pos_ = saved;
    return t;
  }

  /// @brief Consumes the next token when it equals `keyword` (case-insensitive).
  bool accept(std::string_view keyword) {
    const size_t saved = pos_;
    if (at_end()) return false;
    if (iequals(token(keyword), keyword)) return true;
    pos_ = saved;
    return false;
  }

  /// @brief The rest of the current line (without its end of line); moves past it.
  std::string_view line() {
    const size_t start = pos_;
    while (pos_ < data_.size() && data_[pos_] != '\n') ++pos_;
    std::string_view l = std::string_view(data_).substr(start, pos_ - start);
    if (pos_ < data_.size()) ++pos_;
    if (!l.empty() && l.back() == '\r') l.remove_suffix(1);
    return l;
  }
  /// @brief Moves past the end of the current line (the start of binary data after a header line).
  void skip_line() { (void)line(); }

  /// @brief The next token as a number of type T (integer or floating point); Error naming
  /// `what` and the token when it is not one.
  template <typename T>
  T number(std::string_view what) {
    std::string_view t = token(what);
    T v{};
    if (!parse_number(t, v)) fail(fmt::format("'{}' is not {} ({})", t, kind_name<T>(), what));
    return v;
  }
  double real(std::string_view what) { return number<double>(what); }
  int64_t integer(std::string_view what) { return number<int64_t>(what); }

  /// @brief n raw bytes; Error naming `what` when fewer are left.
  const char* bytes(uint64_t n, std::string_view what) {
    if (n > remaining())
      fail_binary(fmt::format("the file ends inside {} ({} bytes needed, {} left)", what, n, remaining()));
    const char* p = data_.data() + pos_;
    pos_ += size_t(n);
    return p;
  }
  /// @brief One binary value of type T (swapped when `swap`).
  template <typename T>
  T binary(bool swap, std::string_view what) {
    return load_binary<T>(bytes(sizeof(T), what), swap);
  }

  /// @brief Error when `count` items of at least `min_bytes` each cannot fit in the rest of the
  /// file: call before reserving for a count a header gives.
  void check_count(uint64_t count, uint64_t min_bytes, std::string_view what) const {
    if (min_bytes == 0) min_bytes = 1;
    if (count > (remaining() + 1) / min_bytes)
      fail(fmt::format("{} says {} but only {} bytes are left in the file", what, count, remaining()));
  }

  /// @brief Moves to the first occurrence of `s` at or after the cursor (past it); false when absent.
  bool skip_past(std::string_view s) {
    const size_t at = data_.find(s, pos_);
    if (at == std::string::npos) return false;
    pos_ = at + s.size();
    return true;
  }

  /// @brief Whether the bytes at the cursor (after whitespace) start with `s`, case-insensitive.
  bool next_is(std::string_view s) {
    const size_t saved = pos_;
    skip_space();
    const bool yes = remaining() >= s.size() && iequals(std::string_view(data_).substr(pos_, s.size()), s);
    pos_ = saved;
    return yes;
  }

 private:
  static bool is_space(char c) { return c == ' ' || c == '\t' || c == '\n' || c == '\r' || c == '\f' || c == '\v'; }

  void skip_space() {
    while (pos_ < data_.size()) {
      const char c = data_[pos_];
      if (is_space(c)) {
        ++pos_;
      } else if (comments_ && c == '#') {
        while (pos_ < data_.size() && data_[pos_] != '\n') ++pos_;
      } else {
        break;
      }
    }
  }

  template <typename T>
  static bool parse_number(std::string_view t, T& v) {
    if (!t.empty() && t.front() == '+') t.remove_prefix(1);
    const auto [end, ec] = std::from_chars(t.data(), t.data() + t.size(), v);
    return !t.empty() && ec == std::errc() && end == t.data() + t.size();
  }

  template <typename T>
  static const char* kind_name() {
    return std::is_floating_point_v<T> ? "a number" : "an integer";
  }

  std::string path_;
  std::string data_;
  size_t pos_ = 0;
  bool comments_ = false;
};

}  // namespace brickyard::mesh_io
