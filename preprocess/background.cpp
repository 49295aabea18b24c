#include "preprocess/background.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <vector>

#include "core/value_type.h"
#include "preprocess/volume_source.h"

namespace brickyard {
namespace {

constexpr int64_t kFaceSamples = int64_t(1) << 20;

template <typename T>
void collect_slice(const T* s, int64_t nx, int64_t ny, bool whole_face, std::vector<double>& out) {
  const auto take = [&](T v) {
    if constexpr (std::is_same_v<T, float>)
      if (!std::isfinite(v)) return;
    out.push_back(double(v));
  };
  if (whole_face) {
    const int64_t n = nx * ny, stride = std::max<int64_t>(1, n / kFaceSamples);
    for (int64_t i = 0; i < n; i += stride) take(s[i]);
    return;
  }
  for (int64_t x = 0; x < nx; ++x) take(s[x]), take(s[(ny - 1) * nx + x]);
  for (int64_t y = 1; y + 1 < ny; ++y) take(s[y * nx]), take(s[y * nx + nx - 1]);
}

}  // namespace

double estimate_background(VolumeSource& source, int max_slices) {
  const Vec3s d = source.dims();
  std::vector<int64_t> slices;
  if (source.can_skip() && d.z > max_slices + 2) {
    for (int i = 0; i <= max_slices + 1; ++i) slices.push_back(int64_t(double(i) * double(d.z - 1) / (max_slices + 1)));
    slices.erase(std::unique(slices.begin(), slices.end()), slices.end());
  } else {
    for (int64_t z = 0; z < d.z; ++z) slices.push_back(z);
  }
  std::vector<std::byte> slice(size_t(d.x * d.y) * size_of(source.type()));
  std::vector<double> values;
  int64_t next = 0;
  for (int64_t z : slices) {
    if (z < next) continue;
    source.read_slab(z, z + 1, slice);
    next = z + 1;
    const bool face = z == 0 || z == d.z - 1;
    dispatch_value_type(source.type(), [&](auto tag) {
      using T = decltype(tag);
      collect_slice(reinterpret_cast<const T*>(slice.data()), d.x, d.y, face, values);
    });
  }
  source.rewind();
  if (values.empty()) return 0.0;
  auto mid = values.begin() + long(values.size() / 2);
  std::nth_element(values.begin(), mid, values.end());
  return *mid;
}

}  // namespace brickyard
