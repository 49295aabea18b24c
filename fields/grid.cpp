#include "fields/grid.h"

#include <xxhash.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <cmath>
#include <filesystem>
#include <future>
#include <limits>
#include <memory>
#include <vector>

#include <fmt/format.h>

#include "core/atomic_file.h"
#include "core/error.h"
#include "core/parallel.h"
#include "core/progress.h"

namespace brickyard {

double dequantize(double stored, ValueType type, const ValueRange& r) {
  if (!is_integer(type)) return stored;
  return r.lo + (stored - integer_min(type)) / (integer_max(type) - integer_min(type)) * (r.hi - r.lo);
}

GridSampler::GridSampler(const Field& field, const Vec3s& dims, ValueType type)
    : field_(field), dims_(dims), type_(type) {
  if (!checked_grid_bytes(dims, type))
    throw Error(Errc::invalid_argument,
                fmt::format("grid {}x{}x{} {} is empty or its byte size overflows 64 bits", dims.x, dims.y, dims.z,
                            to_string(type)))
        .with_field("size");
  const Box3d d = field.domain();
  for (int a = 0; a < 3; ++a) {
    const double extent = d.hi[a] - d.lo[a];
    if (dims[a] > 1) {
      spacing_[a] = extent / double(dims[a] - 1);
      offset_[a] = 0.0;
    } else {
      spacing_[a] = extent;
      offset_[a] = extent / 2.0;
    }
  }
}

bool GridSampler::stores_values_as_is() const {
  if (!is_integer(type_) || !field_.integer_valued()) return false;
  const ValueRange r = field_.range();
  return r.lo >= integer_min(type_) && r.hi <= integer_max(type_);
}

ValueRange GridSampler::quantization() const {
  if (stores_values_as_is()) return {integer_min(type_), integer_max(type_)};
  return field_.range();
}

namespace {
template <typename T>
void sample_rows(const GridSampler& s, int64_t z0, int64_t z1, T* out) {
  const Vec3s dims = s.dims();
  const ValueRange q = s.quantization();
  const bool as_is = s.stores_values_as_is();
  const int64_t rows = (z1 - z0) * dims.y;
  parallel_for<int64_t>(0, rows, 4, [&](int64_t row_begin, int64_t row_end) {
    std::vector<double> row(size_t(dims.x));
    for (int64_t i = row_begin; i < row_end; ++i) {
      const int64_t z = z0 + i / dims.y, y = i % dims.y;
      s.field().sample_row(s.position(0, y, z), s.spacing().x, dims.x, row.data());
      T* dst = out + i * dims.x;
      if (as_is) {
        // The field's integers themselves; (x - lo) / (hi - lo) * (hi - lo) would round some.
        for (int64_t x = 0; x < dims.x; ++x)
          dst[x] = static_cast<T>(std::clamp(std::nearbyint(row[size_t(x)]), q.lo, q.hi));
      } else {
        for (int64_t x = 0; x < dims.x; ++x) dst[x] = quantize<T>(row[size_t(x)], q);
      }
    }
  });
}
}  // namespace

void GridSampler::sample_slab(int64_t z0, int64_t z1, std::span<std::byte> out) const {
  BY_CHECK(z0 >= 0 && z0 <= z1 && z1 <= dims_.z);
  BY_CHECK_EQ(out.size(), size_t(z1 - z0) * slice_bytes());
  dispatch_value_type(type_, [&](auto tag) {
    using T = decltype(tag);
    sample_rows<T>(*this, z0, z1, reinterpret_cast<T*>(out.data()));
  });
}

void stream_grid(const GridSampler& sampler, int64_t slab_slices,
                 const std::function<void(int64_t, int64_t, std::span<const std::byte>)>& sink, Progress* progress) {
  const size_t slice = sampler.slice_bytes();
  // At most 8 MiB and at least 32 slabs per grid: enough rows for every core, bounded memory,
  // and progress that moves.
  if (slab_slices <= 0)
    slab_slices = std::max<int64_t>(1, std::min(int64_t((8u << 20) / slice), sampler.dims().z / 32));
  slab_slices = std::min(slab_slices, sampler.dims().z);
  const int64_t voxels_per_slice = sampler.dims().x * sampler.dims().y;
  // Double buffering: the sink consumes one slab (writing, hashing) on its own thread while
  // the next slab is sampled.
  std::vector<std::byte> buffers[2];
  for (auto& b : buffers) b.resize(size_t(slab_slices) * slice);
  std::future<void> pending;
  int current = 0;
  for (int64_t z0 = 0; z0 < sampler.dims().z; z0 += slab_slices, current ^= 1) {
    const int64_t z1 = std::min(z0 + slab_slices, sampler.dims().z);
    std::span<std::byte> bytes(buffers[current].data(), size_t(z1 - z0) * slice);
    sampler.sample_slab(z0, z1, bytes);
    if (pending.valid()) pending.get();  // rethrows the sink's error, if any
    pending = std::async(std::launch::async, [&sink, &progress, z0, z1, bytes, voxels_per_slice] {
      sink(z0, z1, bytes);
      if (progress) progress->advance(uint64_t((z1 - z0) * voxels_per_slice));
    });
  }
  if (pending.valid()) pending.get();
}


RawVolumeInfo write_raw_grid(const GridSampler& sampler, const std::string& path, Progress* progress) {
  AtomicFile file(path);
  std::unique_ptr<XXH3_state_t, decltype(&XXH3_freeState)> hash(XXH3_createState(), XXH3_freeState);
  XXH3_64bits_reset(hash.get());
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  uint64_t written = 0;
  stream_grid(
      sampler, 0,
      [&](int64_t, int64_t, std::span<const std::byte> bytes) {
        file.write(bytes.data(), bytes.size());
        written += bytes.size();
        XXH3_64bits_update(hash.get(), bytes.data(), bytes.size());
        extend_range(bytes, sampler.type(), lo, hi);
      },
      progress);
  file.commit();

  RawVolumeInfo info;
  info.dims = sampler.dims();
  info.type = sampler.type();
  info.little_endian = true;
  info.spacing = sampler.spacing();
  info.origin = sampler.origin();
  info.min_value = lo;
  info.max_value = hi;
  if (is_integer(sampler.type())) info.quantization = {{sampler.quantization().lo, sampler.quantization().hi}};
  info.source = fmt::format("field {}", sampler.field().name());
  for (const auto& p : sampler.field().params()) info.source_params.emplace_back(p.name, p.value);
  info.bytes = written;
  info.xxh3_64 = XXH3_64bits_digest(hash.get());
  write_raw_sidecar(raw_sidecar_path(path), info);
  return info;
}

}  // namespace brickyard
