// The page cache over records of several kinds: each kind its own pages, pools and budgets, one
// loader, one trace; a fake source whose pages say which (kind, id) they are.

#include <gtest/gtest.h>

#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <set>
#include <thread>

#include "cache/page_cache.h"
#include "cache/replay.h"
#include "cache/trace.h"
#include "core/error.h"
#include "test_util.h"

namespace brickyard {
namespace {

/// Two kinds: 64-byte bricks (ids 0..99) and 256-byte octree pages (ids 0..49, id 13 corrupt).
/// A page's bytes are its kind's number, then its id, then a repeating id pattern.
class FakeSource final : public PageSource {
 public:
  const std::string& source_name() const override { return name_; }
  std::vector<PageKindInfo> page_kinds() const override {
    return {{RecordKind::brick, 64, 100}, {RecordKind::octree_page, 256, 50}};
  }
  std::unique_ptr<PageReader> open_reader() const override { return std::make_unique<Reader>(*this); }
  static uint8_t pattern(const PageKey& k, size_t i) { return uint8_t(uint8_t(k.kind) * 101 + k.id * 7 + i); }
  mutable std::atomic<int> reads{0};

 private:
  struct Reader final : PageReader {
    explicit Reader(const FakeSource& s) : source(s) {}
    PageRead read(const PageKey& key, std::span<std::byte> out) override {
      const uint64_t records = key.kind == RecordKind::brick ? 100 : 50;
      if (key.id >= records) throw Error(Errc::not_found, "no such page").with_key(to_string(key));
      if (key.kind == RecordKind::octree_page && key.id == 13) throw Error(Errc::corrupt, "checksum mismatch").with_key(to_string(key));
      ++source.reads;
      for (size_t i = 0; i < out.size(); ++i) out[i] = std::byte(pattern(key, i));
      return {out.size() / 2, 1000};
    }
    const FakeSource& source;
  };
  std::string name_ = "fake-source";
};

bool holds_page(const PageHandle& h, const PageKey& k, size_t bytes) {
  for (size_t i = 0; i < bytes; ++i)
    if (h.bytes()[i] != std::byte(FakeSource::pattern(k, i))) return false;
  return true;
}

CacheConfig two_kinds() {
  CacheConfig c;
  c.l1_bytes = 64 * 20;  // bricks: 20 slots
  c.l2_bytes = 64 * 40;
  c.kinds[RecordKind::octree_page] = {3, 0, 256 * 4};  // 3 slots, 4 pages of L2
  return c;
}

TEST(PageCache, TheSameIdOfTwoKindsIsTwoPagesOfTheirOwnSize) {
  FakeSource source;
  PageCache cache(source, two_kinds());
  EXPECT_EQ(cache.kinds(), (std::vector<RecordKind>{RecordKind::brick, RecordKind::octree_page}));
  EXPECT_FALSE(cache.holds(RecordKind::tet_cluster));
  EXPECT_EQ(cache.page_bytes(RecordKind::brick), 64u);
  EXPECT_EQ(cache.page_bytes(RecordKind::octree_page), 256u);
  EXPECT_EQ(cache.pool_slots(RecordKind::brick), 20u);
  EXPECT_EQ(cache.pool_slots(RecordKind::octree_page), 3u);
  const PageKey brick{RecordKind::brick, 5}, page{RecordKind::octree_page, 5};
  const PageHandle a = cache.fetch(brick), b = cache.fetch(page);
  EXPECT_TRUE(holds_page(a, brick, 64));
  EXPECT_TRUE(holds_page(b, page, 256));
  EXPECT_EQ(cache.stats(RecordKind::brick).l3.hits, 1u);
  EXPECT_EQ(cache.stats(RecordKind::octree_page).l3.hits, 1u);
  EXPECT_EQ(cache.stats(RecordKind::octree_page).l3_bytes_read, 128u);
  const CacheStats total = cache.stats();
  EXPECT_EQ(total.l3.hits, 2u);
  EXPECT_EQ(total.l1_pool_bytes, 20u * 64 + 3u * 256);
  ASSERT_EQ(total.kinds.size(), 2u);  // a source of two kinds reports each
  EXPECT_NE(total.to_json().find("\"octree_page\""), std::string::npos);
}

TEST(PageCache, KindsWithoutTheirOwnBudgetShareTheCachesEqually) {
  FakeSource source;
  CacheConfig c;
  c.l1_bytes = 64 * 64;
  c.l2_bytes = 1 << 20;
  PageCache cache(source, c);
  EXPECT_EQ(cache.pool_slots(RecordKind::brick), 32u);        // half of the L1 bytes
  EXPECT_EQ(cache.pool_slots(RecordKind::octree_page), 8u);   // the other half, in 256-byte pages
  EXPECT_EQ(cache.stats().l2.capacity, uint64_t(1 << 20));
}

TEST(PageCache, PagesOfEveryKindLoadAsynchronouslyWithinTheirOwnPools) {
  FakeSource source;
  testing::TempDir dir;
  CacheConfig c = two_kinds();
  c.trace_path = dir.file("mixed.bytrace");
  {
    PageCache cache(source, c);
    cache.frame_begin();
    for (uint64_t id = 0; id < 6; ++id) {
      EXPECT_FALSE(cache.lookup({RecordKind::brick, id}).resident());
      EXPECT_FALSE(cache.lookup({RecordKind::octree_page, id}).resident());
    }
    const FrameReport report = cache.frame_end();
    EXPECT_EQ(report.requests, 12u);
    cache.wait_idle();
    cache.frame_begin();
    for (uint64_t id = 0; id < 6; ++id) EXPECT_TRUE(holds_page(cache.lookup({RecordKind::brick, id}), {RecordKind::brick, id}, 64));
    int pages = 0;  // three octree slots for six pages: the pool holds three of them
    for (uint64_t id = 0; id < 6; ++id) pages += cache.lookup({RecordKind::octree_page, id}, 0, false).resident();
    EXPECT_EQ(pages, 3);
    EXPECT_EQ(cache.stats(RecordKind::octree_page).l1.resident, 3u);
    EXPECT_LE(cache.stats(RecordKind::octree_page).l2_peak_bytes, 256u * 4);
    cache.frame_end();
  }
  // The trace says which kind every access was; replayed, a brick and a page of one id are two
  // objects, and a cache of both kinds' working set misses each once.
  const Trace t = read_trace(dir.file("mixed.bytrace"));
  EXPECT_EQ(t.record_kinds(), (std::vector<RecordKind>{RecordKind::brick, RecordKind::octree_page}));
  EXPECT_EQ(t.unique_objects(), 12u);
  EXPECT_EQ(t.unique_bytes(), 6u * 64 + 6u * 256);
  const ReplayResult all = replay(t, next_demand_access(t), "lru", t.unique_bytes());
  EXPECT_EQ(all.misses, 12u);
  const Trace pages_only = t.of_kind(RecordKind::octree_page);
  EXPECT_EQ(pages_only.unique_objects(), 6u);
  EXPECT_EQ(replay(pages_only, {}, "lru", pages_only.unique_bytes()).misses, 6u);
}

TEST(PageCache, ACorruptPageFailsOnceAndNamesItsKindAndSource) {
  FakeSource source;
  PageCache cache(source, two_kinds());
  const PageKey bad{RecordKind::octree_page, 13};
  cache.frame_begin();
  cache.lookup(bad);
  cache.frame_end();
  cache.wait_idle();
  const PageHandle h = cache.lookup(bad);
  ASSERT_TRUE(h.failed());
  EXPECT_NE(h.error().find("fake-source"), std::string::npos) << h.error();
  EXPECT_NE(h.error().find("octree_page 0xd"), std::string::npos) << h.error();
  const int reads = source.reads.load();
  cache.request(bad, 9);
  cache.wait_idle();
  EXPECT_EQ(source.reads.load(), reads);  // never retried
  EXPECT_EQ(cache.stats(RecordKind::octree_page).failed_keys, 1u);
  EXPECT_EQ(cache.stats(RecordKind::brick).failed_keys, 0u);
  EXPECT_TRUE(holds_page(cache.fetch({RecordKind::brick, 13}), {RecordKind::brick, 13}, 64));  // the same id, another kind
}

TEST(PageCache, AKindTheSourceLacksIsRefusedByName) {
  FakeSource source;
  PageCache cache(source, two_kinds());
  const PageHandle h = cache.lookup({RecordKind::tet_cluster, 1});
  EXPECT_TRUE(h.failed());
  EXPECT_NE(h.error().find("holds no tet_cluster pages"), std::string::npos) << h.error();
  try {
    cache.fetch({RecordKind::tet_cluster, 1});
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), Errc::not_found);
    EXPECT_EQ(e.file(), "fake-source");
  }
  cache.request({RecordKind::tet_cluster, 1}, 1);  // nothing to ask for: ignored
  cache.wait_idle();
  EXPECT_EQ(cache.stats().requests, 0u);
}

TEST(PageCache, BudgetsSmallerThanOnePageOfAKindNameTheKind) {
  FakeSource source;
  CacheConfig c = two_kinds();
  c.kinds[RecordKind::octree_page] = {0, 100, 256};
  try {
    PageCache cache(source, c);
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.field(), "l1_bytes");
    EXPECT_NE(e.message().find("one octree_page"), std::string::npos) << e.what();
  }
}

TEST(PageCache, FeedbackAndPrioritiesServeEveryKind) {
  FakeSource source;
  PageCache cache(source, two_kinds());
  const PageKey page{RecordKind::octree_page, 3}, brick{RecordKind::brick, 3};
  cache.frame_begin();
  cache.mark_visible(page, false);
  cache.mark_visible(brick, true);
  cache.request(page, 1);
  cache.request({RecordKind::octree_page, 4}, 9);
  cache.request(brick, 5);
  EXPECT_EQ(cache.visibility(page), std::nullopt);  // readable once the frame has ended
  cache.frame_end();
  EXPECT_EQ(cache.visibility(page), std::optional<bool>(false));
  EXPECT_EQ(cache.visibility(brick), std::optional<bool>(true));
  // The frame's requests, merged, highest priority first, each with its kind.
  const std::vector<PageRequest> asked = cache.frame_requests();
  ASSERT_EQ(asked.size(), 3u);
  EXPECT_EQ(asked[0].key, (PageKey{RecordKind::octree_page, 4}));
  EXPECT_EQ(asked[1].key, brick);
  EXPECT_EQ(asked[2].key, page);
  cache.wait_idle();
  EXPECT_TRUE(cache.resident(page));
  EXPECT_TRUE(cache.resident(brick));
}

TEST(PageCache, UsageFeedbackProtectsAPageOfAnyKindUnderLruFrame) {
  FakeSource source;
  CacheConfig c = two_kinds();
  c.l1_policy = "lru-frame";
  PageCache cache(source, c);  // three octree slots
  for (uint64_t id = 0; id < 3; ++id) (void)cache.fetch({RecordKind::octree_page, id});
  cache.frame_begin();
  for (uint64_t id = 0; id < 3; ++id) cache.mark_used({RecordKind::octree_page, id});  // all used this frame
  cache.frame_end();
  // Every slot is protected by this frame's use: a new page cannot evict one, so the blocking
  // fetch hands back a private copy and every page used stays.
  const PageHandle extra = cache.fetch({RecordKind::octree_page, 7});
  EXPECT_TRUE(holds_page(extra, {RecordKind::octree_page, 7}, 256));
  EXPECT_EQ(extra.slot(), kNoSlot);
  for (uint64_t id = 0; id < 3; ++id) EXPECT_TRUE(cache.resident({RecordKind::octree_page, id})) << id;
  EXPECT_GT(cache.stats(RecordKind::octree_page).l1.failed_evictions, 0u);
}

/// A source whose reads take a while (so that requests are still queued and being read when
/// the cache is destroyed), counting the readers open and the reads begun and ended.
class SlowSource final : public PageSource {
 public:
  const std::string& source_name() const override { return name_; }
  std::vector<PageKindInfo> page_kinds() const override { return {{RecordKind::brick, 64, 4000}}; }
  std::unique_ptr<PageReader> open_reader() const override {
    ++readers_open;
    return std::make_unique<Reader>(*this);
  }
  mutable std::atomic<int> readers_open{0}, reads_begun{0}, reads_ended{0};

 private:
  struct Reader final : PageReader {
    explicit Reader(const SlowSource& s) : source(s) {}
    ~Reader() override { --source.readers_open; }
    PageRead read(const PageKey& key, std::span<std::byte> out) override {
      ++source.reads_begun;
      std::this_thread::sleep_for(std::chrono::microseconds(300));
      for (size_t i = 0; i < out.size(); ++i) out[i] = std::byte(FakeSource::pattern(key, i));
      ++source.reads_ended;
      return {out.size(), 0};
    }
    const SlowSource& source;
  };
  std::string name_ = "slow-source";
};

TEST(PageCache, ShutdownWithRequestsInFlightIsClean) {
  testing::TempDir dir;
  for (int round = 0; round < 5; ++round) {
    SlowSource source;
    const std::string trace = dir.file("shutdown" + std::to_string(round) + ".bytrace");
    CacheStats last;
    {
      CacheConfig c;
      c.l1_slots = 32;
      c.l2_bytes = 64 * 32;
      c.loader_threads = 3;
      c.upload_pages_per_frame = 3;
      c.trace_path = trace;
      PageCache cache(source, c);
      cache.frame_begin();
      for (uint64_t id = 0; id < 4000; ++id) cache.request({RecordKind::brick, id}, float(id % 7));
      cache.frame_end();
      // The loader well under way (draining everything would take it over a second).
      for (int wait = 0; wait < 5000 && source.reads_ended.load() < 6; ++wait) std::this_thread::sleep_for(std::chrono::milliseconds(1));
      last = cache.stats();
      // Counters agree with each other while it runs: the pool holds what was uploaded and not
      // evicted, never more than its slots.
      EXPECT_EQ(last.l1.resident, last.l1.inserts - last.l1.evictions);
      EXPECT_LE(last.l1.resident, 32u);
      EXPECT_LE(last.uploads, 3u + 3u);  // this frame's budget, and at most one per drain under way
      // Destroyed now, with requests queued, reads under way and decoded pages waiting for the
      // budget.
    }
    // Every loader thread ended and let its reader go; no read was left half done; and far from
    // everything was read: the queue was dropped, not drained.
    EXPECT_EQ(source.readers_open.load(), 0);
    EXPECT_EQ(source.reads_begun.load(), source.reads_ended.load());
    EXPECT_GE(source.reads_ended.load(), 6);
    EXPECT_LT(source.reads_ended.load(), 4000);
    // What the trace says was placed (written as the cache closed): each page once, each one
    // asked for, no more than the budget let through, and all of them within the pool's slots.
    const Trace t = read_trace(trace);
    std::set<uint64_t> asked, placed;
    for (const TraceRecord& r : t.records) {
      if (r.kind == AccessKind::prefetch_request) asked.insert(r.key);
      if (r.kind != AccessKind::prefetch_fill) continue;
      EXPECT_TRUE(asked.count(r.key)) << r.key;
      EXPECT_TRUE(placed.insert(r.key).second) << "placed twice: " << r.key;
    }
    EXPECT_EQ(asked.size(), 4000u);
    EXPECT_LE(placed.size(), 32u);
    EXPECT_GE(placed.size(), last.uploads);
  }
}

TEST(PageCache, ATracePathThatCannotBeWrittenIsRefusedWhenTheCacheIsMade) {
  FakeSource source;
  testing::TempDir dir;
  std::ofstream(dir.file("file")) << "x";
  CacheConfig c = two_kinds();
  // A missing directory, a directory that is a file, a path that is a directory: each would
  // fail only when the trace is written, after all the work.
  for (const std::string& bad : {dir.file("missing/t.bytrace"), dir.file("file/t.bytrace"), dir.path().string()}) {
    c.trace_path = bad;
    try {
      PageCache cache(source, c);
      ADD_FAILURE() << "accepted the trace path " << bad;
    } catch (const Error& e) {
      EXPECT_EQ(e.file(), bad) << e.what();
    }
  }
  EXPECT_FALSE(std::filesystem::exists(dir.file("missing")));
  // A good path: checked without leaving anything behind, written by close().
  c.trace_path = dir.file("t.bytrace");
  PageCache cache(source, c);
  EXPECT_FALSE(std::filesystem::exists(dir.file("t.bytrace.partial")));
  EXPECT_FALSE(std::filesystem::exists(dir.file("t.bytrace")));
  cache.fetch({RecordKind::brick, 3});
  cache.close();
  EXPECT_EQ(read_trace(dir.file("t.bytrace")).records.size(), 1u);
}

TEST(PageCache, CloseThrowsWhenTheTraceCannotBeWritten) {
  FakeSource source;
  testing::TempDir dir;
  const std::string sub = dir.file("gone");
  std::filesystem::create_directory(sub);
  CacheConfig c = two_kinds();
  c.trace_path = sub + "/t.bytrace";
  PageCache cache(source, c);
  cache.frame_begin();
  EXPECT_FALSE(cache.lookup({RecordKind::brick, 1}).resident());
  cache.frame_end();
  cache.wait_idle();
  std::filesystem::remove_all(sub);  // after the check at construction
  try {
    cache.close();
    ADD_FAILURE() << "close() reported no error for a trace it could not write";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), Errc::io);
    EXPECT_EQ(e.file(), c.trace_path) << e.what();
  }
  // Reported once: a second close() and the destructor do not try again.
  EXPECT_NO_THROW(cache.close());
  cache.wait_idle();  // closed: returns at once
  EXPECT_EQ(cache.stats(RecordKind::brick).l3.hits, 1u);
  EXPECT_FALSE(std::filesystem::exists(sub));
}

TEST(Trace, RecordKindsSurviveEveryFormat) {
  testing::TempDir dir;
  Trace t;
  t.records = {{7, 0, 64, AccessKind::demand, 0, 0, RecordKind::brick},
               {7, 0, 256, AccessKind::demand, 0, 0, RecordKind::octree_page},
               {9, 1, 4096, AccessKind::blocking, 3, 1, RecordKind::tet_cluster},
               {7, 1, 64, AccessKind::demand, 1, 0, RecordKind::brick}};
  write_trace(dir.file("t.bytrace"), t, TraceFormat::brickyard);
  const Trace b = read_trace(dir.file("t.bytrace"));
  ASSERT_EQ(b.records.size(), 4u);
  for (size_t i = 0; i < 4; ++i) {
    EXPECT_EQ(b.records[i].record, t.records[i].record);
    EXPECT_EQ(b.records[i].key, t.records[i].key);
  }
  write_trace(dir.file("t.txt"), t, TraceFormat::text);
  EXPECT_EQ(testing::read_file(dir.file("t.txt")), "7 64\n7 256 octree_page\n9 4096 tet_cluster\n7 64\n");
  const Trace x = read_trace(dir.file("t.txt"));
  EXPECT_EQ(x.records[1].record, RecordKind::octree_page);
  EXPECT_EQ(x.unique_objects(), 3u);
  // oracleGeneral has no kinds: a mixed trace becomes dense object ids, one per (kind, key).
  write_trace(dir.file("t.oracleGeneral"), t, TraceFormat::oracle_general);
  const Trace o = read_trace(dir.file("t.oracleGeneral"));
  std::vector<uint64_t> ids;
  for (const auto& r : o.records) ids.push_back(r.key);
  EXPECT_EQ(ids, (std::vector<uint64_t>{0, 1, 2, 0}));
  EXPECT_EQ(object_ids(t), ids);
  EXPECT_EQ(next_demand_access(t), (std::vector<uint64_t>{3, kNoNextAccess, kNoNextAccess, kNoNextAccess}));
}

}  // namespace
}  // namespace brickyard
