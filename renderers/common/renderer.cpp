#include "renderers/common/renderer.h"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

namespace brickyard {

bool BackendInfo::accepts(DataKind kind, RenderMode mode) const {
  return std::find(kinds.begin(), kinds.end(), kind) != kinds.end() &&
         std::find(modes.begin(), modes.end(), mode) != modes.end();
}

BackendParams::BackendParams(const BackendInfo& info, const std::map<std::string, double>& given, const std::string& file) {
  for (const BackendParam& p : info.params) values_[p.name] = p.default_value;
  for (const auto& [name, value] : given) {
    auto it = std::find_if(info.params.begin(), info.params.end(), [&](const BackendParam& p) { return p.name == name; });
    if (it == info.params.end()) {
      std::string known;
      for (const BackendParam& p : info.params) known += fmt::format("{}'{}'", known.empty() ? "" : ", ", p.name);
      Error e(Errc::invalid_argument, fmt::format("back end '{}' has no parameter '{}' (its parameters: {})", info.name,
                                                  name, known.empty() ? "none" : known));
      e.with_field(fmt::format("backend.params.{}", name));
      if (!file.empty()) e.with_file(file);
      throw e;
    }
    if (!(value >= it->lo && value <= it->hi)) {
      Error e(Errc::invalid_argument, fmt::format("{} is outside [{}, {}]", value, it->lo, it->hi));
      e.with_field(fmt::format("backend.params.{}", name));
      if (!file.empty()) e.with_file(file);
      throw e;
    }
    if (it->integer && value != std::floor(value)) {
      Error e(Errc::invalid_argument, fmt::format("{} is not a whole number ({} takes {})", value, name,
                                                  it->lo == 0 && it->hi == 1 ? "0 or 1" : "a count"));
      e.with_field(fmt::format("backend.params.{}", name));
      if (!file.empty()) e.with_file(file);
      throw e;
    }
    values_[name] = value;
  }
}

double BackendParams::operator[](const std::string& name) const {
  auto it = values_.find(name);
  BY_CHECK(it != values_.end());  // back ends read only parameters they declared
  return it->second;
}

const RenderContext::ValueSpan& RenderContext::range_below(const BrickKey& k) const {
  std::call_once(ranges_below_once_, [this] {
    const NodeTable& table = nodes();
    const GridLayout& layout = table.layout();
    ranges_below_.resize(size_t(layout.levels));
    for (int l = layout.finest(); l >= 0; --l) {
      const Vec3s n = layout.level_bricks(l);
      auto& spans = ranges_below_[size_t(l)];
      spans.resize(table.level(l).size());
      for (int64_t z = 0; z < n.z; ++z)
        for (int64_t y = 0; y < n.y; ++y)
          for (int64_t x = 0; x < n.x; ++x) {
            const BrickKey key{uint32_t(l), uint32_t(x), uint32_t(y), uint32_t(z)};
            const NodeRecord& r = table.at(key);
            ValueSpan s{r.min, r.max};
            if (l < layout.finest())
              for (int c = 0; c < 8; ++c) {
                const BrickKey child = key.child(c);
                if (!layout.contains(child)) continue;
                const ValueSpan& below = ranges_below_[size_t(l + 1)][size_t(layout.linear_index(child))];
                s.lo = std::min(s.lo, below.lo), s.hi = std::max(s.hi, below.hi);
              }
            spans[size_t(layout.linear_index(key))] = s;
          }
    }
  });
  return ranges_below_[k.level][size_t(layout().linear_index(k))];
}

uint64_t l1_staging_share(uint64_t staging, uint64_t budget_slots) {
  return std::clamp<uint64_t>(staging, 1, std::max<uint64_t>(budget_slots / 4, 1));
}

uint64_t RenderContext::backend_pool_bytes() const {
  const CacheConfig& c = pages_->config();
  return c.backend_pool_bytes.value_or(c.l1_bytes);
}

RenderContext::RenderContext(const Scene& scene, const Dataset& dataset, PageCache& pages, BrickCache* bricks)
    : scene_(scene), dataset_(dataset), pages_(&pages), bricks_(bricks) {
  BY_CHECK(dataset.has_grid() == (bricks != nullptr));
  VolumeGeometry& g = geometry_;
  const DatasetInfo& info = dataset.info();
  g.world = info.world;
  g.voxel_size = info.unit_length;
  if (dataset.has_grid()) {
    const GridView& grid = dataset.grid();
    g.dims = grid.dims();
    g.origin = grid.origin();
    g.spacing = grid.spacing();
    g.voxel_clip = Box3d(Vec3d(0.0), Vec3d(g.dims - Vec3s(1)));
  } else {
    g.origin = info.world.lo;
    g.voxel_clip = Box3d(Vec3d(0.0), info.world.extent());
  }
  if (scene.clip) {
    const Box3d c{g.to_voxel(g.from_normalised(scene.clip->lo)), g.to_voxel(g.from_normalised(scene.clip->hi))};
    g.voxel_clip = g.voxel_clip.intersect(c);
  }
}

void RenderContext::rebind_cache(PageCache& pages, BrickCache* bricks) {
  BY_CHECK(dataset_.has_grid() == (bricks != nullptr));
  pages_ = &pages;
  bricks_ = bricks;
}

void BackendRegistry::add(BackendEntry entry) {
  if (entry.info.name.empty() || !entry.create)
    throw Error(Errc::invalid_argument, "a back end needs a name and a factory").with_field("backend");
  if (contains(entry.info.name))
    throw Error(Errc::invalid_argument, fmt::format("a back end named '{}' is registered already", entry.info.name))
        .with_field("backend");
  entries_.push_back(std::move(entry));
}

bool BackendRegistry::contains(const std::string& name) const {
  return std::any_of(entries_.begin(), entries_.end(), [&](const BackendEntry& e) { return e.info.name == name; });
}

const BackendEntry& BackendRegistry::find(const std::string& name) const {
  for (const BackendEntry& e : entries_)
    if (e.info.name == name) return e;
  std::string known;
  for (const BackendEntry& e : entries_) known += fmt::format("{}'{}'", known.empty() ? "" : ", ", e.info.name);
  throw Error(Errc::invalid_argument, fmt::format("unknown back end '{}' (known: {})", name, known)).with_field("backend");
}

std::vector<std::string> BackendRegistry::names() const {
  std::vector<std::string> out;
  for (const BackendEntry& e : entries_) out.push_back(e.info.name);
  return out;
}

}  // namespace brickyard
