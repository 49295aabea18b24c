#include "core/raw_volume.h"

#include <algorithm>
#include <array>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <nlohmann/json.hpp>

#include "core/atomic_file.h"
#include "core/error.h"
#include "core/json_reader.h"

namespace brickyard {

using nlohmann::json;

std::optional<uint64_t> checked_grid_bytes(const Vec3s& dims, ValueType t) {
  if (dims.x < 1 || dims.y < 1 || dims.z < 1) return std::nullopt;
  uint64_t n = static_cast<uint64_t>(dims.x);
  if (__builtin_mul_overflow(n, static_cast<uint64_t>(dims.y), &n)) return std::nullopt;
  if (__builtin_mul_overflow(n, static_cast<uint64_t>(dims.z), &n)) return std::nullopt;
  if (__builtin_mul_overflow(n, static_cast<uint64_t>(size_of(t)), &n)) return std::nullopt;
  if (n > static_cast<uint64_t>(INT64_MAX)) return std::nullopt;
  return n;
}

std::string spacing_problem(const Vec3d& spacing) {
  for (int a = 0; a < 3; ++a)
    if (!(std::isfinite(spacing[a]) && spacing[a] > 0))
      return fmt::format("spacing ({:g}, {:g}, {:g}): every axis needs a positive, finite distance between samples",
                         spacing.x, spacing.y, spacing.z);
  return {};
}

std::string raw_sidecar_path(const std::string& raw_path) { return raw_path + ".json"; }

void write_file_atomically(const std::string& path, const std::string& contents) {
  AtomicFile file(path);
  file.write(contents.data(), contents.size());
  file.commit();
}

void write_raw_sidecar(const std::string& sidecar_path, const RawVolumeInfo& info) {
  json j;
  j["brickyard_raw"] = kRawSidecarVersion;
  j["dims"] = {info.dims.x, info.dims.y, info.dims.z};
  j["type"] = std::string(to_string(info.type));
  j["endianness"] = info.little_endian ? "little" : "big";
  j["spacing"] = {info.spacing.x, info.spacing.y, info.spacing.z};
  j["origin"] = {info.origin.x, info.origin.y, info.origin.z};
  j["value_range"] = {info.min_value, info.max_value};
  if (info.quantization) j["quantization"] = {{"lo", info.quantization->first}, {"hi", info.quantization->second}};
  j["source"] = info.source;
  json params = json::object();
  for (const auto& [k, v] : info.source_params) params[k] = v;
  j["source_params"] = params;
  j["bytes"] = info.bytes;
  if (info.xxh3_64) j["xxh3_64"] = fmt::format("{:016x}", *info.xxh3_64);
  write_file_atomically(sidecar_path, j.dump(2) + "\n");
}

namespace {

// Typed access that names the key in every error.
// Exactly a T (json_exact): no wrong types, no numbers that do not fit, no infinities.
template <typename T>
T get_as(const json& j, const char* key, const std::string& path) {
  auto it = j.find(key);
  if (it == j.end()) throw Error(Errc::format, "missing key").with_file(path).with_field(key);
  if (auto x = json_exact<T>(*it)) return *x;
  throw Error(Errc::format, fmt::format("expected {}, found {}", json_expected<T>(), json_found(*it)))
      .with_file(path)
      .with_field(key);
}

template <typename T>
Vec3<T> get_vec3(const json& j, const char* key, const std::string& path) {
  auto v = get_as<std::vector<T>>(j, key, path);
  if (v.size() != 3)
    throw Error(Errc::format, fmt::format("expected 3 numbers, got {}", v.size())).with_file(path).with_field(key);
  return {v[0], v[1], v[2]};
}

}  // namespace

RawVolumeInfo read_raw_sidecar(const std::string& path) {
  check_readable_file(path);
  std::ifstream in(path);
  if (!in) throw Error(Errc::io, fmt::format("cannot open: {}", std::strerror(errno))).with_file(path);
  json j;
  try {
    j = json::parse(in);
  } catch (const json::exception& e) {
    throw Error(Errc::format, json_error_message(e)).with_file(path);
  }
  if (!j.is_object()) throw Error(Errc::format, "expected a JSON object").with_file(path);
  // A key this build does not know is a typo or a newer writer: either way its meaning would be lost.
  static constexpr std::array kKnownKeys = {"brickyard_raw", "dims",   "type",          "endianness", "spacing", "origin",
                                            "value_range",   "quantization", "source", "source_params", "bytes", "xxh3_64"};
  for (auto it = j.begin(); it != j.end(); ++it)
    if (std::find(kKnownKeys.begin(), kKnownKeys.end(), it.key()) == kKnownKeys.end())
      throw Error(Errc::format, fmt::format("unknown key (a sidecar has: {})", fmt::join(kKnownKeys, ", ")))
          .with_file(path)
          .with_field(it.key());
  const int version = get_as<int>(j, "brickyard_raw", path);
  if (version > kRawSidecarVersion)
    throw Error(Errc::unsupported, fmt::format("sidecar version {} is newer than this build reads ({})", version,
                                               kRawSidecarVersion))
        .with_file(path)
        .with_field("brickyard_raw");

  RawVolumeInfo info;
  info.dims = get_vec3<int64_t>(j, "dims", path);
  if (info.dims.x < 1 || info.dims.y < 1 || info.dims.z < 1)
    throw Error(Errc::format, "every dimension must be at least 1").with_file(path).with_field("dims");
  const auto type_name = get_as<std::string>(j, "type", path);
  const auto type = parse_value_type(type_name);
  if (!type)
    throw Error(Errc::format, fmt::format("unknown value type '{}' (expected u8, i8, u16, i16 or f32)", type_name))
        .with_file(path)
        .with_field("type");
  info.type = *type;
  const auto endian = get_as<std::string>(j, "endianness", path);
  if (endian != "little" && endian != "big")
    throw Error(Errc::format, fmt::format("'{}' is neither 'little' nor 'big'", endian)).with_file(path).with_field("endianness");
  info.little_endian = endian == "little";
  info.spacing = get_vec3<double>(j, "spacing", path);
  if (const std::string problem = spacing_problem(info.spacing); !problem.empty())
    throw Error(Errc::format, problem).with_file(path).with_field("spacing");
  info.origin = get_vec3<double>(j, "origin", path);
  auto range = get_as<std::vector<double>>(j, "value_range", path);
  if (range.size() != 2 || range[0] > range[1])
    throw Error(Errc::format, "expected [min, max] with min <= max").with_file(path).with_field("value_range");
  info.min_value = range[0];
  info.max_value = range[1];
  if (auto q = j.find("quantization"); q != j.end()) {
    if (!q->is_object())
      throw Error(Errc::format, fmt::format("expected {{\"lo\": LO, \"hi\": HI}}, found {}", json_found(*q)))
          .with_file(path)
          .with_field("quantization");
    info.quantization = {get_as<double>(*q, "lo", path), get_as<double>(*q, "hi", path)};
  }
  if (j.contains("source")) info.source = get_as<std::string>(j, "source", path);
  if (auto p = j.find("source_params"); p != j.end() && p->is_object())
    for (auto it = p->begin(); it != p->end(); ++it) {
      const auto v = json_exact<double>(it.value());
      if (!v)
        throw Error(Errc::format, fmt::format("expected a finite number, found {}", json_found(it.value())))
            .with_file(path)
            .with_field("source_params." + it.key());
      info.source_params.emplace_back(it.key(), *v);
    }
  info.bytes = get_as<uint64_t>(j, "bytes", path);
  if (j.contains("xxh3_64")) {
    const auto hex = get_as<std::string>(j, "xxh3_64", path);
    char* end = nullptr;
    errno = 0;
    const unsigned long long v = std::strtoull(hex.c_str(), &end, 16);
    // Hex digits only: strtoull would also take a sign ("-1" as 2^64 - 1), spaces and "0x", and
    // stop at an embedded NUL.
    const bool digits = !hex.empty() && hex.size() <= 16 &&
                        std::all_of(hex.begin(), hex.end(), [](unsigned char c) { return std::isxdigit(c) != 0; });
    if (!digits || *end != '\0' || errno != 0)
      throw Error(Errc::format, fmt::format("'{}' is not a hexadecimal checksum", hex)).with_file(path).with_field("xxh3_64");
    info.xxh3_64 = v;
  }
  const auto grid_bytes = checked_grid_bytes(info.dims, info.type);
  if (!grid_bytes)
    throw Error(Errc::format, fmt::format("dims {}x{}x{} overflow a 64-bit byte count", info.dims.x, info.dims.y,
                                          info.dims.z))
        .with_file(path)
        .with_field("dims");
  const uint64_t expected = *grid_bytes;
  if (info.bytes != expected)
    throw Error(Errc::format, fmt::format("{} bytes does not match dims {}x{}x{} of {} ({} bytes)", info.bytes,
                                          info.dims.x, info.dims.y, info.dims.z, to_string(info.type), expected))
        .with_file(path)
        .with_field("bytes");
  return info;
}

}  // namespace brickyard
