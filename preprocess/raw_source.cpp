// Raw volumes (memory-mapped) and procedural fields as builder sources.

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <vector>

#include <fmt/format.h>
#include <xxhash.h>
#include <nlohmann/json.hpp>

#include "core/atomic_file.h"
#include "core/error.h"
#include "core/raw_volume.h"
#include "fields/grid.h"
#include "preprocess/volume_source.h"

namespace brickyard {
namespace {

class RawSource final : public VolumeSource {
 public:
  RawSource(const std::string& path, const RawFileSpec& spec) : path_(path), spec_(spec) {
    auto needed = checked_grid_bytes(spec.dims, ValueType::u8);  // the voxel count, then bytes
    if (needed && __builtin_mul_overflow(*needed, uint64_t(size_of(spec.type)), &*needed)) needed.reset();
    if (!needed)
      throw Error(Errc::invalid_argument, fmt::format("dims {}x{}x{} are empty or overflow a 64-bit byte count",
                                                      spec.dims.x, spec.dims.y, spec.dims.z))
          .with_file(path)
          .with_field("dims");
    check_readable_file(path);
    fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd_ < 0) throw Error(Errc::io, fmt::format("cannot open: {}", std::strerror(errno))).with_file(path);
    struct stat st {};
    if (::fstat(fd_, &st) != 0) {
      const int err = errno;
      ::close(fd_);
      throw Error(Errc::io, fmt::format("cannot stat: {}", std::strerror(err))).with_file(path);
    }
    size_ = uint64_t(st.st_size);
    mtime_ns_ = int64_t(st.st_mtim.tv_sec) * 1000000000 + st.st_mtim.tv_nsec;
    uint64_t expected = 0;
    if (__builtin_add_overflow(spec.header_bytes, *needed, &expected)) {
      ::close(fd_);
      throw Error(Errc::invalid_argument, fmt::format("a {}-byte header and {} bytes of voxels overflow a 64-bit size",
                                                      spec.header_bytes, *needed))
          .with_file(path)
          .with_field("--header-bytes");
    }
    if (size_ != expected) {
      ::close(fd_);
      const std::string what = size_ < expected ? "truncated" : "larger than its dims say";
      throw Error(Errc::format, fmt::format("file is {}: {} bytes, but {}x{}x{} {}{} needs {}", what, size_,
                                            spec.dims.x, spec.dims.y, spec.dims.z, to_string(spec.type),
                                            spec.header_bytes ? fmt::format(" after a {}-byte header", spec.header_bytes) : "",
                                            expected))
          .with_file(path)
          .with_field("dims");
    }
    void* map = ::mmap(nullptr, size_, PROT_READ, MAP_PRIVATE, fd_, 0);
    if (map == MAP_FAILED) {
      const int err = errno;
      ::close(fd_);
      throw Error(Errc::io, fmt::format("cannot map: {}", std::strerror(err))).with_file(path);
    }
    ::madvise(map, size_, MADV_SEQUENTIAL);
    map_ = static_cast<const std::byte*>(map);
    if (!is_native(spec.type)) measure_conversion();
  }
  ~RawSource() override {
    ::munmap(const_cast<std::byte*>(map_), size_);
    ::close(fd_);
  }

  std::string name() const override { return path_; }
  Vec3s dims() const override { return spec_.dims; }
  ValueType type() const override { return stored_type(spec_.type); }
  Vec3d spacing() const override { return spec_.spacing; }
  Vec3d origin() const override { return spec_.origin; }
  std::optional<ValueRange> value_range_hint() const override {
    if (conversion_ && conversion_->min <= conversion_->max) return ValueRange{conversion_->min, conversion_->max};
    return spec_.range;
  }
  bool may_contain_nonfinite() const override {
    return conversion_ ? conversion_->nonfinite > 0 : spec_.type == ElementType::f32;
  }
  std::optional<ConversionReport> conversion() const override { return conversion_; }
  uint64_t input_bytes() const override { return size_; }

  void read_slab(int64_t z0, int64_t z1, std::span<std::byte> out) override {
    const size_t es = size_of(spec_.type);
    const size_t voxels = size_t(z1 - z0) * size_t(spec_.dims.x * spec_.dims.y);
    const std::byte* src = map_ + spec_.header_bytes + size_t(z0) * size_t(spec_.dims.x * spec_.dims.y) * es;
    BY_CHECK_EQ(out.size(), voxels * size_of(type()));
    if (is_native(spec_.type)) {
      std::memcpy(out.data(), src, out.size());
      if (!spec_.little_endian) swap_element_bytes(out, es);
    } else {
      converting_.resize(voxels * es);
      std::memcpy(converting_.data(), src, converting_.size());
      if (!spec_.little_endian) swap_element_bytes(converting_, es);
      convert_elements(converting_.data(), spec_.type, voxels, out.data());
    }
    const size_t read_bytes = voxels * es;
    // Pages already copied will not be read again: let the kernel drop them, so importing a
    // file larger than memory does not evict everything else.
    const uintptr_t page = uintptr_t(::sysconf(_SC_PAGESIZE));
    const uintptr_t start = uintptr_t(src) & ~(page - 1);
    ::madvise(reinterpret_cast<void*>(start), uintptr_t(src + read_bytes) - start, MADV_DONTNEED);
  }

  std::string describe_json() const override {
    nlohmann::json j = {{"kind", "raw"},
                        {"path", path_},
                        {"bytes", size_},
                        {"header_bytes", spec_.header_bytes},
                        {"endianness", spec_.little_endian ? "little" : "big"}};
    if (!is_native(spec_.type)) j["element_type"] = std::string(to_string(spec_.type));
    if (conversion_) j["conversion"] = nlohmann::json::parse(conversion_->to_json());
    if (spec_.xxh3_64) {
      j["xxh3_64"] = fmt::format("{:016x}", *spec_.xxh3_64);
      // Which file the checksum was checked on: a rerun of an import finds it in the store or
      // checkpoint in place and need not hash the file again (verify_content()).
      j["checked_mtime_ns"] = mtime_ns_;
    } else {
      j["mtime_ns"] = mtime_ns_;
    }
    if (!spec_.generator_json.empty()) j["generator"] = nlohmann::json::parse(spec_.generator_json);
    return j.dump();
  }

  /// The sidecar's checksum against the file, before anything is built from it: a file
  /// rewritten or damaged since its sidecar would otherwise import as if it were the original.
  void verify_content() override {
    if (!spec_.xxh3_64) return;
    const uint64_t expected = *spec_.xxh3_64;
    const uint64_t actual = XXH3_64bits(map_, size_);
    if (actual == expected) return;
    throw Error(Errc::format, fmt::format("the file's XXH3-64 is {:016x}, its sidecar {}.json says {:016x}: the file "
                                          "changed since the sidecar was written (describe it with --dims and "
                                          "--type to import it as it is now)",
                                          actual, path_, expected))
        .with_file(path_)
        .with_field("xxh3_64");
  }

 private:

  /// One pass over the file before anything is built: a conversion that would change values
  /// is refused (check_conversion) before the store is touched.
  void measure_conversion() {
    const size_t es = size_of(spec_.type), slice = size_t(spec_.dims.x * spec_.dims.y) * es;
    try {
      conversion_ = scan_conversion(spec_.dims, spec_.type, [&](int64_t z0, int64_t, std::span<std::byte> out) {
        std::memcpy(out.data(), map_ + spec_.header_bytes + size_t(z0) * slice, out.size());
        if (!spec_.little_endian) swap_element_bytes(out, es);
      });
      check_conversion(*conversion_, spec_.convert, path_);
    } catch (...) {
      ::munmap(const_cast<std::byte*>(map_), size_);
      ::close(fd_);
      throw;
    }
  }

  std::string path_;
  RawFileSpec spec_;
  int fd_ = -1;
  uint64_t size_ = 0;
  int64_t mtime_ns_ = 0;
  const std::byte* map_ = nullptr;
  std::optional<ConversionReport> conversion_;
  std::vector<std::byte> converting_;  ///< a slab of file elements on their way to f32
};

class FieldSource final : public VolumeSource {
 public:
  FieldSource(std::unique_ptr<Field> field, const Vec3s& dims, ValueType type)
      : field_(std::move(field)), sampler_(*field_, dims, type) {}

  std::string name() const override { return fmt::format("field {}", field_->name()); }
  Vec3s dims() const override { return sampler_.dims(); }
  ValueType type() const override { return sampler_.type(); }
  Vec3d spacing() const override { return sampler_.spacing(); }
  Vec3d origin() const override { return sampler_.origin(); }
  bool may_contain_nonfinite() const override { return false; }
  std::optional<ValueRange> value_range_hint() const override {
    if (is_integer(type())) return ValueRange{integer_min(type()), integer_max(type())};
    return field_->range();
  }
  void read_slab(int64_t z0, int64_t z1, std::span<std::byte> out) override { sampler_.sample_slab(z0, z1, out); }
  std::string describe_json() const override {
    nlohmann::json params = nlohmann::json::object();
    for (const auto& p : field_->params()) params[p.name] = p.value;
    nlohmann::json j = {{"kind", "field"}, {"field", std::string(field_->name())}, {"params", params}};
    if (is_integer(type())) j["quantization"] = {sampler_.quantization().lo, sampler_.quantization().hi};
    return j.dump();
  }

 private:
  std::unique_ptr<Field> field_;
  GridSampler sampler_;
};

}  // namespace

std::unique_ptr<VolumeSource> open_raw_source(const std::string& path, const RawFileSpec& spec) {
  return std::make_unique<RawSource>(path, spec);
}

std::unique_ptr<VolumeSource> make_field_source(std::unique_ptr<Field> field, const Vec3s& dims, ValueType type) {
  return std::make_unique<FieldSource>(std::move(field), dims, type);
}

}  // namespace brickyard
