#include <gtest/gtest.h>

#include <atomic>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <thread>
#include <vector>

#include "cache/brick_cache.h"
#include "session/grid_cache.h"
#include "cache/trace.h"
#include "core/error.h"
#include "preprocess/builder.h"
#include "preprocess/volume_source.h"
#include "test_util.h"

namespace brickyard {
namespace {

/// A store shared by the tests of this file: fbm 64^3 u8 with 8^3 bricks (512 finest).
class BrickCacheTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new testing::TempDir();
    BuildOptions o;
    o.brick_size = 8;
    auto fbm = make_field_source(make_field("fbm"), {64, 64, 64}, ValueType::u8);
    build_store(*fbm, dir_->file("fbm"), o);
    auto blobs = make_field_source(make_field("sparse-blobs"), {64, 64, 64}, ValueType::u8);
    build_store(*blobs, dir_->file("blobs"), o);
    store_ = new Store(dir_->file("fbm"));
  }
  static void TearDownTestSuite() {
    delete store_;
    delete dir_;
  }
  static std::vector<BrickKey> finest_keys(const Store& s) {
    std::vector<BrickKey> keys;
    const GridLayout& l = s.layout();
    for (int64_t i = 0; i < l.brick_count(l.finest()); ++i) {
      const BrickKey k = l.key_at(l.finest(), i);
      if (s.nodes().at(k).has_payload()) keys.push_back(k);
    }
    return keys;
  }
  static std::vector<std::byte> decoded(const Store& s, const BrickKey& k) {
    std::vector<std::byte> out(s.format().bytes());
    s.read_brick(k, out);
    return out;
  }
  static testing::TempDir* dir_;
  static Store* store_;
};
testing::TempDir* BrickCacheTest::dir_ = nullptr;
Store* BrickCacheTest::store_ = nullptr;

CacheConfig small_config(uint32_t slots, uint64_t l2_bricks, uint64_t brick_bytes) {
  CacheConfig c;
  c.l1_slots = slots;
  c.l2_bytes = l2_bricks * brick_bytes;
  return c;
}

/// One frame of a renderer's lookups (its misses become requests), then the loader waited for:
/// how many were resident when looked up.
int ask_one_frame(BrickCache& cache, const std::vector<BrickRequest>& asked) {
  cache.frame_begin();
  int resident = 0;
  for (const BrickRequest& r : asked) resident += cache.lookup(r.key, r.priority).resident();
  cache.frame_end();
  cache.wait_idle();
  return resident;
}

/// How many of `asked` are resident now (looked up without requesting).
int resident_now(BrickCache& cache, const std::vector<BrickRequest>& asked) {
  int resident = 0;
  for (const BrickRequest& r : asked) resident += cache.lookup(r.key, 0, false).resident();
  return resident;
}

TEST_F(BrickCacheTest, FetchReturnsTheDecodedBrickPinnedInTheePool) {
  GridCache cache_pages(*store_, small_config(16, 64, store_->format().bytes()));
  BrickCache& cache = cache_pages.bricks();
  const auto keys = finest_keys(*store_);
  BrickHandle h = cache.fetch(keys[3]);
  ASSERT_TRUE(h.resident());
  ASSERT_NE(h.slot(), kNoSlot);
  EXPECT_EQ(std::memcmp(h.bytes(), decoded(*store_, keys[3]).data(), store_->format().bytes()), 0);
  EXPECT_EQ(h.min(), store_->nodes().at(keys[3]).min);
  EXPECT_EQ(h.key(), keys[3]);
  EXPECT_EQ(cache.stats().stalls, 1u);
  BrickHandle again = cache.fetch(keys[3]);  // now an L1 hit: no stall
  EXPECT_EQ(again.slot(), h.slot());
  EXPECT_EQ(cache.stats().stalls, 1u);
  EXPECT_EQ(cache.stats().l1.hits, 1u);
}

TEST_F(BrickCacheTest, AMissQueuesARequestThatTheLoaderServes) {
  GridCache cache_pages(*store_, small_config(64, 64, store_->format().bytes()));
  BrickCache& cache = cache_pages.bricks();
  const auto keys = finest_keys(*store_);
  cache.frame_begin();
  for (int i = 0; i < 10; ++i) {
    BrickHandle h = cache.lookup(keys[size_t(i)], float(i));
    EXPECT_EQ(h.state(), BrickHandle::State::miss);
  }
  cache.lookup(keys[0], 100.0f);  // a duplicate with a higher priority: merged
  const FrameReport report = cache.frame_end();
  EXPECT_EQ(report.requests, 10u);
  const auto requested = cache.frame_requests();
  ASSERT_EQ(requested.size(), 10u);
  EXPECT_EQ(requested[0].key, keys[0]);  // highest priority first
  EXPECT_EQ(requested[0].priority, 100.0f);
  EXPECT_EQ(requested[1].key, keys[9]);
  cache.wait_idle();
  cache.frame_begin();
  for (int i = 0; i < 10; ++i) {
    BrickHandle h = cache.lookup(keys[size_t(i)]);
    ASSERT_TRUE(h.resident()) << keys[size_t(i)];
    EXPECT_EQ(std::memcmp(h.bytes(), decoded(*store_, keys[size_t(i)]).data(), store_->format().bytes()), 0);
  }
  const CacheStats s = cache.stats();
  EXPECT_EQ(s.requests, 10u);
  EXPECT_EQ(s.uploads, 10u);
  EXPECT_EQ(s.l3_bytes_decoded, 10 * store_->format().bytes());
  EXPECT_GT(s.latency_p99_ms, 0.0);
  EXPECT_EQ(s.stalls, 0u);
}

TEST_F(BrickCacheTest, ConstantNodesNeedNoSlot) {
  Store blobs(dir_->file("blobs"));
  GridCache cache_pages(blobs, small_config(4, 8, blobs.format().bytes()));
  BrickCache& cache = cache_pages.bricks();
  const GridLayout& l = blobs.layout();
  int constants = 0;
  for (int64_t i = 0; i < l.brick_count(l.finest()); ++i) {
    const BrickKey k = l.key_at(l.finest(), i);
    if (!blobs.nodes().at(k).is_constant()) continue;
    BrickHandle h = cache.lookup(k);
    ASSERT_TRUE(h.constant());
    EXPECT_EQ(h.slot(), kNoSlot);
    EXPECT_EQ(h.constant_value(), blobs.nodes().at(k).constant);
    ++constants;
  }
  EXPECT_GT(constants, 100);
  EXPECT_EQ(cache.stats().l1.resident, 0u);
  EXPECT_EQ(cache.stats().constant_hits, uint64_t(constants));
}

TEST_F(BrickCacheTest, AConstantBrickAskedOfThePageCacheIsItsValueNotAnError) {
  // The typed view answers constant nodes itself; a caller of the page cache below it (a tool
  // that knows only pages) gets the brick filled with the node's value, as read_brick gives it.
  Store blobs(dir_->file("blobs"));
  GridCache cache(blobs, small_config(4, 8, blobs.format().bytes()));
  const GridLayout& l = blobs.layout();
  for (int64_t i = 0; i < l.brick_count(l.finest()); ++i) {
    const BrickKey k = l.key_at(l.finest(), i);
    const NodeRecord& n = blobs.nodes().at(k);
    if (!n.is_constant()) continue;
    const PageHandle h = cache.pages().fetch(BrickCache::page_key(k));
    ASSERT_TRUE(h.resident());
    for (size_t v = 0; v < blobs.format().voxels(); ++v) ASSERT_EQ(float(uint8_t(h.bytes()[v])), n.constant) << v;
    EXPECT_EQ(cache.pages().stats().l3_bytes_read, 0u);  // no record was read
    EXPECT_EQ(cache.pages().stats().failed_keys, 0u);
    return;
  }
  FAIL() << "no constant brick";
}

TEST(BrickCacheConstants, NearConstantBricksCarryTheirStoredValue) {
  // With a tolerance, a constant node's value is the middle of its range, not its minimum.
  testing::TempDir dir;
  BuildOptions o;
  o.brick_size = 8;
  o.constant_tolerance = 255;
  auto src = make_field_source(make_field("sphere"), {32, 32, 32}, ValueType::u8);
  build_store(*src, dir.file("s"), o);
  Store store(dir.file("s"));
  CacheConfig c;
  c.l1_slots = 4;
  c.l2_bytes = 4 * store.format().bytes();
  GridCache cache_pages(store, c);
  BrickCache& cache = cache_pages.bricks();
  int differs = 0;
  for (int64_t i = 0; i < store.layout().brick_count(store.layout().finest()); ++i) {
    const BrickKey k = store.layout().key_at(store.layout().finest(), i);
    BrickHandle h = cache.lookup(k);
    ASSERT_TRUE(h.constant());
    EXPECT_EQ(h.constant_value(), store.nodes().at(k).constant);
    differs += h.constant_value() != h.min();
  }
  EXPECT_GT(differs, 0);
}

TEST_F(BrickCacheTest, PinnedSlotsAreNeverEvicted) {
  GridCache cache_pages(*store_, small_config(4, 64, store_->format().bytes()));
  BrickCache& cache = cache_pages.bricks();
  const auto keys = finest_keys(*store_);
  std::vector<BrickHandle> pinned;
  for (int i = 0; i < 4; ++i) pinned.push_back(cache.fetch(keys[size_t(i)]));
  BrickHandle extra = cache.fetch(keys[4]);  // the pool is pinned full: a private copy
  ASSERT_TRUE(extra.resident());
  EXPECT_EQ(extra.slot(), kNoSlot);
  EXPECT_EQ(std::memcmp(extra.bytes(), decoded(*store_, keys[4]).data(), store_->format().bytes()), 0);
  EXPECT_GT(cache.stats().l1.failed_evictions, 0u);
  for (int i = 0; i < 4; ++i) EXPECT_TRUE(cache.lookup(keys[size_t(i)], 0, false).resident());
  pinned.clear();
  BrickHandle now = cache.fetch(keys[5]);  // room again
  EXPECT_NE(now.slot(), kNoSlot);
}

TEST_F(BrickCacheTest, UploadsRespectThePerFrameBudget) {
  CacheConfig c = small_config(64, 64, store_->format().bytes());
  c.upload_pages_per_frame = 5;
  GridCache cache_pages(*store_, c);
  BrickCache& cache = cache_pages.bricks();
  const auto keys = finest_keys(*store_);
  cache.frame_begin();
  for (int i = 0; i < 20; ++i) cache.request(keys[size_t(i)], 1.0f);
  cache.wait_idle();
  EXPECT_EQ(cache.stats().uploads, 5u);
  for (int frame = 0; frame < 3; ++frame) {
    cache.frame_end();
    cache.frame_begin();
    EXPECT_EQ(cache.stats().uploads, uint64_t(5 * (frame + 2)));
  }
  for (int i = 0; i < 20; ++i) EXPECT_TRUE(cache.lookup(keys[size_t(i)], 0, false).resident());
}

TEST_F(BrickCacheTest, BricksWaitingForTheUploadBudgetHoldAtMostOneFramesBudgetBesideL2) {
  // 20 bricks decoded, 5 uploaded a frame, L2 of 4. The loader decodes ahead of the budget;
  // past one frame's budget a decoded brick waits only as L2's, so what waits beside L2 stays
  // within one budget (it was every brick loaded ahead: 1.67 GiB beside a 64 MiB L2 in the
  // soak). A brick L2 evicted while it waited is dropped, and the renewed request loads it.
  const size_t brick = store_->format().bytes();
  CacheConfig c = small_config(64, 4, brick);
  c.upload_pages_per_frame = 5;
  GridCache cache_pages(*store_, c);
  BrickCache& cache = cache_pages.bricks();
  const auto keys = finest_keys(*store_);
  constexpr int kBricks = 20;
  cache.frame_begin();
  for (int i = 0; i < kBricks; ++i) cache.request(keys[size_t(i)], 1.0f);
  cache.wait_idle();
  CacheStats s = cache.stats();
  EXPECT_EQ(s.uploads, 5u);
  EXPECT_LE(s.waiting_pages, uint64_t(kBricks - 5));
  EXPECT_LE(s.waiting_bytes_beside_l2, 5 * brick);
  EXPECT_LE(s.l2.resident, 4 * brick);
  cache.frame_end();
  std::vector<BrickRequest> asked;
  for (int i = 0; i < kBricks; ++i) asked.push_back({keys[size_t(i)], 1.0f});
  int frames = 0;
  for (bool all_resident = false; !all_resident && frames < 20; ++frames) {
    all_resident = ask_one_frame(cache, asked) == kBricks;
    EXPECT_LE(cache.stats().waiting_bytes_beside_l2, 5 * brick) << "frame " << frames;
  }
  EXPECT_LT(frames, 20) << "the bricks never all arrived";
  s = cache.stats();
  EXPECT_GT(s.expired_waiting_pages, 0u);  // L2 of 4 cannot keep 15 waiting
  EXPECT_EQ(s.uploads, uint64_t(kBricks));
}

TEST_F(BrickCacheTest, ABrickLoadedAndWaitingForTheUploadBudgetIsNotRequestedAgain) {
  // A renderer renews its requests every frame until the bricks are resident. One that is
  // decoded and waits for a later frame's upload budget is on its way: asking for it again
  // must not queue a second load (from L2), which would be read and dropped.
  CacheConfig c = small_config(64, 64, store_->format().bytes());
  c.upload_pages_per_frame = 4;
  GridCache cache_pages(*store_, c);
  BrickCache& cache = cache_pages.bricks();
  const auto keys = finest_keys(*store_);
  constexpr int kBricks = 16;
  std::vector<BrickRequest> asked;
  for (int i = 0; i < kBricks; ++i) asked.push_back({keys[size_t(i)], 1.0f});
  int frames = 0;
  for (bool all_resident = false; !all_resident && frames < 10; ++frames) all_resident = ask_one_frame(cache, asked) == kBricks;
  EXPECT_EQ(frames, kBricks / 4);  // a budget's worth a frame: the last frame sees them all
  const CacheStats s = cache.stats();
  EXPECT_EQ(s.requests, uint64_t(kBricks));
  EXPECT_EQ(s.l2.hits, 0u) << "a brick was loaded twice";
  EXPECT_EQ(s.uploads, uint64_t(kBricks));
}

TEST_F(BrickCacheTest, ABrickWithNoUnpinnedSlotDoesNotHoldBackTheOthers) {
  // Pins fill one shard of the pool: a brick of that shard cannot be placed until they go, but
  // the bricks of the other shards, queued behind it, are placed this frame all the same.
  CacheConfig c = small_config(64, 512, store_->format().bytes());
  c.loader_threads = 1;  // the loader serves by priority: the blocked brick first
  GridCache cache_pages(*store_, c);
  BrickCache& cache = cache_pages.bricks();
  const auto keys = finest_keys(*store_);
  std::vector<BrickHandle> pins;
  size_t next = 0;
  while (next < keys.size()) {
    BrickHandle h = cache.fetch(keys[next++]);
    if (h.slot() == kNoSlot) break;  // a private copy: this key's shard is all pinned
    pins.push_back(std::move(h));
  }
  ASSERT_LT(next + 8, keys.size());
  const BrickKey blocked = keys[next - 1];
  std::vector<BrickRequest> others, asked{{blocked, 10.0f}};
  for (size_t i = next; i < next + 8; ++i) others.push_back({keys[i], 1.0f});
  asked.insert(asked.end(), others.begin(), others.end());
  ask_one_frame(cache, asked);
  EXPECT_FALSE(cache.lookup(blocked, 0, false).resident());
  EXPECT_GT(resident_now(cache, others), 0) << "the blocked brick held back the queue behind it";
  const uint64_t requests = cache.stats().requests;
  ask_one_frame(cache, asked);  // asked again while blocked: merged, not loaded again
  EXPECT_FALSE(cache.lookup(blocked, 0, false).resident());
  EXPECT_EQ(cache.stats().requests, requests);
  pins.clear();
  cache.frame_begin();  // the blocked bricks now find slots
  EXPECT_TRUE(cache.lookup(blocked, 0, false).resident());
  for (size_t i = next; i < next + 8; ++i) EXPECT_TRUE(cache.lookup(keys[i], 0, false).resident()) << keys[i];
  EXPECT_EQ(cache.stats().l2.hits, 1u);  // the blocked brick, which its fetch() had decoded; no other
}

TEST_F(BrickCacheTest, WaitIdleReturnsOnlyOnceEveryBrickItWasAskedForIsResident) {
  // wait_idle() promises every queued brick placed in the pool (none is held back by an
  // upload budget here). A loader thread that has decoded a brick but not yet placed it must
  // keep it counted as in flight, or another thread's idle signal lets wait_idle() return
  // early. Many small batches on 4 loader threads, from L2 after the first pass (loads at
  // their shortest, so placing is the larger part), give that window many chances: a stress
  // test, which failed in most of 20 repetitions before the fix. A batch is at most one of the
  // pool's 4 shards of 16 slots, so under LRU it never pushes out a brick of its own.
  CacheConfig c = small_config(64, 1024, store_->format().bytes());
  c.loader_threads = 4;
  GridCache cache_pages(*store_, c);
  BrickCache& cache = cache_pages.bricks();
  const auto keys = finest_keys(*store_);
  constexpr size_t kBatch = 16;
  ASSERT_GT(keys.size(), kBatch + c.l1_slots);  // batches that come back after the pool has turned over
  int early = 0;
  for (size_t round = 0; round < 600; ++round) {
    const size_t first = round * kBatch % (keys.size() - kBatch);
    std::vector<BrickRequest> batch;
    for (size_t i = first; i < first + kBatch; ++i) batch.push_back({keys[i], 1.0f});
    ask_one_frame(cache, batch);
    early += int(kBatch) - resident_now(cache, batch);
  }
  EXPECT_EQ(early, 0) << "bricks not yet resident when wait_idle() returned";
  EXPECT_GT(cache.stats().l2.hits, 0u);  // the short loads from L2 were taken
}

TEST_F(BrickCacheTest, RequestsNotRenewedAreDroppedAtFrameEnd) {
  CacheConfig c = small_config(512, 512, store_->format().bytes());
  c.loader_threads = 1;
  GridCache cache_pages(*store_, c);
  BrickCache& cache = cache_pages.bricks();
  const auto keys = finest_keys(*store_);
  cache.frame_begin();
  for (const auto& k : keys) cache.request(k, 0);
  cache.frame_end();  // frame 1's requests are pending, renewed in frame 1
  cache.frame_begin();
  const FrameReport r = cache.frame_end();  // not renewed in frame 2: whatever is still queued goes
  cache.wait_idle();
  const CacheStats s = cache.stats();
  EXPECT_EQ(s.queue_length, 0u);
  EXPECT_EQ(r.dropped, s.dropped_requests);
  EXPECT_EQ(s.uploads + s.dropped_requests, keys.size());
}

TEST_F(BrickCacheTest, NeverExceedsItsBudgetsUnderConcurrentRandomLoad) {
  const size_t brick = store_->format().bytes();
  CacheConfig c = small_config(24, 40, brick);
  c.l2_policy = "s3fifo";
  c.l1_policy = "clock";
  GridCache cache_pages(*store_, c);
  BrickCache& cache = cache_pages.bricks();
  const auto keys = finest_keys(*store_);
  std::atomic<bool> done{false};
  std::atomic<uint64_t> checks{0};
  std::thread watcher([&] {
    while (!done) {
      const CacheStats s = cache.stats();
      EXPECT_LE(s.l1.resident, 24u);
      EXPECT_LE(s.l2.resident, 40 * brick);
      checks++;
    }
  });
  std::vector<std::thread> workers;
  for (int t = 0; t < 2; ++t)
    workers.emplace_back([&, t] {
      std::mt19937 rng{static_cast<uint32_t>(t)};
      for (int i = 0; i < 3000; ++i) {
        const BrickKey& k = keys[rng() % keys.size()];
        if (i % 3 == 0) {
          BrickHandle h = cache.fetch(k);
          EXPECT_TRUE(h.resident());
          EXPECT_EQ(h.bytes()[0], decoded(*store_, k)[0]);
        } else {
          BrickHandle h = cache.lookup(k, float(i));
          if (h.resident()) cache.mark_used(k);
        }
      }
    });
  for (int f = 0; f < 20; ++f) {
    cache.frame_begin();
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
    cache.frame_end();
  }
  for (auto& w : workers) w.join();
  cache.wait_idle();
  done = true;
  watcher.join();
  const CacheStats s = cache.stats();
  EXPECT_GT(checks.load(), 0u);
  EXPECT_LE(s.l2_peak_bytes, 40 * brick);
  EXPECT_LE(s.l1.resident, 24u);
  EXPECT_GT(s.l1.evictions, 0u);
  EXPECT_GT(s.l2.evictions, 0u);
}

TEST_F(BrickCacheTest, VisibilityMarksAppearAfterTheFrame) {
  GridCache cache_pages(*store_, small_config(8, 8, store_->format().bytes()));
  BrickCache& cache = cache_pages.bricks();
  const BrickKey k{1, 0, 1, 0};
  cache.frame_begin();
  cache.mark_visible(k, true);
  EXPECT_FALSE(cache.visibility(k).has_value());
  cache.frame_end();
  EXPECT_EQ(cache.visibility(k), std::optional<bool>(true));
  cache.frame_begin();
  cache.mark_visible(k, false);
  cache.frame_end();
  EXPECT_EQ(cache.visibility(k), std::optional<bool>(false));
}

TEST_F(BrickCacheTest, LruFrameProtectsBricksUsedThisFrame) {
  CacheConfig c = small_config(16, 64, store_->format().bytes());
  c.l1_policy = "lru-frame";
  GridCache cache_pages(*store_, c);
  BrickCache& cache = cache_pages.bricks();
  const auto keys = finest_keys(*store_);
  cache.frame_begin();
  for (int i = 0; i < 16; ++i) cache.fetch(keys[size_t(i)]);  // fill the pool in this frame
  BrickHandle h = cache.fetch(keys[16]);  // nothing evictable: every slot was used this frame
  EXPECT_EQ(h.slot(), kNoSlot);
  cache.frame_end();
  cache.frame_begin();
  cache.mark_used(keys[0]);
  BrickHandle next = cache.fetch(keys[17]);
  EXPECT_NE(next.slot(), kNoSlot);
  EXPECT_TRUE(cache.lookup(keys[0], 0, false).resident());   // used this frame: kept
  EXPECT_FALSE(cache.lookup(keys[1], 0, false).resident());  // the least recent of the rest
}

TEST_F(BrickCacheTest, KeysOutsideTheStoreAreClearErrors) {
  GridCache cache_pages(*store_, small_config(8, 8, store_->format().bytes()));
  BrickCache& cache = cache_pages.bricks();
  const BrickKey outside{9, 0, 0, 0};
  BrickHandle h = cache.lookup(outside);
  EXPECT_TRUE(h.failed());
  EXPECT_NE(h.error().find("outside the grid's"), std::string::npos) << h.error();
  try {
    cache.fetch(outside);
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), Errc::not_found);
    EXPECT_EQ(e.key(), outside.to_string());
  }
}

TEST_F(BrickCacheTest, BudgetsSmallerThanOneBrickAreConfigurationErrors) {
  CacheConfig c;
  c.l1_bytes = 100;
  try {
    PageCache cache(*store_, c);
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), Errc::invalid_argument);
    EXPECT_EQ(e.field(), "l1_bytes");
  }
  c = CacheConfig{};
  c.l2_bytes = 100;
  try {
    PageCache cache(*store_, c);
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.field(), "l2_bytes");
  }
  c = CacheConfig{};
  c.l1_policy = "opt";
  EXPECT_THROW(PageCache(*store_, c), Error);
}

TEST_F(BrickCacheTest, RecordsATraceOfEveryAccess) {
  testing::TempDir dir;
  const auto keys = finest_keys(*store_);
  {
    CacheConfig c = small_config(8, 16, store_->format().bytes());
    c.trace_path = dir.file("t.bytrace");
    GridCache cache_pages(*store_, c);
    BrickCache& cache = cache_pages.bricks();
    cache.frame_begin();
    cache.lookup(keys[0]);
    cache.wait_idle();
    cache.frame_end();
    cache.frame_begin();
    cache.lookup(keys[0]);
    cache.fetch(keys[1]);
    cache.frame_end();
  }
  const Trace t = read_trace(dir.file("t.bytrace"));
  std::vector<AccessKind> kinds;
  for (const auto& r : t.records) kinds.push_back(r.kind);
  EXPECT_EQ(kinds, (std::vector<AccessKind>{AccessKind::demand, AccessKind::prefetch_request, AccessKind::prefetch_fill,
                                            AccessKind::demand, AccessKind::blocking}));
  EXPECT_EQ(t.records[0].hit_level, 0);
  EXPECT_EQ(t.records[3].hit_level, 1);
  EXPECT_EQ(t.records[4].hit_level, 3);
  EXPECT_EQ(t.records[3].frame, 2u);
  EXPECT_EQ(t.records[0].key, keys[0].code());
}

class CorruptStoreTest : public ::testing::Test {};

TEST_F(CorruptStoreTest, ACorruptBrickFailsOnceAndOthersStillLoad) {
  testing::TempDir dir;
  BuildOptions o;
  o.brick_size = 8;
  auto src = make_field_source(make_field("fbm"), {32, 32, 32}, ValueType::u8);
  build_store(*src, dir.file("s"), o);
  // Damage one record inside LMDB's file.
  const std::string header = testing::corrupt_first_brick(dir.file("s/data.mdb"), 30, 16);
  ASSERT_EQ(header.size(), 28u);
  BrickHeader h{};
  std::memcpy(&h, header.data(), header.size());
  const BrickKey bad{h.level, h.x, h.y, h.z};

  Store store(dir.file("s"));
  CacheConfig c = small_config(64, 64, store.format().bytes());
  GridCache cache_pages(store, c);
  BrickCache& cache = cache_pages.bricks();
  cache.frame_begin();
  const BrickKey good = bad.x > 0 ? BrickKey{bad.level, bad.x - 1, bad.y, bad.z} : BrickKey{bad.level, bad.x + 1, bad.y, bad.z};
  cache.lookup(bad);
  cache.lookup(good);
  cache.wait_idle();
  BrickHandle hb = cache.lookup(bad);
  EXPECT_TRUE(hb.failed());
  EXPECT_NE(hb.error().find(bad.to_string()), std::string::npos) << hb.error();
  EXPECT_TRUE(cache.lookup(good).resident() || store.nodes().at(good).is_constant());
  const uint64_t reads = cache.stats().l3.hits;
  for (int i = 0; i < 10; ++i) cache.request(bad, 5);  // never retried
  cache.wait_idle();
  EXPECT_EQ(cache.stats().l3.hits, reads);
  EXPECT_EQ(cache.stats().failed_keys, 1u);
  try {
    cache.fetch(bad);
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), Errc::corrupt);
  }
}

}  // namespace
}  // namespace brickyard
