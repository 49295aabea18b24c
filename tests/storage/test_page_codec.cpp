#include <gtest/gtest.h>

#include <cstdint>
#include <cstring>
#include <numeric>

#include "core/error.h"
#include "dataset/tet.h"
#include "storage/page_codec.h"

namespace brickyard {
namespace {

std::vector<std::byte> ramp(size_t n) {
  std::vector<std::byte> v(n);
  for (size_t i = 0; i < n; ++i) v[i] = std::byte(i * 13 / 7);
  return v;
}

TEST(PageCodec, RoundTripsIntoALargerPageAndZeroesTheRest) {
  const PageKey key{RecordKind::tet_cluster, 42};
  const std::vector<std::byte> bytes = ramp(1000);
  const std::vector<std::byte> record = encode_page(key, bytes);
  EXPECT_LT(record.size(), bytes.size());  // a smooth ramp compresses
  std::vector<std::byte> page(1500, std::byte{0x77});
  EXPECT_EQ(decode_page(key, record, page), 1000u);
  EXPECT_TRUE(std::equal(bytes.begin(), bytes.end(), page.begin()));
  for (size_t i = 1000; i < page.size(); ++i) ASSERT_EQ(page[i], std::byte{0}) << i;
  std::vector<std::byte> empty_page(16, std::byte{1});
  EXPECT_EQ(decode_page(key, encode_page(key, {}), empty_page), 0u);
  EXPECT_EQ(empty_page[0], std::byte{0});
  // Found by fuzzing: an empty record into a kind's empty page (a manifest may say 0 bytes)
  // passed a null pointer to memset.
  EXPECT_EQ(decode_page(key, encode_page(key, {}), std::span<std::byte>()), 0u);
}

Errc decode_error(const PageKey& key, const std::vector<std::byte>& record, size_t page_bytes, std::string* what) {
  std::vector<std::byte> page(page_bytes);
  try {
    decode_page(key, record, page);
  } catch (const Error& e) {
    *what = e.what();
    return e.code();
  }
  return Errc::internal;
}

TEST(PageCodec, EveryDamageIsACorruptErrorNamingTheKey) {
  const PageKey key{RecordKind::octree_page, 7};
  const std::vector<std::byte> good = encode_page(key, ramp(600));
  std::string what;
  auto flipped = good;
  flipped[sizeof(PageHeader) + 5] ^= std::byte{0xff};
  EXPECT_EQ(decode_error(key, flipped, 600, &what), Errc::corrupt);
  EXPECT_NE(what.find("octree_page 0x7"), std::string::npos) << what;
  EXPECT_EQ(decode_error({RecordKind::octree_page, 8}, good, 600, &what), Errc::corrupt);
  EXPECT_NE(what.find("record holds octree_page 0x7"), std::string::npos) << what;
  EXPECT_EQ(decode_error({RecordKind::tet_cluster, 7}, good, 600, &what), Errc::corrupt);
  EXPECT_EQ(decode_error(key, std::vector<std::byte>(good.begin(), good.end() - 3), 600, &what), Errc::corrupt);
  EXPECT_NE(what.find("payload size"), std::string::npos) << what;
  EXPECT_EQ(decode_error(key, std::vector<std::byte>(good.begin(), good.begin() + 10), 600, &what), Errc::corrupt);
  EXPECT_EQ(decode_error(key, good, 599, &what), Errc::corrupt);
  EXPECT_NE(what.find("more than the kind's 599-byte pages"), std::string::npos) << what;
  auto newer = good;
  newer[4] = std::byte{9};  // version
  EXPECT_EQ(decode_error(key, newer, 600, &what), Errc::unsupported);
}

// Found by fuzzing (tests/fuzz/regressions/page_codec/): a page's 32-bit counts whose byte size
// wraps 64 bits (2^30 vertices in 2^30 steps: 2^64 bytes, 0 after wrapping) fit any page, and the
// arrays pointed far outside it.
TEST(ClusterPage, CountsWhoseByteSizeOverflowsAreCorrupt) {
  EXPECT_EQ(TetClusterPage::bytes(uint32_t(1) << 30, 1, uint32_t(1) << 30, uint32_t(1) << 30), SIZE_MAX);
  EXPECT_EQ(TetClusterPage::bytes(8, 6), 16 + 8 * 4 * 4 + 6 * 16);
  std::vector<std::byte> page(64);
  const uint32_t header[4] = {uint32_t(1) << 30, 1, uint32_t(1) << 30, uint32_t(1) << 30};
  std::memcpy(page.data(), header, sizeof header);
  try {
    TetClusterPage::view(page);
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), Errc::corrupt);
    EXPECT_NE(e.message().find("cannot hold 1073741824 vertices"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace brickyard
