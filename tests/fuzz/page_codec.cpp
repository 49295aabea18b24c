// Page records of every kind but bricks (storage/page_codec.h), and what their decoded pages
// hold: decode_page over untrusted record bytes; then a tetrahedral cluster's page as tet_bvh
// reads it (dataset/tet.h, dataset/tet_bvh.h: TetClusterPage::view, the BVH the importer may
// have stored after the tets, one built and refitted over it), or an octree page as octree_cgt
// reads it (dataset/octree.h: OctreePage::view, for the 24^3 f32 grid of the seeds).
//
// Input: 4 bytes of parameters (mode, the kind's page size in 8-byte units, the leaf size),
// then the record. In mode "page" (bit 0 of the first byte) the rest is a decoded page
// instead: it is encoded (encode_page), so its checksum holds, and decoded again, which
// reaches the page readers with any contents a forged store could give them.

#include <cstring>
#include <vector>

#include "dataset/octree.h"
#include "dataset/tet.h"
#include "dataset/tet_bvh.h"
#include "storage/page_codec.h"
#include "tests/fuzz/fuzz_util.h"

using namespace brickyard;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  fuzz::Prefix in(data, size);
  const uint8_t mode = in.u8();
  const bool page_mode = mode & 1;
  const RecordKind kind = (mode & 2) ? RecordKind::octree_page : RecordKind::tet_cluster;
  const size_t page_bytes = 8 * (size_t(in.u8()) | (size_t(in.u8()) << 8));
  const uint8_t leaf = in.u8();
  const tet_bvh::BuildMethod method = (leaf & 0x80) ? tet_bvh::BuildMethod::sah : tet_bvh::BuildMethod::bih;
  const uint32_t leaf_size = 1 + leaf % 16;
  const PageKey key{kind, 7};
  const std::span<const std::byte> rest(reinterpret_cast<const std::byte*>(in.rest()), in.rest_size());

  return fuzz::run_one([&] {
    std::vector<std::byte> record;
    std::span<const std::byte> stored = rest;
    if (page_mode) {
      record = encode_page(key, rest);
      stored = record;
    }
    std::vector<std::byte> page(page_mode ? std::max(page_bytes, rest.size()) : page_bytes);
    const size_t used = decode_page(key, stored, page);
    if (used > page.size()) std::abort();
    if (kind == RecordKind::octree_page) {
      static const OctreeLayout layout = OctreeLayout::make(Vec3s(24), ValueType::f32);
      (void)OctreePage<float>::view(page, layout);
      return;
    }
    // The page's size as the store would give it: the kind's fixed size (whole 4-byte units).
    page.resize(page.size() / 4 * 4);
    const TetClusterPage view = TetClusterPage::view(page);
    const auto bvh = tet_bvh::ClusterBvh::stored(view, method, leaf_size);
    const tet_bvh::ClusterBvh built = tet_bvh::ClusterBvh::build(view, 0, method, leaf_size);
    for (uint32_t step = 1; step < std::min<uint32_t>(view.steps, 4); ++step) (void)built.refit(view, step);
    (void)bvh;
  });
}
