#include "dataset/dataset.h"

#include <fmt/format.h>

#include "core/error.h"

namespace brickyard {

std::string_view to_string(DataKind k) { return k == DataKind::structured ? "structured" : "tetrahedral"; }

DataKind data_kind_from_string(std::string_view s, std::string_view field) {
  if (s == "structured") return DataKind::structured;
  if (s == "tetrahedral") return DataKind::tetrahedral;
  throw Error(Errc::invalid_argument, fmt::format("unknown dataset kind '{}' (known: 'structured', 'tetrahedral')", s))
      .with_field(field);
}

namespace {
[[noreturn]] void no_view(const DatasetInfo& info, std::string_view view) {
  throw Error(Errc::unsupported, fmt::format("the dataset is {} and has no {} view", to_string(info.kind), view))
      .with_file(info.name);
}
}  // namespace

const GridView& Dataset::grid() const {
  if (!grid_) no_view(info_, "grid");
  return *grid_;
}

const TetView& Dataset::tets() const {
  if (!tets_) no_view(info_, "tetrahedral mesh");
  return *tets_;
}

const OctreeView& Dataset::octree() const {
  if (!octree_) {
    if (info_.kind != DataKind::structured) no_view(info_, "octree");
    throw Error(Errc::unsupported,
                fmt::format("the grid has no octree volume; build one with 'brickyard build-octree {}'", info_.name))
        .with_file(info_.name);
  }
  return *octree_;
}

}  // namespace brickyard
