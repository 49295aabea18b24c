// The `gigavoxels` feedback buffers: what a 2x2 packet of rays records (spatial pattern), which
// part of a long list a frame keeps (temporal window), and the compaction the loader reads,
// checked against a brute-force statement of its rule on random coherent images. The loader's
// guarantee is checked by a small frame loop: a request a frame could not keep is made again
// and served later.

#include <gtest/gtest.h>

#include <tbb/task_arena.h>

#include <algorithm>
#include <cstdint>
#include <map>
#include <random>
#include <set>
#include <vector>

#include "core/error.h"
#include "core/parallel.h"
#include "renderers/gigavoxels/feedback.h"

namespace brickyard::gigavoxels {
namespace {

using List = std::vector<uint32_t>;

/// One ray's whole traversal: the nodes it used front to back and the requests it made.
struct Ray {
  List uses;
  List requests;
};

void record(UseBuffer& buffer, int x, int y, const Ray& ray) {
  RayRecorder rec = buffer.recorder(x, y);
  for (uint32_t e : ray.uses) rec.used(e);
  for (uint32_t e : ray.requests) rec.request(e);
  rec.finish();
}

List iota_list(uint32_t first, size_t n) {
  List l(n);
  for (size_t i = 0; i < n; ++i) l[i] = first + uint32_t(i);
  return l;
}

List span_to_list(std::span<const uint32_t> s) { return List(s.begin(), s.end()); }

List non_empty(std::span<const uint32_t> s) {
  List l;
  for (uint32_t v : s)
    if (v != kNoEntry) l.push_back(v);
  return l;
}

// --- recording ----------------------------------------------------------------------

TEST(UseBuffer, PacketRecordsASharedListCompletelyEachRankItsQuarterInOrder) {
  for (int k : {1, 2, 3, 4, 16}) {
    SCOPED_TRACE(k);
    UseBuffer buffer(2, 2, k);
    buffer.begin_frame(7);
    const List list = iota_list(100, size_t(4 * k));
    for (int y = 0; y < 2; ++y)
      for (int x = 0; x < 2; ++x) record(buffer, x, y, {list, {}});
    EXPECT_EQ(span_to_list(buffer.use_slots(0)), list);
    // Rank 1 is pixel (1, 0): it holds the second quarter.
    EXPECT_EQ(span_to_list(buffer.use_slots(0).subspan(size_t(k), size_t(k))),
              List(list.begin() + k, list.begin() + 2 * k));
    EXPECT_EQ(span_to_list(buffer.request_slots(0)), List(4, kNoEntry));
  }
}

TEST(UseBuffer, OnlyItsOwnPixelsRayWritesItsSlots) {
  UseBuffer buffer(4, 2, 4);
  buffer.begin_frame(0);
  record(buffer, 3, 1, {iota_list(1, 16), {99}});  // packet 1, rank 3: entries 12..15
  EXPECT_EQ(non_empty(buffer.use_slots(0)), List{});
  EXPECT_EQ(span_to_list(buffer.use_slots(1)),
            List({kNoEntry, kNoEntry, kNoEntry, kNoEntry, kNoEntry, kNoEntry, kNoEntry, kNoEntry, kNoEntry, kNoEntry,
                  kNoEntry, kNoEntry, 13, 14, 15, 16}));
  EXPECT_EQ(span_to_list(buffer.request_slots(1)), List({kNoEntry, kNoEntry, kNoEntry, 99}));
  // begin_frame empties everything again.
  buffer.begin_frame(1);
  EXPECT_EQ(non_empty(buffer.entries()), List{});
}

TEST(RayRecorder, DropsImmediateRepeatsAndKeepsOnlyTheFirstRequest) {
  UseBuffer buffer(1, 1, 4);
  buffer.begin_frame(0);
  RayRecorder rec = buffer.recorder(0, 0);
  for (uint32_t e : {5u, 5u, 5u, 6u, kNoEntry, 6u, 5u, 7u, 7u}) rec.used(e);
  rec.request(40);
  rec.request(41);
  rec.request(40);
  EXPECT_EQ(rec.length(), 4u);
  EXPECT_EQ(rec.dropped_requests(), 2u);
  rec.finish();
  EXPECT_EQ(span_to_list(buffer.use_slots(0).first(4)), List({5, 6, 5, 7}));
  EXPECT_EQ(buffer.request_slots(0)[0], 40u);
  // A second finish() changes nothing, even after more uses.
  rec.used(8);
  rec.finish();
  EXPECT_EQ(span_to_list(buffer.use_slots(0).first(4)), List({5, 6, 5, 7}));
}

TEST(RayRecorder, UnfinishedRayLeavesItsSlotsEmpty) {
  UseBuffer buffer(2, 2, 2);
  buffer.begin_frame(0);
  {
    RayRecorder rec = buffer.recorder(1, 1);
    rec.used(3);
    rec.request(4);
  }
  EXPECT_EQ(non_empty(buffer.entries()), List{});
}

TEST(RayRecorder, ShortListIsKeptCompletelyEveryFrame) {
  UseBuffer buffer(2, 2, 4);
  for (const size_t length : {size_t(1), size_t(9), size_t(16)})
    for (uint64_t frame = 0; frame < 5; ++frame) {
      SCOPED_TRACE(testing::Message() << "L " << length << " frame " << frame);
      buffer.begin_frame(frame);
      const List list = iota_list(1000, length);
      for (int y = 0; y < 2; ++y)
        for (int x = 0; x < 2; ++x) record(buffer, x, y, {list, {}});
      EXPECT_EQ(non_empty(buffer.use_slots(0)), list);
    }
}

/// Sequence indices of rank r's share of a list of length L with K slots per pixel.
std::set<uint32_t> share_of(const List& list, uint32_t rank, uint32_t k) {
  std::set<uint32_t> share;
  for (size_t i = 0; i < list.size(); ++i)
    if (i % (4 * k) / k == rank) share.insert(list[i]);
  return share;
}

TEST(RayRecorder, TemporalWindowKeepsEveryPartOfALongListWithinItsWindowCount) {
  // Lengths across window boundaries, and long enough to spill past the inline buffer.
  for (const uint32_t k : {1u, 4u, 16u})
    for (const size_t length : {size_t(4 * k + 1), size_t(8 * k), size_t(8 * k + 3), size_t(300), size_t(2000)}) {
      SCOPED_TRACE(testing::Message() << "K " << k << " L " << length);
      const List list = iota_list(1, length);
      const uint64_t windows = (length + 4 * k - 1) / (4 * k);
      UseBuffer buffer(2, 2, int(k));
      for (uint32_t rank = 0; rank < 4; ++rank) {
        const int x = int(rank & 1), y = int(rank >> 1);
        std::set<uint32_t> seen;
        for (uint64_t frame = 11; frame < 11 + windows; ++frame) {
          buffer.begin_frame(frame);
          RayRecorder rec = buffer.recorder(x, y);
          for (uint32_t e : list) rec.used(e);
          EXPECT_EQ(rec.window(), frame % windows);
          rec.finish();
          // Each frame keeps consecutive entries of the list, in order, at most K of them.
          const List kept = non_empty(buffer.use_slots(0).subspan(rank * k, k));
          ASSERT_LE(kept.size(), size_t(k));
          for (size_t i = 1; i < kept.size(); ++i) EXPECT_EQ(kept[i], kept[i - 1] + 1);
          seen.insert(kept.begin(), kept.end());
        }
        EXPECT_EQ(seen, share_of(list, rank, k)) << "rank " << rank;
      }
    }
}

TEST(RayRecorder, PacketCoversALongListWithinItsWindowCount) {
  UseBuffer buffer(2, 2, 4);
  const List list = iota_list(50, 70);  // 5 windows of 16
  std::set<uint32_t> seen;
  for (uint64_t frame = 0; frame < 5; ++frame) {
    buffer.begin_frame(frame);
    for (int y = 0; y < 2; ++y)
      for (int x = 0; x < 2; ++x) record(buffer, x, y, {list, {}});
    for (uint32_t v : non_empty(buffer.use_slots(0))) seen.insert(v);
  }
  EXPECT_EQ(seen, std::set<uint32_t>(list.begin(), list.end()));
}

TEST(RayRecorder, MovedRecorderRecordsTheSame) {
  for (const size_t split : {size_t(3), size_t(100), size_t(400)}) {  // inline and spilled when moved
    const List list = iota_list(1, 500);
    UseBuffer direct(2, 2, 4), moved(2, 2, 4);
    direct.begin_frame(9);
    moved.begin_frame(9);
    record(direct, 1, 0, {list, {7}});
    RayRecorder first = moved.recorder(1, 0);
    for (size_t i = 0; i < split; ++i) first.used(list[i]);
    first.request(7);
    RayRecorder second(std::move(first));
    for (size_t i = split; i < list.size(); ++i) second.used(list[i]);
    second.finish();
    first.finish();  // moved-from: writes nothing
    EXPECT_EQ(span_to_list(moved.entries()), span_to_list(direct.entries())) << "split " << split;
  }
}

TEST(UseBuffer, PartialPacketsAtOddSizesWork) {
  UseBuffer buffer(5, 3, 2);
  EXPECT_EQ(buffer.packets_x(), 3);
  EXPECT_EQ(buffer.packets_y(), 2);
  buffer.begin_frame(0);
  for (int y = 0; y < 3; ++y)
    for (int x = 0; x < 5; ++x) {
      const uint32_t id = uint32_t(y * 5 + x);
      record(buffer, x, y, {iota_list(100 * id, 8), {id}});  // 4K entries: every rank has a share
    }
  for (int y = 0; y < 3; ++y)
    for (int x = 0; x < 5; ++x) {
      const size_t p = buffer.packet_of(x, y);
      const uint32_t r = UseBuffer::rank_of(x, y);
      const uint32_t id = uint32_t(y * 5 + x);
      EXPECT_EQ(span_to_list(buffer.use_slots(p).subspan(2 * r, 2)), List({100 * id + 2 * r, 100 * id + 2 * r + 1}));
      EXPECT_EQ(buffer.request_slots(p)[r], id);
    }
  // The missing rays of edge packets leave their slots empty: 15 pixels of 24 slots' worth.
  EXPECT_EQ(non_empty(buffer.entries()).size(), size_t(15 * 3));
  std::vector<uint32_t> uses, requests;
  const CompactionReport report = Compactor().compact(buffer, uses, requests);
  EXPECT_EQ(uses.size(), size_t(30));
  EXPECT_EQ(requests.size(), size_t(15));
  EXPECT_EQ(report.uses.slots, uint64_t(6 * 8));
  EXPECT_EQ(report.requests.slots, uint64_t(6 * 4));
}

TEST(UseBuffer, RejectsBadSizes) {
  EXPECT_THROW(UseBuffer(4, 4, 0), Error);
  EXPECT_THROW(UseBuffer(4, 4, kMaxSlotsPerPixel + 1), Error);
  EXPECT_THROW(UseBuffer(-1, 4, 4), Error);
  UseBuffer empty(0, 0, 4);
  empty.begin_frame(3);
  std::vector<uint32_t> uses{1}, requests{2};
  const CompactionReport report = Compactor().compact(empty, uses, requests);
  EXPECT_TRUE(uses.empty());
  EXPECT_TRUE(requests.empty());
  EXPECT_EQ(report.uses.slots, 0u);
}

// --- compaction -----------------------------------------------------------------------

/// A coherent random image: each ray descends a shared coarse path (regions of 8x8 pixels share
/// nodes) and then crosses fine nodes shared by 2x2 or 3x3 pixel neighbourhoods, sometimes
/// repeating a node; some rays make one or more requests drawn from a small set.
std::vector<Ray> random_rays(int w, int h, uint32_t seed) {
  std::mt19937 rng(seed);
  std::vector<Ray> rays(size_t(w) * size_t(h));
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      Ray& ray = rays[size_t(y) * size_t(w) + size_t(x)];
      ray.uses.push_back(1);  // the root
      ray.uses.push_back(uint32_t(100 + (x / 8) * 37 + (y / 8)));
      const int cell = 2 + int(rng() % 2);
      const uint32_t fine = uint32_t(10000 + (x / cell) * 1000 + (y / cell) * 10);
      const int n = int(rng() % 30);
      for (int i = 0; i < n; ++i) {
        ray.uses.push_back(fine + uint32_t(i));
        if (rng() % 5 == 0) ray.uses.push_back(fine + uint32_t(i));  // a consecutive repeat
      }
      const int requests = rng() % 3 == 0 ? 1 + int(rng() % 3) : 0;
      for (int i = 0; i < requests; ++i) ray.requests.push_back(uint32_t(500000 + rng() % 40));
    }
  return rays;
}

void record_all(UseBuffer& buffer, const std::vector<Ray>& rays) {
  const int w = buffer.width();
  parallel_for<int>(0, buffer.height(), 1, [&](int y0, int y1) {
    for (int y = y0; y < y1; ++y)
      for (int x = 0; x < w; ++x) record(buffer, x, y, rays[size_t(y) * size_t(w) + size_t(x)]);
  });
}

/// The compaction rule, stated slot by slot, over one stream (offset and count of its slots in
/// each block).
List brute_force(const UseBuffer& buffer, size_t offset, size_t count) {
  List out;
  const size_t px = size_t(buffer.packets_x());
  auto block = [&](size_t p) { return buffer.entries().subspan(p * buffer.block_stride() + offset, count); };
  auto holds = [](std::span<const uint32_t> s, uint32_t v) { return std::find(s.begin(), s.end(), v) != s.end(); };
  for (size_t p = 0; p < buffer.packet_count(); ++p)
    for (size_t i = 0; i < count; ++i) {
      const uint32_t v = block(p)[i];
      if (v == kNoEntry || holds(block(p).first(i), v)) continue;
      if (p % px != 0 && holds(block(p - 1), v)) continue;
      if (p >= px && holds(block(p - px), v)) continue;
      out.push_back(v);
    }
  return out;
}

void expect_adds_up(const CompactionStats& s) { EXPECT_EQ(s.slots, s.empty + s.local_duplicates + s.out); }

TEST(Compactor, KeepsEveryBufferedEntryAndEveryRequestAndRemovesLocalDuplicates) {
  Compactor compactor;  // reused across images, as across frames
  for (uint32_t seed = 0; seed < 12; ++seed) {
    const int w = 1 + int(seed * 7 % 41), h = 1 + int(seed * 13 % 37);  // 1x1 to 41x37, odd and even
    const int k = 1 + int(seed % 5);
    SCOPED_TRACE(testing::Message() << w << "x" << h << " K " << k);
    const std::vector<Ray> rays = random_rays(w, h, seed);
    UseBuffer buffer(w, h, k);
    buffer.begin_frame(seed);
    record_all(buffer, rays);
    std::vector<uint32_t> uses, requests;
    const CompactionReport report = compactor.compact(buffer, uses, requests);

    // Every request a ray kept (its first) is in the output, and nothing else is.
    std::set<uint32_t> first_requests;
    for (const Ray& ray : rays)
      if (!ray.requests.empty()) first_requests.insert(ray.requests.front());
    EXPECT_EQ(std::set<uint32_t>(requests.begin(), requests.end()), first_requests);
    // Every used entry the buffer held is in the output, and nothing else is.
    std::set<uint32_t> buffered_uses;
    for (size_t p = 0; p < buffer.packet_count(); ++p)
      for (uint32_t v : non_empty(buffer.use_slots(p))) buffered_uses.insert(v);
    EXPECT_EQ(std::set<uint32_t>(uses.begin(), uses.end()), buffered_uses);
    EXPECT_EQ(std::count(uses.begin(), uses.end(), kNoEntry), 0);
    EXPECT_EQ(std::count(requests.begin(), requests.end(), kNoEntry), 0);
    // Exactly the local duplicates are gone, in buffer order.
    EXPECT_EQ(uses, brute_force(buffer, 0, size_t(4 * k)));
    EXPECT_EQ(requests, brute_force(buffer, size_t(4 * k), 4));
    expect_adds_up(report.uses);
    expect_adds_up(report.requests);
    EXPECT_EQ(report.uses.slots, buffer.packet_count() * size_t(4 * k));
    EXPECT_EQ(report.requests.slots, buffer.packet_count() * 4);
    EXPECT_EQ(report.uses.out, uses.size());
    EXPECT_EQ(report.requests.out, requests.size());
    if (w >= 4 && h >= 4) {
      EXPECT_GT(report.uses.local_duplicates, 0u);
    }
  }
}

TEST(Compactor, UniformImageCompactsToItsListOnce) {
  UseBuffer buffer(64, 48, 4);
  buffer.begin_frame(0);
  const List list = iota_list(20, 10);
  for (int y = 0; y < 48; ++y)
    for (int x = 0; x < 64; ++x) record(buffer, x, y, {list, {77}});
  std::vector<uint32_t> uses, requests;
  const CompactionReport report = Compactor().compact(buffer, uses, requests);
  EXPECT_EQ(uses, list);
  EXPECT_EQ(requests, List{77});
  EXPECT_EQ(report.uses.local_duplicates, uint64_t(32 * 24 - 1) * 10);
  EXPECT_EQ(report.uses.empty, uint64_t(32 * 24) * 6);
  EXPECT_EQ(report.requests.local_duplicates, uint64_t(64 * 48 - 1));
}

TEST(Compactor, RequestIsNeverRemovedAsADuplicateOfAUse) {
  UseBuffer buffer(4, 4, 2);
  buffer.begin_frame(0);
  for (int y = 0; y < 4; ++y)
    for (int x = 0; x < 4; ++x) record(buffer, x, y, {{5, 6}, x == 3 && y == 3 ? List{6} : List{}});
  std::vector<uint32_t> uses, requests;
  Compactor().compact(buffer, uses, requests);
  EXPECT_EQ(uses, List({5, 6}));
  EXPECT_EQ(requests, List{6});
}

TEST(Compactor, OutputDoesNotDependOnTheThreadCount) {
  const int w = 300, h = 257;  // 76 chunks of packets
  const std::vector<Ray> rays = random_rays(w, h, 99);
  UseBuffer serial(w, h, 4), parallel(w, h, 4);
  std::vector<uint32_t> uses1, requests1, uses2, requests2;
  CompactionReport one, two;
  tbb::task_arena(1).execute([&] {
    serial.begin_frame(3);
    record_all(serial, rays);
    one = Compactor().compact(serial, uses1, requests1);
  });
  tbb::task_arena(2).execute([&] {
    parallel.begin_frame(3);
    record_all(parallel, rays);
    two = Compactor().compact(parallel, uses2, requests2);
  });
  EXPECT_EQ(span_to_list(serial.entries()), span_to_list(parallel.entries()));
  EXPECT_EQ(uses1, uses2);
  EXPECT_EQ(requests1, requests2);
  EXPECT_EQ(one.uses.local_duplicates, two.uses.local_duplicates);
  EXPECT_EQ(one.requests.out, two.requests.out);
  EXPECT_GT(uses1.size(), 1000u);
}

// --- the loader's view over frames ---------------------------------------------------

TEST(Feedback, RequestTheBufferCouldNotKeepIsServedInALaterFrame) {
  // Each ray wants several nodes subdivided; a frame keeps only its first request. The loader
  // serves whatever the compacted request list names; the rays ask again for what is left.
  const int w = 13, h = 9;
  std::mt19937 rng(5);
  std::vector<List> pending(size_t(w) * size_t(h));
  size_t most = 0;
  for (List& p : pending) {
    const size_t n = rng() % 5;
    for (size_t i = 0; i < n; ++i) p.push_back(uint32_t(rng() % 60));
    std::sort(p.begin(), p.end());  // front to back: the renderer meets them in this order
    p.erase(std::unique(p.begin(), p.end()), p.end());
    most = std::max(most, p.size());
  }
  ASSERT_GE(most, 3u);
  const std::vector<List> wanted = pending;
  UseBuffer buffer(w, h, 4);
  Compactor compactor;
  std::set<uint32_t> served;
  std::vector<uint32_t> uses, requests;
  for (uint64_t frame = 0; frame < most; ++frame) {
    buffer.begin_frame(frame);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        List& p = pending[size_t(y) * size_t(w) + size_t(x)];
        std::erase_if(p, [&](uint32_t v) { return served.count(v) != 0; });
        record(buffer, x, y, {{1, 2, 3}, p});
      }
    compactor.compact(buffer, uses, requests);
    // Every ray's front-most pending request is in this frame's list.
    for (const List& p : pending) {
      if (!p.empty()) {
        EXPECT_NE(std::find(requests.begin(), requests.end(), p.front()), requests.end());
      }
    }
    served.insert(requests.begin(), requests.end());
  }
  // Within as many frames as the longest queue, every request has been served.
  for (const List& p : wanted)
    for (uint32_t v : p) EXPECT_EQ(served.count(v), 1u) << v;
}

}  // namespace
}  // namespace brickyard::gigavoxels
