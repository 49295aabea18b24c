#include "dataset/pages.h"

#include <fmt/format.h>

#include "core/error.h"

namespace brickyard {

std::string_view to_string(RecordKind k) {
  switch (k) {
    case RecordKind::brick: return "brick";
    case RecordKind::octree_page: return "octree_page";
    case RecordKind::tet_cluster: return "tet_cluster";
  }
  return "unknown";
}

RecordKind record_kind_from_string(std::string_view s, std::string_view field) {
  for (size_t k = 0; k < kRecordKinds; ++k)
    if (s == to_string(RecordKind(k))) return RecordKind(k);
  throw Error(Errc::invalid_argument,
              fmt::format("unknown record kind '{}' (known: 'brick', 'octree_page', 'tet_cluster')", s))
      .with_field(field);
}

std::string to_string(const PageKey& k) { return fmt::format("{} {:#x}", to_string(k.kind), k.id); }

}  // namespace brickyard
