#include "preprocess/convert.h"

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstring>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/parallel.h"

namespace brickyard {
namespace {

template <typename S>
S load(const std::byte* p) {
  S v;
  std::memcpy(&v, p, sizeof(S));
  return v;
}

template <typename S>
void scan_as(const std::byte* in, size_t n, ConversionReport& r) {
  for (size_t i = 0; i < n; ++i) {
    const S v = load<S>(in + i * sizeof(S));
    const double d = double(v);
    if constexpr (std::is_floating_point_v<S>) {
      if (!std::isfinite(d)) {
        ++r.nonfinite;
        continue;
      }
      if (std::fabs(d) > double(FLT_MAX)) {
        ++r.out_of_range;
        r.min = std::min(r.min, d), r.max = std::max(r.max, d);
        continue;
      }
    }
    r.min = std::min(r.min, d), r.max = std::max(r.max, d);
    const double err = std::fabs(double(float(v)) - d);
    if (err == 0) continue;
    ++r.inexact;
    if (err > r.max_abs_error) r.max_abs_error = err, r.worst_value = d;
    r.max_rel_error = std::max(r.max_rel_error, err / std::fabs(d));
  }
}

template <typename S, typename D>
void convert_as(const std::byte* in, size_t n, D* out) {
  for (size_t i = 0; i < n; ++i) out[i] = static_cast<D>(load<S>(in + i * sizeof(S)));
}

std::string value_text(double v) { return fmt::format("{:.17g}", v); }

}  // namespace

void ConversionReport::merge(const ConversionReport& o) {
  values += o.values, inexact += o.inexact, nonfinite += o.nonfinite, out_of_range += o.out_of_range;
  if (o.max_abs_error > max_abs_error) max_abs_error = o.max_abs_error, worst_value = o.worst_value;
  max_rel_error = std::max(max_rel_error, o.max_rel_error);
  min = std::min(min, o.min), max = std::max(max, o.max);
}

std::string ConversionReport::summary() const {
  std::string s = fmt::format("converted {} -> f32", to_string(from));
  if (min <= max) s += fmt::format(", values in [{}, {}]", value_text(min), value_text(max));
  if (exact()) return s + ": exact";
  s += fmt::format(": {} of {} values rounded, largest error {:g} (at {}), largest relative error {:.3g}", inexact,
                   values, max_abs_error, value_text(worst_value), max_rel_error);
  if (out_of_range) s += fmt::format(", {} beyond the float range", out_of_range);
  return s;
}

std::string ConversionReport::to_json() const {
  nlohmann::json j = {{"from", std::string(to_string(from))}, {"to", "f32"},     {"values", values},
                      {"exact", exact()},                     {"inexact", inexact}, {"max_abs_error", max_abs_error},
                      {"max_rel_error", max_rel_error}};
  if (nonfinite) j["nonfinite"] = nonfinite;
  if (out_of_range) j["out_of_range"] = out_of_range;
  return j.dump();
}

void scan_elements(const std::byte* in, ElementType from, size_t n, ConversionReport& r) {
  r.from = from;
  r.values += n;
  switch (from) {
    case ElementType::u8: return scan_as<uint8_t>(in, n, r);
    case ElementType::i8: return scan_as<int8_t>(in, n, r);
    case ElementType::u16: return scan_as<uint16_t>(in, n, r);
    case ElementType::i16: return scan_as<int16_t>(in, n, r);
    case ElementType::u32: return scan_as<uint32_t>(in, n, r);
    case ElementType::i32: return scan_as<int32_t>(in, n, r);
    case ElementType::f32: return scan_as<float>(in, n, r);
    case ElementType::f64: return scan_as<double>(in, n, r);
  }
}

void convert_elements(const std::byte* in, ElementType from, size_t n, std::byte* out) {
  if (is_native(from)) {
    std::memcpy(out, in, n * size_of(from));
    return;
  }
  float* dst = reinterpret_cast<float*>(out);
  switch (from) {
    case ElementType::u32: return convert_as<uint32_t>(in, n, dst);
    case ElementType::i32: return convert_as<int32_t>(in, n, dst);
    case ElementType::f64:
      // Beyond the float range the conversion is undefined: saturate to infinity explicitly.
      for (size_t i = 0; i < n; ++i) {
        const double v = load<double>(in + i * sizeof(double));
        dst[i] = std::isfinite(v) && std::fabs(v) > double(FLT_MAX) ? (v > 0 ? INFINITY : -INFINITY)
                                                                      : static_cast<float>(v);
      }
      return;
    default: return;
  }
}

std::pair<double, double> element_limits(ElementType t) {
  switch (t) {
    case ElementType::u8: return {0.0, 255.0};
    case ElementType::i8: return {-128.0, 127.0};
    case ElementType::u16: return {0.0, 65535.0};
    case ElementType::i16: return {-32768.0, 32767.0};
    case ElementType::u32: return {0.0, 4294967295.0};
    case ElementType::i32: return {-2147483648.0, 2147483647.0};
    default: return {0.0, 0.0};
  }
}

void scale_elements(const std::byte* in, ElementType from, size_t n, double slope, double intercept, double* out) {
  auto apply = [&](auto tag) {
    using S = decltype(tag);
    for (size_t i = 0; i < n; ++i) out[i] = slope * double(load<S>(in + i * sizeof(S))) + intercept;
  };
  switch (from) {
    case ElementType::u8: return apply(uint8_t{});
    case ElementType::i8: return apply(int8_t{});
    case ElementType::u16: return apply(uint16_t{});
    case ElementType::i16: return apply(int16_t{});
    case ElementType::u32: return apply(uint32_t{});
    case ElementType::i32: return apply(int32_t{});
    case ElementType::f32: return apply(float{});
    case ElementType::f64: return apply(double{});
  }
}

void store_values(const double* values, size_t n, ValueType to, std::byte* out) {
  if (to == ValueType::f32) return convert_elements(reinterpret_cast<const std::byte*>(values), ElementType::f64, n, out);
  dispatch_value_type(to, [&](auto tag) {
    using T = decltype(tag);
    T* dst = reinterpret_cast<T*>(out);
    for (size_t i = 0; i < n; ++i) dst[i] = static_cast<T>(values[i]);
  });
}

bool is_whole(double v) { return std::isfinite(v) && v == std::floor(v); }

void swap_element_bytes(std::span<std::byte> data, size_t element_size) {
  if (element_size < 2) return;
  for (size_t i = 0; i + element_size <= data.size(); i += element_size)
    std::reverse(data.begin() + long(i), data.begin() + long(i + element_size));
}

void check_conversion(const ConversionReport& r, const ConvertOptions& options, const std::string& file) {
  if (r.out_of_range)
    throw Error(Errc::format, fmt::format("{} of its {} values lie beyond the largest float ({:g}), the first found in "
                                          "[{}, {}]: f32 cannot hold them",
                                          r.out_of_range, to_string(r.from), double(FLT_MAX), value_text(r.min),
                                          value_text(r.max)))
        .with_file(file)
        .with_field("type");
  const bool integers = r.from == ElementType::u32 || r.from == ElementType::i32;
  if (integers && r.inexact && !options.accept_rounding)
    throw Error(Errc::invalid_argument,
                fmt::format("{} of its {} values exceed 2^24 in magnitude (values in [{}, {}]) and f32 would round "
                            "them, by up to {:g} (at {}); pass --convert f32 to accept the rounding",
                            r.inexact, to_string(r.from), value_text(r.min), value_text(r.max), r.max_abs_error,
                            value_text(r.worst_value)))
        .with_file(file)
        .with_field("--convert");
}

ConversionReport scan_conversion(const Vec3s& dims, ElementType from,
                                 const std::function<void(int64_t, int64_t, std::span<std::byte>)>& read,
                                 size_t slab_bytes) {
  const size_t es = size_of(from);
  const size_t slice = size_t(dims.x) * size_t(dims.y) * es;
  const int64_t slab = std::max<int64_t>(1, std::min<int64_t>(dims.z, int64_t(slab_bytes / std::max<size_t>(1, slice))));
  std::vector<std::byte> buffer;
  ConversionReport total;
  total.from = from;
  constexpr size_t kBlock = size_t(1) << 16;
  for (int64_t z0 = 0; z0 < dims.z; z0 += slab) {
    const int64_t z1 = std::min(dims.z, z0 + slab);
    buffer.resize(size_t(z1 - z0) * slice);
    read(z0, z1, buffer);
    const size_t n = buffer.size() / es, blocks = (n + kBlock - 1) / kBlock;
    std::vector<ConversionReport> partial(blocks);
    parallel_for<size_t>(0, blocks, 1, [&](size_t b0, size_t b1) {
      for (size_t b = b0; b < b1; ++b) {
        const size_t lo = b * kBlock, hi = std::min(n, lo + kBlock);
        scan_elements(buffer.data() + lo * es, from, hi - lo, partial[b]);
      }
    });
    for (const auto& p : partial) total.merge(p);
  }
  return total;
}

}  // namespace brickyard
