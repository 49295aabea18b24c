#include <gtest/gtest.h>

#include <algorithm>
#include <list>
#include <map>
#include <random>
#include <set>
#include <string>

#include "cache/policy.h"
#include "cache/replay.h"
#include "cache/trace.h"
#include "core/error.h"

namespace brickyard {
namespace {

const std::vector<std::string> kLivePolicies = {"lru", "clock", "arc", "s3fifo", "sieve", "lru-frame"};

/// Drives a policy the way the caches do, with unit sizes, and checks its invariants.
class PolicyDriver {
 public:
  PolicyDriver(const std::string& name, uint64_t capacity) : policy_(make_policy(name, capacity)), capacity_(capacity) {}
  bool access(uint64_t id) {
    if (resident_.contains(id)) {
      policy_->on_hit(id, kNoNextAccess);
      return true;
    }
    policy_->on_miss(id);
    while (resident_.size() >= capacity_) {
      auto v = policy_->evict({});
      EXPECT_TRUE(v.has_value());
      if (!v) return false;
      EXPECT_TRUE(resident_.contains(*v)) << "evicted " << *v << ", which is not resident";
      resident_.erase(*v);
    }
    policy_->on_insert(id, 1, kNoNextAccess);
    resident_.insert(id);
    return false;
  }
  Policy& policy() { return *policy_; }
  std::set<uint64_t>& resident() { return resident_; }

 private:
  std::unique_ptr<Policy> policy_;
  uint64_t capacity_;
  std::set<uint64_t> resident_;
};

TEST(Policies, RegistryNamesEveryPolicyAndRejectsUnknownOnes) {
  EXPECT_EQ(policy_names(), (std::vector<std::string>{"lru", "clock", "arc", "s3fifo", "sieve", "lru-frame", "opt"}));
  for (const auto& p : policy_catalog()) EXPECT_EQ(make_policy(p.name, 10)->name(), p.name);
  try {
    make_policy("lfu", 10);
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("known policies: lru, clock, arc"), std::string::npos) << e.what();
  }
}

TEST(Policies, RandomWorkloadsKeepEveryPolicyConsistent) {
  for (const auto& name : kLivePolicies) {
    PolicyDriver d(name, 32);
    std::mt19937 rng(7);
    std::geometric_distribution<int> pick(0.02);
    for (int i = 0; i < 20000; ++i) {
      d.policy().on_frame(uint64_t(i));  // lru-frame protects only the current frame
      d.access(uint64_t(pick(rng)));
      ASSERT_LE(d.resident().size(), 32u) << name;
    }
    // Removing an entry behind the policy's back: it must never come back as a victim.
    const uint64_t gone = *d.resident().begin();
    d.policy().on_remove(gone);
    d.resident().erase(gone);
    d.policy().on_frame(999);
    for (size_t i = 0; i < d.resident().size(); ++i) {
      auto v = d.policy().evict({});
      ASSERT_TRUE(v.has_value()) << name;
      EXPECT_NE(*v, gone) << name;
    }
  }
}

TEST(Policies, PinnedEntriesAreNeverEvicted) {
  for (const auto& name : kLivePolicies) {
    auto p = make_policy(name, 8);
    for (uint64_t id = 0; id < 8; ++id) {
      p->on_miss(id);
      p->on_insert(id, 1, kNoNextAccess);
    }
    p->on_frame(1);  // so that lru-frame may evict entries of frame 0
    const std::set<uint64_t> pinned = {0, 1, 2, 3, 5, 6, 7};
    EvictableFn evictable{[](const void* ctx, uint64_t id) { return !static_cast<const std::set<uint64_t>*>(ctx)->contains(id); },
                          &pinned};
    auto v = p->evict(evictable);
    ASSERT_TRUE(v.has_value()) << name;
    EXPECT_EQ(*v, 4u) << name;
    EXPECT_FALSE(p->evict(evictable).has_value()) << name << " evicted a pinned entry";
  }
}

TEST(Policies, LruEvictsTheLeastRecentlyUsed) {
  PolicyDriver d("lru", 3);
  for (uint64_t id : {1, 2, 3, 1, 4}) d.access(id);  // 2 is the oldest when 4 arrives
  EXPECT_EQ(d.resident(), (std::set<uint64_t>{1, 3, 4}));
}

TEST(Policies, ClockGivesReferencedEntriesASecondChance) {
  PolicyDriver d("clock", 3);
  for (uint64_t id : {1, 2, 3}) d.access(id);
  d.access(1);  // referenced
  d.access(4);  // the hand clears 1's bit, evicts 2
  EXPECT_EQ(d.resident(), (std::set<uint64_t>{1, 3, 4}));
}

TEST(Policies, SieveKeepsVisitedEntriesWithoutMovingThem) {
  PolicyDriver d("sieve", 3);
  for (uint64_t id : {1, 2, 3}) d.access(id);
  d.access(1);  // visited
  d.access(4);  // hand from the tail: 1 visited (cleared), evicts 2
  EXPECT_EQ(d.resident(), (std::set<uint64_t>{1, 3, 4}));
  d.access(5);  // hand continues at 3 (unvisited)
  EXPECT_EQ(d.resident(), (std::set<uint64_t>{1, 4, 5}));
}

TEST(Policies, LruFrameProtectsEverythingUsedThisFrame) {
  auto p = make_policy("lru-frame", 4);
  p->on_frame(1);
  for (uint64_t id = 0; id < 4; ++id) p->on_insert(id, 1, kNoNextAccess);
  EXPECT_FALSE(p->evict({}).has_value());  // all used in frame 1
  p->on_frame(2);
  p->on_hit(0, kNoNextAccess);
  p->on_hit(2, kNoNextAccess);
  auto v = p->evict({});
  ASSERT_TRUE(v.has_value());
  EXPECT_EQ(*v, 1u);  // least recently used among those not used in frame 2
  EXPECT_EQ(*p->evict({}), 3u);
  EXPECT_FALSE(p->evict({}).has_value());
}

// SIEVE as the paper's pseudo-code states it, on a std::list: the reference the
// implementation must match miss for miss.
uint64_t reference_sieve_misses(const std::vector<uint64_t>& accesses, size_t capacity) {
  std::list<std::pair<uint64_t, bool>> queue;  // front = newest; bool = visited
  std::map<uint64_t, std::list<std::pair<uint64_t, bool>>::iterator> where;
  auto hand = queue.end();  // end(): start from the tail
  uint64_t misses = 0;
  for (uint64_t x : accesses) {
    if (auto it = where.find(x); it != where.end()) {
      it->second->second = true;
      continue;
    }
    ++misses;
    if (queue.size() == capacity) {
      auto o = hand == queue.end() ? std::prev(queue.end()) : hand;
      while (o->second) {
        o->second = false;
        o = o == queue.begin() ? std::prev(queue.end()) : std::prev(o);
      }
      hand = o == queue.begin() ? queue.end() : std::prev(o);
      where.erase(o->first);
      queue.erase(o);
    }
    queue.emplace_front(x, false);
    where[x] = queue.begin();
  }
  return misses;
}

TEST(Policies, SieveMatchesThePublishedAlgorithmMissForMiss) {
  std::mt19937 rng(5);
  for (int round = 0; round < 20; ++round) {
    std::vector<uint64_t> accesses;
    std::geometric_distribution<int> pick(0.01 + 0.01 * round);
    for (int i = 0; i < 5000; ++i) accesses.push_back(uint64_t(pick(rng)));
    const size_t capacity = 5 + size_t(round) * 3;
    PolicyDriver d("sieve", capacity);
    uint64_t misses = 0;
    for (uint64_t x : accesses) misses += !d.access(x);
    EXPECT_EQ(misses, reference_sieve_misses(accesses, capacity)) << "round " << round;
  }
}

double miss_ratio(const Trace& t, const std::string& policy, uint64_t capacity) {
  return replay(t, next_demand_access(t), policy, capacity).miss_ratio();
}

TEST(Replay, LruCollapsesOnALoopLargerThanTheCacheAndOptDoesNot) {
  // Every online policy here misses everything on a cyclic scan of twice its size; OPT, which
  // sees the future, keeps C - 1 objects across passes.
  const Trace loop = loop_trace(1000, 10);
  EXPECT_DOUBLE_EQ(miss_ratio(loop, "lru", 500), 1.0);
  EXPECT_DOUBLE_EQ(miss_ratio(loop, "clock", 500), 1.0);
  // OPT keeps 499 objects of each pass: misses = 1000 first pass + (1000 - 499) per later pass.
  EXPECT_NEAR(miss_ratio(loop, "opt", 500), (1000.0 + 9 * 501.0) / 10000.0, 5e-3);
}

TEST(Replay, OptIsALowerBoundOnZipfTraces) {
  const Trace t = zipf_trace(5000, 100000, 0.9, 3);
  const auto next = next_demand_access(t);
  for (uint64_t cap : {50, 250, 1000}) {
    const double opt = replay(t, next, "opt", cap).miss_ratio();
    for (const auto& p : kLivePolicies) EXPECT_LE(opt, replay(t, next, p, cap).miss_ratio() + 1e-12) << p << " at " << cap;
    EXPECT_GT(opt, 0.0);
  }
}

TEST(Replay, ScanResistantPoliciesBeatLruOnHotSetPlusScan) {
  // A hot set of 100 objects re-read between one-time scans of 400 new objects.
  Trace t;
  uint64_t fresh = 1000000;
  for (int round = 0; round < 50; ++round) {
    for (int rep = 0; rep < 3; ++rep)
      for (uint64_t i = 0; i < 100; ++i) t.records.push_back({i, uint32_t(round), 1});
    for (int i = 0; i < 400; ++i) t.records.push_back({fresh++, uint32_t(round), 1});
  }
  const double lru = miss_ratio(t, "lru", 200);
  EXPECT_LT(miss_ratio(t, "s3fifo", 200), lru);
  EXPECT_LT(miss_ratio(t, "arc", 200), lru);
}

TEST(Replay, ARequestAtANewSizeIsAMissThatReplacesTheCachedCopy) {
  // Capacity 10; A=1, B=2, C=3 with sizes. By hand, LRU (most recent first):
  //   A4 miss [A]  B4 miss [B A]  A4 hit [A B]  B6 miss: B4 dropped, B6 in [B A] (10 bytes)
  //   A4 hit [A B]  C2 miss: evicts B [C A]  B6 miss: evicts A [B C]  A4 miss: evicts C [A B]
  // OPT, whose copy of B4 is never used again (B is next asked for at 6):
  //   A4 miss, B4 miss, A4 hit, B6 miss (B4 dropped), A4 hit, C2 miss: evicts A (next at 7,
  //   B at 6), B6 hit, A4 miss.
  Trace t;
  t.records = {{1, 0, 4}, {2, 0, 4}, {1, 0, 4}, {2, 0, 6}, {1, 0, 4}, {3, 0, 2}, {2, 0, 6}, {1, 0, 4}};
  EXPECT_EQ(t.unique_bytes(), 4u + 6u + 2u);  // each object at its largest size
  const auto next = next_demand_access(t);
  const ReplayResult lru = replay(t, next, "lru", 10);
  EXPECT_EQ(lru.requests, 8u);
  EXPECT_EQ(lru.misses, 6u);
  EXPECT_EQ(lru.evictions, 3u);  // the dropped copy of B4 is not an eviction
  EXPECT_EQ(lru.bytes_requested, 34u);
  EXPECT_EQ(lru.bytes_missed, 4u + 4u + 6u + 2u + 6u + 4u);
  const ReplayResult opt = replay(t, next, "opt", 10);
  EXPECT_EQ(opt.misses, 5u);
  EXPECT_EQ(opt.evictions, 2u);
  EXPECT_EQ(opt.bytes_missed, 4u + 4u + 6u + 2u + 4u);
  // A 6-byte B in a 5-byte cache: a miss that bypasses it, and still drops B4's copy.
  Trace small;
  small.records = {{2, 0, 4}, {2, 0, 6}, {2, 0, 4}};
  EXPECT_EQ(replay(small, next_demand_access(small), "lru", 5).misses, 3u);
  // Prefetched copies follow the same rule: a demand at a new size wastes the fill; a fill at a
  // new size replaces the copy and serves the demand that follows.
  Trace fills;
  fills.records = {{1, 0, 10, AccessKind::prefetch_fill}, {1, 0, 20}, {1, 0, 30, AccessKind::prefetch_fill}, {1, 0, 30}};
  const ReplayResult f = replay(fills, {}, "lru", 100);
  EXPECT_EQ(f.requests, 2u);
  EXPECT_EQ(f.misses, 1u);
  EXPECT_EQ(f.prefetches, 2u);
  EXPECT_EQ(f.prefetches_used, 1u);
  EXPECT_EQ(f.prefetch_wasted_bytes, 10u);  // the first fill, never used
}

/// A skewed trace over `objects` whose sizes (1 to 64 bytes) are drawn at an object's first
/// request and again at one request in 16, so that objects change size while cached.
/// splitmix64 and one double expression: the same trace on every platform.
Trace resizing_trace(uint64_t seed, uint64_t objects, uint64_t requests) {
  uint64_t state = seed;
  auto random = [&] {
    uint64_t z = (state += 0x9e3779b97f4a7c15ull);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
  };
  constexpr uint32_t kSizes[] = {1, 2, 4, 8, 16, 32, 64};
  std::map<uint64_t, uint32_t> size;
  Trace t;
  for (uint64_t i = 0; i < requests; ++i) {
    const double u = double(random() >> 11) * 0x1p-53;
    const uint64_t key = uint64_t(double(objects) * (u * u * u));
    const uint64_t x = random();
    auto [it, first] = size.try_emplace(key, 0);
    if (first || x % 16 == 0) it->second = kSizes[(x >> 8) % 7];
    t.records.push_back({key, 0, it->second});
  }
  return t;
}

TEST(Replay, OptBoundsEveryPolicyWhenObjectsChangeSize) {
  const Trace t = resizing_trace(1, 300, 10000);
  const auto next = next_demand_access(t);
  const uint64_t working_set = t.unique_bytes();
  uint32_t largest = 0;
  for (const TraceRecord& r : t.records) largest = std::max(largest, r.size);
  // What a cache of the whole working set still misses: first requests and requests at a new
  // size. Every policy, OPT too, misses exactly those there.
  uint64_t unavoidable = 0;
  std::map<uint64_t, uint32_t> last;
  for (const TraceRecord& r : t.records) {
    auto [it, first] = last.try_emplace(r.key, r.size);
    unavoidable += first || it->second != r.size;
    it->second = r.size;
  }
  ASSERT_GT(unavoidable, t.unique_objects());  // sizes did change
  // lru-frame is left out: in a trace of one frame it protects everything and refuses to
  // insert, which a replay OPT that inserts every miss does not bound.
  for (double fraction : {0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0}) {
    const uint64_t capacity = std::max<uint64_t>(1, uint64_t(double(working_set) * fraction));
    const uint64_t opt = replay(t, next, "opt", capacity).misses;
    EXPECT_GE(opt, unavoidable);
    if (fraction == 1.0) {
      EXPECT_EQ(opt, unavoidable);
    }
    for (const char* policy : {"lru", "clock", "arc", "s3fifo", "sieve"}) {
      const uint64_t misses = replay(t, next, policy, capacity).misses;
      EXPECT_GE(misses, opt) << policy << " at " << capacity << " bytes";
      if (fraction == 1.0) {
        EXPECT_EQ(misses, unavoidable) << policy;
      }
    }
  }
  // LRU's cache is a prefix of its recency stack; once no object is larger than the cache
  // (none bypasses it), a larger cache holds a superset of a smaller one's objects, each at
  // its latest size, so its misses never grow. Below that size they may.
  uint64_t previous = UINT64_MAX;
  for (uint64_t capacity = largest; capacity <= working_set; capacity = capacity * 3 / 2) {
    const uint64_t misses = replay(t, {}, "lru", capacity).misses;
    EXPECT_LE(misses, previous) << "at " << capacity << " bytes";
    previous = misses;
  }
}

TEST(Replay, CountsBytesAndPrefetches) {
  Trace t;
  t.records = {{1, 0, 10, AccessKind::prefetch_request},
               {1, 0, 10, AccessKind::prefetch_fill},
               {1, 0, 10},                                    // hit on a prefetched brick: useful
               {2, 0, 30, AccessKind::prefetch_fill},         // never used: wasted when evicted
               {3, 1, 50, AccessKind::prefetch_request},
               {3, 1, 50},                                    // miss while requested: late
               {4, 1, 100}};                                  // larger than the cache: bypass
  const ReplayResult r = replay(t, {}, "lru", 60);
  EXPECT_EQ(r.requests, 3u);
  EXPECT_EQ(r.misses, 2u);
  EXPECT_EQ(r.bytes_requested, 160u);
  EXPECT_EQ(r.bytes_missed, 150u);
  EXPECT_EQ(r.prefetches, 2u);
  EXPECT_EQ(r.prefetches_used, 1u);
  EXPECT_EQ(r.late_prefetches, 1u);
  EXPECT_EQ(r.prefetch_wasted_bytes, 30u);  // brick 2 made room for brick 3
  EXPECT_DOUBLE_EQ(r.prefetch_accuracy(), 0.5);
  EXPECT_NEAR(r.prefetch_coverage(), 1.0 / 3.0, 1e-12);
  EXPECT_GT(r.metadata_bytes_per_entry, 0.0);
}

}  // namespace
}  // namespace brickyard
