#include "storage/manifest.h"

#include <algorithm>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/json_reader.h"

namespace brickyard {

using nlohmann::json;

uint64_t Histogram::total() const {
  uint64_t n = 0;
  for (uint64_t c : counts) n += c;
  return n;
}

double Histogram::quantile(double q) const {
  const uint64_t n = total();
  if (n == 0 || counts.empty()) return lo;
  const double target = q * double(n);
  double acc = 0;
  for (size_t i = 0; i < counts.size(); ++i) {
    acc += double(counts[i]);
    if (acc >= target) return lo + (hi - lo) * double(i + 1) / double(counts.size());
  }
  return hi;
}

GridLayout Manifest::layout() const { return GridLayout::make(dims, format.brick_size); }

std::string Manifest::to_json() const {
  json j;
  j["format"] = "brickyard-store";
  j["format_version"] = format_version;
  j["complete"] = complete;
  j["kind"] = std::string(brickyard::to_string(kind));
  j["time_steps"] = time_steps;
  j["value_range"] = {min_value, max_value};
  j["source"] = json::parse(source);
  j["build"] = json::parse(build);
  if (kind == DataKind::tetrahedral) {
    j["mesh"] = {{"bounds", {{mesh.bounds.lo.x, mesh.bounds.lo.y, mesh.bounds.lo.z}, {mesh.bounds.hi.x, mesh.bounds.hi.y, mesh.bounds.hi.z}}},
                 {"clusters", mesh.clusters}, {"tets", mesh.tets}, {"vertices", mesh.vertices}, {"page_bytes", mesh.page_bytes},
                 {"moving", mesh.moving}};
    return j.dump(2);
  }
  j["dims"] = {dims.x, dims.y, dims.z};
  j["spacing"] = {spacing.x, spacing.y, spacing.z};
  j["origin"] = {origin.x, origin.y, origin.z};
  j["value_type"] = std::string(to_string(format.type));
  j["brick_size"] = format.brick_size;
  j["apron"] = format.apron;
  j["codec"] = {{"name", std::string(to_string(format.codec))}, {"hc_level", format.hc_level}, {"shuffle", format.shuffles()}};
  j["levels"] = levels;
  j["background"] = background;
  if (time_steps > 1 && !step_ranges.empty()) {  // a series build writes them with its final manifest
    json ranges = json::array();
    for (const StepValueRange& r : step_ranges) ranges.push_back({r.min, r.max});
    j["step_value_ranges"] = ranges;
  }
  j["histogram"] = {{"lo", histogram.lo}, {"hi", histogram.hi}, {"counts", histogram.counts}};
  json st = json::array();
  for (const auto& s : stats)
    st.push_back({{"bricks", s.bricks}, {"constant", s.constant}, {"empty", s.empty}, {"raw_bytes", s.raw_bytes},
                  {"stored_bytes", s.stored_bytes}});
  j["level_stats"] = st;
  if (octree) {
    const OctreeSummary& o = *octree;
    j["octree"] = {{"depth", o.depth}, {"pages", o.pages}, {"interior_nodes", o.interior_nodes}, {"caps", o.caps},
                   {"consolidated", o.consolidated}, {"bytes", o.bytes}, {"stored_bytes", o.stored_bytes},
                   {"raw_bytes", o.raw_bytes}, {"tolerance", o.tolerance}, {"max_error", o.max_error},
                   {"page_bytes", o.page_bytes}};
    j["octree"]["clamp"] = o.clamped ? json{o.clamp_lo, o.clamp_hi} : json(nullptr);
  }
  return j.dump(2);
}

namespace {
struct Reader {
  const json& j;
  const std::string& path;

  const json& at(const char* key) const {
    auto it = j.find(key);
    if (it == j.end()) throw Error(Errc::format, "missing key").with_file(path).with_field(key);
    return *it;
  }
  /// Exactly a T (json_exact): no wrong types, no numbers that do not fit, no infinities.
  template <typename T>
  T get(const char* key) const {
    const json& v = at(key);
    if (auto x = json_exact<T>(v)) return *x;
    throw Error(Errc::format, fmt::format("expected {}, found {}", json_expected<T>(), json_found(v)))
        .with_file(path)
        .with_field(key);
  }
  template <typename T>
  Vec3<T> vec3(const char* key) const {
    auto v = get<std::vector<T>>(key);
    if (v.size() != 3)
      throw Error(Errc::format, fmt::format("expected 3 numbers, got {}", v.size())).with_file(path).with_field(key);
    return {v[0], v[1], v[2]};
  }
};
}  // namespace

Manifest Manifest::from_json(const std::string& text, const std::string& path) {
  json j;
  try {
    j = json::parse(text);
  } catch (const json::exception& e) {
    throw Error(Errc::format, "manifest: " + json_error_message(e)).with_file(path);
  }
  if (!j.is_object()) throw Error(Errc::format, "manifest is not a JSON object").with_file(path);
  Reader r{j, path};
  if (r.get<std::string>("format") != "brickyard-store")
    throw Error(Errc::format, "not a brickyard store manifest").with_file(path).with_field("format");
  Manifest m;
  m.format_version = r.get<int>("format_version");
  if (m.format_version > kStoreFormatVersion)
    throw Error(Errc::unsupported, fmt::format("store format version {} is newer than this build reads ({}); "
                                               "upgrade brickyard", m.format_version, kStoreFormatVersion))
        .with_file(path)
        .with_field("format_version");
  if (m.format_version < 1)
    throw Error(Errc::format, fmt::format("invalid format version {}", m.format_version)).with_file(path).with_field("format_version");
  m.complete = r.get<bool>("complete");
  // Stores written before datasets had a kind are grids.
  if (j.contains("kind")) {
    try {
      m.kind = data_kind_from_string(r.get<std::string>("kind"));
    } catch (const Error& e) {
      throw Error(Errc::format, e.message()).with_file(path).with_field("kind");
    }
  }
  if (j.contains("time_steps")) m.time_steps = r.get<int>("time_steps");
  if (m.time_steps < 1)
    throw Error(Errc::format, fmt::format("{} time steps (need at least 1)", m.time_steps)).with_file(path).with_field("time_steps");
  const auto range = r.get<std::vector<double>>("value_range");
  if (range.size() != 2) throw Error(Errc::format, "expected [min, max]").with_file(path).with_field("value_range");
  m.min_value = range[0];
  m.max_value = range[1];
  m.source = r.at("source").dump();
  m.build = r.at("build").dump();
  if (m.kind == DataKind::tetrahedral) {
    if (m.format_version < 2)
      throw Error(Errc::format, fmt::format("a tetrahedral store needs format version 2 or later, not {}", m.format_version))
          .with_file(path)
          .with_field("format_version");
    const json& mesh = r.at("mesh");
    if (!mesh.is_object()) throw Error(Errc::format, "not an object").with_file(path).with_field("mesh");
    Reader rm{mesh, path};
    const auto bounds = rm.get<std::vector<std::vector<double>>>("bounds");
    if (bounds.size() != 2 || bounds[0].size() != 3 || bounds[1].size() != 3)
      throw Error(Errc::format, "expected [[x, y, z], [x, y, z]]").with_file(path).with_field("mesh.bounds");
    m.mesh.bounds = Box3d(Vec3d(bounds[0][0], bounds[0][1], bounds[0][2]), Vec3d(bounds[1][0], bounds[1][1], bounds[1][2]));
    m.mesh.clusters = rm.get<uint64_t>("clusters");
    m.mesh.tets = rm.get<uint64_t>("tets");
    m.mesh.vertices = rm.get<uint64_t>("vertices");
    m.mesh.page_bytes = rm.get<uint64_t>("page_bytes");
    if (mesh.contains("moving")) m.mesh.moving = rm.get<bool>("moving");
    return m;
  }
  if (m.time_steps > 1) {
    if (m.format_version < kTimeSeriesGridFormatVersion)
      throw Error(Errc::format, fmt::format("a grid of {} time steps needs format version {} or later, not {}", m.time_steps,
                                            kTimeSeriesGridFormatVersion, m.format_version))
          .with_file(path)
          .with_field("format_version");
    // Written with the final manifest: an interrupted build's has none yet, and gets none.
    if (m.complete || j.contains("step_value_ranges")) {
      const auto ranges = r.get<std::vector<std::vector<double>>>("step_value_ranges");
      if (ranges.size() != size_t(m.time_steps))
        throw Error(Errc::format, fmt::format("{} ranges for {} time steps", ranges.size(), m.time_steps))
            .with_file(path)
            .with_field("step_value_ranges");
      for (size_t i = 0; i < ranges.size(); ++i) {
        if (ranges[i].size() != 2 || !(ranges[i][0] <= ranges[i][1]))
          throw Error(Errc::format, fmt::format("step {}: expected [min, max] with min <= max", i))
              .with_file(path)
              .with_field("step_value_ranges");
        m.step_ranges.push_back({ranges[i][0], ranges[i][1]});
      }
    }
  }
  m.dims = r.vec3<int64_t>("dims");
  m.spacing = r.vec3<double>("spacing");
  m.origin = r.vec3<double>("origin");
  const auto type = parse_value_type(r.get<std::string>("value_type"));
  if (!type) throw Error(Errc::format, "unknown value type").with_file(path).with_field("value_type");
  m.format.type = *type;
  m.format.brick_size = r.get<int>("brick_size");
  m.format.apron = r.get<int>("apron");
  if (m.format.apron < 0 || m.format.apron > 4)
    throw Error(Errc::format, fmt::format("apron {} is outside [0, 4]", m.format.apron)).with_file(path).with_field("apron");
  const json& codec = r.at("codec");
  Reader rc{codec, path};
  const auto codec_name = rc.get<std::string>("name");
  if (codec_name == "lz4") m.format.codec = Codec::lz4;
  else if (codec_name == "lz4hc") m.format.codec = Codec::lz4hc;
  else if (codec_name == "none") m.format.codec = Codec::none;
  else throw Error(Errc::unsupported, fmt::format("unknown codec '{}'", codec_name)).with_file(path).with_field("codec.name");
  m.format.hc_level = rc.get<int>("hc_level");
  m.format.shuffle = rc.get<bool>("shuffle");
  m.levels = r.get<int>("levels");
  m.background = r.get<double>("background");
  const json& h = r.at("histogram");
  Reader rh{h, path};
  m.histogram.lo = rh.get<double>("lo");
  m.histogram.hi = rh.get<double>("hi");
  m.histogram.counts = rh.get<std::vector<uint64_t>>("counts");
  if (!r.at("level_stats").is_array())
    throw Error(Errc::format, fmt::format("expected an array, found {}", json_found(r.at("level_stats"))))
        .with_file(path)
        .with_field("level_stats");
  for (const json& s : r.at("level_stats")) {
    Reader rs{s, path};
    m.stats.push_back({rs.get<int64_t>("bricks"), rs.get<int64_t>("constant"), rs.get<int64_t>("empty"),
                       rs.get<uint64_t>("raw_bytes"), rs.get<uint64_t>("stored_bytes")});
  }
  if (j.contains("octree")) {
    const json& oj = r.at("octree");
    if (!oj.is_object()) throw Error(Errc::format, "not an object").with_file(path).with_field("octree");
    Reader ro{oj, path};
    OctreeSummary o;
    o.depth = ro.get<int>("depth");
    o.pages = ro.get<uint64_t>("pages");
    o.interior_nodes = ro.get<uint64_t>("interior_nodes");
    o.caps = ro.get<uint64_t>("caps");
    o.consolidated = ro.get<uint64_t>("consolidated");
    o.bytes = ro.get<uint64_t>("bytes");
    o.stored_bytes = ro.get<uint64_t>("stored_bytes");
    o.raw_bytes = ro.get<uint64_t>("raw_bytes");
    o.tolerance = ro.get<double>("tolerance");
    o.max_error = ro.get<double>("max_error");
    o.page_bytes = ro.get<uint64_t>("page_bytes");
    const json& clamp = ro.at("clamp");
    if (!clamp.is_null()) {
      const auto c = ro.get<std::vector<double>>("clamp");
      if (c.size() != 2) throw Error(Errc::format, "expected [lo, hi] or null").with_file(path).with_field("octree.clamp");
      o.clamped = true, o.clamp_lo = c[0], o.clamp_hi = c[1];
    }
    const OctreeLayout ol = OctreeLayout::make(m.dims, m.format.type);
    if (o.depth != ol.depth || o.page_bytes != ol.page_bytes())
      throw Error(Errc::format, fmt::format("octree of depth {} with {}-byte pages, but the grid's dims give depth {} "
                                            "and {}-byte pages", o.depth, o.page_bytes, ol.depth, ol.page_bytes()))
          .with_file(path)
          .with_field("octree");
    if (m.time_steps > 1)
      throw Error(Errc::format, "an octree volume over a grid of several time steps").with_file(path).with_field("octree");
    m.octree = o;
  }
  // The layout must agree with the recorded level count, or nothing else can be trusted.
  const GridLayout layout = m.layout();
  if (layout.levels != m.levels)
    throw Error(Errc::format, fmt::format("{} levels recorded, but dims and brick size give {}", m.levels, layout.levels))
        .with_file(path)
        .with_field("levels");
  return m;
}

}  // namespace brickyard
