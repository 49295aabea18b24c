#pragma once
// Reference implementations for the builder tests: dense grids and a plain 2x pyramid.

#include <cmath>
#include <cstring>
#include <vector>

#include "fields/field.h"
#include "fields/grid.h"
#include "preprocess/export.h"
#include "storage/store.h"

namespace brickyard::testing {

template <typename T>
struct Grid {
  Vec3s dims;
  std::vector<T> v;
  const T& at(int64_t x, int64_t y, int64_t z) const {
    x = std::clamp<int64_t>(x, 0, dims.x - 1);
    y = std::clamp<int64_t>(y, 0, dims.y - 1);
    z = std::clamp<int64_t>(z, 0, dims.z - 1);
    return v[size_t((z * dims.y + y) * dims.x + x)];
  }
};

template <typename T>
Grid<T> sample(const Field& f, const Vec3s& dims) {
  GridSampler s(f, dims, ValueTypeOf<T>::value);
  Grid<T> g{dims, std::vector<T>(size_t(volume(dims)))};
  s.sample_slab(0, dims.z, {reinterpret_cast<std::byte*>(g.v.data()), g.v.size() * sizeof(T)});
  return g;
}

/// The box filter of the builder, written independently: 2x2x2 average (integers round half
/// up), the last sample replicated along odd dimensions.
template <typename T>
Grid<T> halve(const Grid<T>& g) {
  Grid<T> c{{(g.dims.x + 1) / 2, (g.dims.y + 1) / 2, (g.dims.z + 1) / 2}, {}};
  c.v.resize(size_t(volume(c.dims)));
  for (int64_t z = 0; z < c.dims.z; ++z)
    for (int64_t y = 0; y < c.dims.y; ++y)
      for (int64_t x = 0; x < c.dims.x; ++x) {
        double sum = 0;
        float fsum[8];
        int n = 0;
        for (int dz = 0; dz < 2; ++dz)
          for (int dy = 0; dy < 2; ++dy)
            for (int dx = 0; dx < 2; ++dx) {
              const T v = g.at(std::min(2 * x + dx, g.dims.x - 1), std::min(2 * y + dy, g.dims.y - 1),
                               std::min(2 * z + dz, g.dims.z - 1));
              sum += double(v);
              fsum[n++] = float(v);
            }
        T& out = c.v[size_t((z * c.dims.y + y) * c.dims.x + x)];
        if constexpr (std::is_same_v<T, float>)
          out = ((fsum[0] + fsum[1]) + (fsum[2] + fsum[3]) + (fsum[4] + fsum[5]) + (fsum[6] + fsum[7])) * 0.125f;
        else
          out = T(int64_t(std::floor((sum + 4) / 8)));
      }
  return c;
}

template <typename T>
Grid<T> read_level(const Store& store, int level) {
  const VoxelBox region = export_region(store, level, std::nullopt);
  Grid<T> g{region.size(), {}};
  g.v.reserve(size_t(volume(g.dims)));
  for_each_region_slab(store, level, region, [&](int64_t, int64_t, std::span<const std::byte> bytes) {
    const T* p = reinterpret_cast<const T*>(bytes.data());
    g.v.insert(g.v.end(), p, p + bytes.size() / sizeof(T));
  });
  return g;
}

/// Every stored record, for comparing two builds byte for byte.
inline std::vector<std::pair<uint64_t, std::vector<std::byte>>> all_records(const Store& store) {
  std::vector<std::pair<uint64_t, std::vector<std::byte>>> out;
  auto txn = store.begin_read();
  store.for_each_record(txn, [&](const BrickKey& k, std::span<const std::byte> r) {
    out.emplace_back(k.code(), std::vector<std::byte>(r.begin(), r.end()));
    return true;
  });
  return out;
}

}  // namespace brickyard::testing
