#pragma once
/// @file build_state.h
/// @brief The bytes of a build checkpoint (StoreWriter::put_checkpoint): what a killed import
/// needs to resume where its last checkpoint was, brick for brick as if it had not stopped.
/// Plain little-endian fields in order; a reader past the end is a corrupt checkpoint.
///
/// A checkpoint opens with its identity (format version, the source's provenance and the build
/// parameters, as the manifest records them): a rerun resumes only the same import.

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <optional>
#include <span>
#include <string>
#include <type_traits>
#include <vector>

#include "core/error.h"

namespace brickyard {

/// 2: the series part (time steps done, their ranges, statistics and histograms) after the
/// identity. A checkpoint of another version is not resumed: the build starts over.
inline constexpr uint32_t kBuildStateVersion = 2;

class StateWriter {
 public:
  template <typename T>
  void put(const T& v) {
    static_assert(std::is_trivially_copyable_v<T>);
    put_bytes({reinterpret_cast<const std::byte*>(&v), sizeof(T)});
  }
  void put_bytes(std::span<const std::byte> b) { bytes_.insert(bytes_.end(), b.begin(), b.end()); }
  void put_string(const std::string& s) {
    put(uint64_t(s.size()));
    put_bytes({reinterpret_cast<const std::byte*>(s.data()), s.size()});
  }
  template <typename T>
  void put_vector(const std::vector<T>& v) {
    put(uint64_t(v.size()));
    put_bytes({reinterpret_cast<const std::byte*>(v.data()), v.size() * sizeof(T)});
  }
  std::vector<std::byte>& bytes() { return bytes_; }

 private:
  std::vector<std::byte> bytes_;
};

class StateReader {
 public:
  explicit StateReader(std::span<const std::byte> bytes) : bytes_(bytes) {}
  template <typename T>
  T get() {
    static_assert(std::is_trivially_copyable_v<T>);
    T v;
    std::memcpy(&v, take(sizeof(T)).data(), sizeof(T));
    return v;
  }
  std::span<const std::byte> take(size_t n) {
    if (n > bytes_.size() - at_) throw Error(Errc::corrupt, "the build checkpoint ends early");
    const auto s = bytes_.subspan(at_, n);
    at_ += n;
    return s;
  }
  std::string get_string() {
    const auto n = get<uint64_t>();
    const auto s = take(size_t(n));
    return {reinterpret_cast<const char*>(s.data()), s.size()};
  }
  template <typename T>
  std::vector<T> get_vector() {
    const auto n = get<uint64_t>();
    if (n > (bytes_.size() - at_) / sizeof(T)) throw Error(Errc::corrupt, "the build checkpoint ends early");
    std::vector<T> v(static_cast<size_t>(n));
    if (n == 0) return v;  // (memcpy from or to an empty vector's null data is undefined)
    std::memcpy(v.data(), take(size_t(n) * sizeof(T)).data(), size_t(n) * sizeof(T));
    return v;
  }
  bool done() const { return at_ == bytes_.size(); }

 private:
  std::span<const std::byte> bytes_;
  size_t at_ = 0;
};

/// @brief The identity a checkpoint opens with.
struct BuildIdentity {
  std::string source_json, build_json;
};
inline void put_identity(StateWriter& w, const BuildIdentity& id) {
  w.put(kBuildStateVersion);
  w.put_string(id.source_json);
  w.put_string(id.build_json);
}
/// @brief The identity, or nothing when the checkpoint is of another format version.
inline std::optional<BuildIdentity> get_identity(StateReader& r) {
  if (r.get<uint32_t>() != kBuildStateVersion) return std::nullopt;
  BuildIdentity id;
  id.source_json = r.get_string();
  id.build_json = r.get_string();
  return id;
}

}  // namespace brickyard
