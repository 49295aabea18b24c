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
