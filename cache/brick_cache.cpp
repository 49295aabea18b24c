#include "cache/brick_cache.h"

#include <fmt/format.h>

#include "core/error.h"

namespace brickyard {

BrickCache::BrickCache(PageCache& pages, const GridView& grid) : pages_(pages), grid_(grid) {
  if (!pages.holds(RecordKind::brick)) throw Error(Errc::invalid_argument, "the page cache holds no bricks");
  if (pages.page_bytes(RecordKind::brick) != grid.shape().bytes())
    throw Error(Errc::internal, fmt::format("the cache's bricks are {} bytes, the grid's {}", pages.page_bytes(RecordKind::brick),
                                            grid.shape().bytes()));
}

void BrickCache::set_node(BrickHandle& h, const BrickKey& key, const NodeRecord& node, BrickHandle::State state) {
  h.key_ = key;
  h.state_ = state;
  h.min_ = node.min;
  h.max_ = node.max;
  h.constant_ = node.constant;
}

BrickHandle BrickCache::lookup(const BrickKey& key, float priority, bool request_on_miss) {
  BrickHandle h;
  if (!grid_.layout().contains(key)) {
    h.key_ = key;
    h.state_ = BrickHandle::State::failed;
    h.page_.state_ = PageHandle::State::failed;
    h.page_.error_ = std::make_shared<const std::string>(
        fmt::format("key {}: brick is outside the grid's {} levels", key.to_string(), grid_.layout().levels));
    return h;
  }
  const NodeRecord& node = grid_.nodes().at(key);
  if (node.is_constant()) {
    pages_.count_constant_hit(RecordKind::brick);
    set_node(h, key, node, BrickHandle::State::constant);
    return h;
  }
  pages_.lookup_into(h.page_, page_key(key), priority, request_on_miss);
  set_node(h, key, node,
           h.page_.resident() ? BrickHandle::State::resident
           : h.page_.failed() ? BrickHandle::State::failed
                              : BrickHandle::State::miss);
  return h;
}

BrickHandle BrickCache::fetch(const BrickKey& key) {
  if (!grid_.layout().contains(key))
    throw Error(Errc::not_found, fmt::format("brick is outside the grid's {} levels", grid_.layout().levels))
        .with_key(key.to_string());
  BrickHandle h;
  const NodeRecord& node = grid_.nodes().at(key);
  if (node.is_constant()) {
    set_node(h, key, node, BrickHandle::State::constant);
    return h;
  }
  h.page_ = pages_.fetch(page_key(key));
  set_node(h, key, node, BrickHandle::State::resident);
  return h;
}

BrickHandle BrickCache::fetch_or_failed(const BrickKey& key) {
  if (!grid_.layout().contains(key)) return lookup(key, 0, false);  // a failed handle naming the grid
  BrickHandle h;
  const NodeRecord& node = grid_.nodes().at(key);
  if (node.is_constant()) {
    set_node(h, key, node, BrickHandle::State::constant);
    return h;
  }
  h.page_ = pages_.fetch_or_failed(page_key(key));
  set_node(h, key, node, h.page_.failed() ? BrickHandle::State::failed : BrickHandle::State::resident);
  return h;
}

void BrickCache::request(const BrickKey& key, float priority) {
  if (!grid_.layout().contains(key) || grid_.nodes().at(key).is_constant()) return;
  pages_.request(page_key(key), priority);
}

std::vector<BrickRequest> BrickCache::frame_requests() const {
  std::vector<BrickRequest> out;
  for (const PageRequest& r : pages_.frame_requests())
    if (r.key.kind == RecordKind::brick) out.push_back({BrickKey::from_code(r.key.id), r.priority});
  return out;
}

}  // namespace brickyard
