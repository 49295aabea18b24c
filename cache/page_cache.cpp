#include "cache/page_cache.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstring>
#include <deque>
#include <mutex>
#include <queue>
#include <shared_mutex>
#include <thread>

#include <absl/container/flat_hash_map.h>
#include <absl/container/flat_hash_set.h>
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "core/atomic_file.h"
#include "core/error.h"
#include "core/thread_stripe.h"
#include "core/timing.h"
#include "core/units.h"

namespace brickyard {

namespace {

uint64_t now_ns() {
  return uint64_t(std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch()).count());
}

constexpr size_t kStripes = 16;

size_t stripe_of_this_thread() { return thread_stripe(kStripes); }

uint32_t slots_for(const KindBudget& b, RecordKind kind, size_t page_bytes) {
  const uint64_t slots = b.l1_slots ? b.l1_slots : b.l1_bytes / page_bytes;
  if (slots == 0) {
    const auto [budget, page] = format_bytes_apart(b.l1_bytes, page_bytes);
    throw Error(Errc::invalid_argument, fmt::format("the L1 budget of {} is smaller than one {} ({})", budget,
                                                    kind == RecordKind::brick ? "brick" : to_string(kind), page))
        .with_field("l1_bytes");
  }
  if (slots > UINT32_MAX / 2) throw Error(Errc::invalid_argument, "too many L1 slots").with_field("l1_slots");
  return uint32_t(slots);
}

/// The budgets of each kind a source holds (CacheConfig::kinds).
KindBudget budget_of(const CacheConfig& c, RecordKind kind, size_t kinds_held, size_t kinds_listed) {
  if (auto it = c.kinds.find(kind); it != c.kinds.end()) return it->second;
  const uint64_t sharing = std::max<uint64_t>(1, kinds_held - kinds_listed);
  return {c.l1_slots, c.l1_bytes / sharing, c.l2_bytes / sharing};
}

/// Latencies in log-spaced buckets (10% wide) from 1 us to ~1000 s: percentiles within 10%.
class LatencyHistogram {
 public:
  void add(double seconds) {
    const double us = std::max(1.0, seconds * 1e6);
    const size_t b = std::min(buckets_.size() - 1, size_t(std::log(us) / std::log(1.1)));
    std::lock_guard lock(mutex_);
    ++buckets_[b];
    ++count_;
  }
  double quantile_ms(double q) const {
    std::lock_guard lock(mutex_);
    if (count_ == 0) return 0;
    const double target = q * double(count_);
    double acc = 0;
    for (size_t b = 0; b < buckets_.size(); ++b) {
      acc += double(buckets_[b]);
      if (acc >= target) return std::pow(1.1, double(b) + 0.5) / 1e3;
    }
    return std::pow(1.1, double(buckets_.size())) / 1e3;
  }

 private:
  mutable std::mutex mutex_;
  std::vector<uint64_t> buckets_ = std::vector<uint64_t>(220, 0);
  uint64_t count_ = 0;
};

/// Appends access records from many threads; written out, in order, when the cache closes.
class TraceRecorder {
 public:
  explicit TraceRecorder(std::string path) : path_(std::move(path)) {}
  void add(const PageKey& key, uint32_t frame, uint32_t size, AccessKind kind, uint8_t hit_level) {
    const uint64_t seq = seq_.fetch_add(1, std::memory_order_relaxed);
    Stripe& s = stripes_[stripe_of_this_thread()];
    std::lock_guard lock(s.mutex);
    s.records.push_back({seq, {key.id, frame, size, kind, hit_level, uint32_t(stripe_of_this_thread()), key.kind}});
  }
  void write() {
    std::vector<std::pair<uint64_t, TraceRecord>> all;
    for (auto& s : stripes_) {
      std::lock_guard lock(s.mutex);
      all.insert(all.end(), s.records.begin(), s.records.end());
    }
    std::sort(all.begin(), all.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
    Trace t;
    t.records.reserve(all.size());
    for (const auto& [seq, r] : all) t.records.push_back(r);
    write_trace(path_, t, TraceFormat::brickyard);
  }

 private:
  struct alignas(64) Stripe {
    std::mutex mutex;
    std::vector<std::pair<uint64_t, TraceRecord>> records;
  };
  std::string path_;
  std::atomic<uint64_t> seq_{0};
  Stripe stripes_[kStripes];
};

}  // namespace

namespace {
bool claim_budget(std::atomic<uint64_t>& counter, uint64_t amount, uint64_t limit) {
  if (limit == 0) {
    counter.fetch_add(amount, std::memory_order_relaxed);
    return true;
  }
  const uint64_t before = counter.fetch_add(amount, std::memory_order_relaxed);
  if (before + amount <= limit) return true;
  counter.fetch_sub(amount, std::memory_order_relaxed);
  return false;
}
}  // namespace

// ---------------------------------------------------------------------------------------------

struct PageCache::Impl {
  struct Pending {
    float priority;
    uint64_t frame;
    uint64_t requested_ns;
  };
  struct HeapEntry {
    float priority;
    uint64_t seq;
    PageKey key;
    bool operator<(const HeapEntry& o) const {
      return priority != o.priority ? priority < o.priority : seq > o.seq;  // FIFO among equals
    }
  };
  struct Ready {
    PageKey key;
    PageBuffer data;  // null while only `parked` refers to it (see held_bytes)
    uint64_t requested_ns;
    uint64_t ticket;  // which load of the key this is (ready_keys)
    std::weak_ptr<const std::vector<std::byte>> parked;  // the page as L2 holds it, while L2 does
  };
  struct alignas(64) RequestStripe {
    std::mutex mutex;
    std::vector<PageRequest> staged;
  };
  struct alignas(64) MarkStripe {
    std::mutex mutex;  // guards visible
    std::vector<std::pair<PageKey, bool>> visible;
    // Counted on the hit path: relaxed atomics on a line that one thread mostly owns.
    std::atomic<uint64_t> lookups{0}, hits{0};
    std::atomic<uint64_t> constant_hits[kRecordKinds] = {};
  };

  // Loader queue. queue_mutex guards heap, pending, in_flight, ready, blocked, ready_keys,
  // failed, frame_requests, the request counters and every change to the per-frame upload
  // budget (frame_end() only reads it); the workers wait on work_cv, wait_idle() on idle_cv.
  mutable std::mutex queue_mutex;
  std::condition_variable work_cv, idle_cv;
  std::priority_queue<HeapEntry> heap;
  absl::flat_hash_map<PageKey, Pending> pending;
  // Keys being read and decoded, or placed in the pool; a decoded key waits in ready as in
  // flight until its loader's drain_ready() returns, and after that as deferred.
  absl::flat_hash_set<PageKey> in_flight;
  std::deque<Ready> ready;
  // Decoded bricks that no unpinned slot could take, tried again at the next frame_begin()
  // (pins are released between frames): once a frame each, not at every drain.
  std::deque<Ready> blocked;
  // The keys of ready and blocked (decoded, waiting for an upload budget or a slot) and their
  // loads' tickets: requests for them are merged, and a loader leaves in_flight only for its
  // own load of a key.
  absl::flat_hash_map<PageKey, uint64_t> ready_keys;
  // Bytes of ready pages the queue holds itself. Past one frame's upload budget a decoded page
  // waits only as L2's (parked): the queue would otherwise keep every page loaded ahead of
  // the budget alive, past L2's budget, for as long as the budget lags the requests. A parked
  // page L2 evicted is dropped when its turn comes; a renewed request loads it again.
  uint64_t held_bytes = 0;
  uint64_t expired_waiting = 0;
  uint64_t next_ticket = 1;  // 0: no load queued
  absl::flat_hash_map<PageKey, std::string> failed;
  absl::flat_hash_map<PageKey, float> this_frame_requests;
  std::vector<PageRequest> last_frame_requests;
  uint64_t seq = 0;
  uint64_t requests = 0, merged = 0, dropped = 0, frame_dropped = 0;
  bool stop = false;

  RequestStripe request_stripes[kStripes];
  MarkStripe mark_stripes[kStripes];

  mutable std::shared_mutex visibility_mutex;
  absl::flat_hash_map<PageKey, bool> visibility;

  std::atomic<uint64_t> frame{0};
  std::atomic<uint64_t> frame_uploads{0}, frame_upload_bytes{0};
  std::atomic<uint64_t> deferred{0};
  uint64_t frames_done = 0;
  LatencyHistogram latency;
  std::unique_ptr<TraceRecorder> trace;
  std::vector<std::thread> workers;
};

// ---------------------------------------------------------------------------------------------

const std::string& PageHandle::error() const {
  static const std::string none;
  return error_ ? *error_ : none;
}

PageHandle& PageHandle::operator=(PageHandle&& o) noexcept {
  if (this != &o) {
    release();
    cache_ = o.cache_;
    state_ = o.state_;
    key_ = o.key_;
    slot_ = o.slot_;
    data_ = o.data_;
    owned_ = std::move(o.owned_);
    error_ = std::move(o.error_);
    o.cache_ = nullptr;
    o.slot_ = kNoSlot;
    o.state_ = State::miss;
    o.data_ = nullptr;
  }
  return *this;
}

void PageHandle::release() {
  if (cache_ && slot_ != kNoSlot) cache_->unpin(key_.kind, slot_);
  cache_ = nullptr;
  slot_ = kNoSlot;
  data_ = nullptr;
  owned_.reset();
  if (state_ == State::resident) state_ = State::miss;
}

CacheLevelStats& CacheLevelStats::operator+=(const CacheLevelStats& o) {
  const uint64_t entries = resident + o.resident;
  if (entries > 0)
    metadata_bytes_per_entry =
        (metadata_bytes_per_entry * double(resident) + o.metadata_bytes_per_entry * double(o.resident)) / double(entries);
  hits += o.hits;
  misses += o.misses;
  inserts += o.inserts;
  evictions += o.evictions;
  failed_evictions += o.failed_evictions;
  resident += o.resident;
  capacity += o.capacity;
  return *this;
}

// ---------------------------------------------------------------------------------------------

PageCache::Kind::Kind(RecordKind k, size_t bytes, uint32_t slot_count, uint64_t l2_bytes, const CacheConfig& config)
    : kind(k),
      page_bytes(bytes),
      slots(slot_count, config.l1_policy),
      // Committed as slots fill (zeroing a 1 GiB L1 up front took 2 s of a 256^3 render that
      // fills 24 MiB of it).
      pool(make_pool_array<std::byte>(size_t(slot_count) * bytes)),
      l2(l2_bytes, bytes, config.l2_policy) {}

PageCache::PageCache(const PageSource& source, const CacheConfig& config)
    : source_(source), config_(config), impl_(std::make_unique<Impl>()) {
  if (config.loader_threads < 1 || config.loader_threads > 256)
    throw Error(Errc::invalid_argument, fmt::format("{} loader threads (need 1 to 256)", config.loader_threads))
        .with_field("loader_threads");
  // Before the pools are allocated, and long before the trace is written at close().
  if (!config.trace_path.empty()) check_writable(config.trace_path);
  const std::vector<PageKindInfo> held = source.page_kinds();
  if (held.empty()) throw Error(Errc::invalid_argument, "the source holds no pages").with_file(source.source_name());
  size_t listed = 0;
  for (const PageKindInfo& info : held) listed += config.kinds.count(info.kind);
  for (const PageKindInfo& info : held) {
    if (info.page_bytes == 0)
      throw Error(Errc::invalid_argument, fmt::format("{} pages of 0 bytes", to_string(info.kind))).with_file(source.source_name());
    if (kinds_[size_t(info.kind)])
      throw Error(Errc::internal, fmt::format("{} pages listed twice", to_string(info.kind))).with_file(source.source_name());
    const KindBudget b = budget_of(config, info.kind, held.size(), listed);
    kinds_[size_t(info.kind)] =
        std::make_unique<Kind>(info.kind, info.page_bytes, slots_for(b, info.kind, info.page_bytes), b.l2_bytes, config);
  }
  if (!config.trace_path.empty()) impl_->trace = std::make_unique<TraceRecorder>(config.trace_path);
  for (int t = 0; t < config.loader_threads; ++t) impl_->workers.emplace_back([this] { worker_loop(); });
}

std::vector<RecordKind> PageCache::kinds() const {
  std::vector<RecordKind> out;
  for (size_t k = 0; k < kRecordKinds; ++k)
    if (kinds_[k]) out.push_back(RecordKind(k));
  return out;
}

void PageCache::worker_loop() {
  Impl& m = *impl_;
  const std::unique_ptr<PageReader> reader = source_.open_reader();  // one snapshot per worker: the source is immutable
  while (true) {
    PageKey key;
    uint64_t requested_ns = 0;
    {
      std::unique_lock lock(m.queue_mutex);
      m.work_cv.wait(lock, [&] { return m.stop || !m.heap.empty(); });
      if (m.stop) return;
      const Impl::HeapEntry top = m.heap.top();
      m.heap.pop();
      auto it = m.pending.find(top.key);
      if (it == m.pending.end() || it->second.priority != top.priority) {
        notify_if_idle_locked();
        continue;  // stale: served, dropped or re-prioritised
      }
      key = top.key;
      requested_ns = it->second.requested_ns;
      m.pending.erase(it);
      m.in_flight.insert(key);
    }
    // Step 1: L2, else read and decode from the source (outside every lock).
    Kind& k = *kinds_[size_t(key.kind)];
    std::string error;
    PageBuffer data;
    if (!k.slots.resident_or_reserved(key.id)) {  // else placed, or being placed by a blocking fetch
      data = k.l2.find(key.id);
      if (!data) {
        try {
          data = load_from_source(*reader, k, key);
        } catch (const Error& e) {
          error = e.what();
        }
      }
    }
    // Step 2: hand the page to the upload queue, and upload what the budget allows. It stays
    // in flight until it is placed (by whichever thread drains it) or left for a later frame's
    // budget: until then wait_idle() must not return, nor a renewed request queue it again.
    uint64_t ticket = 0;  // none queued
    {
      std::lock_guard lock(m.queue_mutex);
      if (!error.empty()) m.failed.emplace(key, error);
      // One frame's upload budget, in bytes (none without a budget: then drains place at once).
      const uint64_t hold_limit = std::max(config_.upload_bytes_per_frame, config_.upload_pages_per_frame * k.page_bytes);
      const bool over = data && hold_limit > 0 && m.held_bytes + data->size() > hold_limit;
      if (over && data.use_count() == 1) {
        // Past the budget and L2 has already let it go: dropped now, as a parked page would be.
        ++m.expired_waiting;
        data.reset();
      }
      if (data) {
        ticket = m.next_ticket++;
        Impl::Ready r{key, std::move(data), requested_ns, ticket, {}};
        if (over) {  // L2 holds it: it waits as L2's
          r.parked = r.data;
          r.data.reset();
        } else {
          m.held_bytes += r.data->size();
        }
        m.ready.push_back(std::move(r));
        m.ready_keys.emplace(key, ticket);
      } else {
        m.in_flight.erase(key);
      }
    }
    drain_ready();
    std::lock_guard lock(m.queue_mutex);
    // Still waiting: deferred, no longer in flight. (A later load of the same key, once this
    // one was placed and evicted, has its own ticket and stays in flight.)
    if (auto it = m.ready_keys.find(key); it != m.ready_keys.end() && it->second == ticket) m.in_flight.erase(key);
    notify_if_idle_locked();
  }
}

bool PageCache::idle_locked() const { return impl_->pending.empty() && impl_->in_flight.empty(); }

void PageCache::notify_if_idle_locked() {
  if (idle_locked()) impl_->idle_cv.notify_all();
}

PageBuffer PageCache::load_from_source(PageReader& reader, Kind& k, const PageKey& key) {
  try {
    auto buffer = std::make_shared<std::vector<std::byte>>(k.page_bytes);
    const PageRead read = reader.read(key, *buffer);
    k.l3_decode_ns.fetch_add(read.decode_ns, std::memory_order_relaxed);
    k.l3_reads.fetch_add(1, std::memory_order_relaxed);
    k.l3_bytes_read.fetch_add(read.stored_bytes, std::memory_order_relaxed);
    k.l3_bytes_decoded.fetch_add(k.page_bytes, std::memory_order_relaxed);
    PageBuffer data = std::move(buffer);
    k.l2.insert(key.id, data);
    return data;
  } catch (Error& e) {
    if (e.file().empty()) e.with_file(source_.source_name());
    throw;
  }
}

void PageCache::drain_ready() {
  Impl& m = *impl_;
  const uint64_t page_limit = config_.upload_pages_per_frame, byte_limit = config_.upload_bytes_per_frame;
  while (true) {
    Impl::Ready r;
    uint64_t claimed_in = 0;  // the frame whose budget this page claimed
    size_t bytes = 0;
    {
      std::lock_guard lock(m.queue_mutex);
      if (m.ready.empty()) break;
      bytes = kinds_[size_t(m.ready.front().key.kind)]->page_bytes;
      if (!claim_budget(m.frame_uploads, 1, page_limit)) break;
      if (!claim_budget(m.frame_upload_bytes, bytes, byte_limit)) {
        m.frame_uploads.fetch_sub(1);
        break;
      }
      // A claim outlived by frame_begin() is charged to no frame: a frame may place one page
      // more than its limit for each drain under way as it begins.
      claimed_in = m.frame.load();
      r = std::move(m.ready.front());
      m.ready.pop_front();
      m.ready_keys.erase(r.key);
      if (r.data) {
        m.held_bytes -= r.data->size();
      } else if (!(r.data = r.parked.lock())) {
        // Parked, and L2 has evicted it since: dropped, the budget given back.
        ++m.expired_waiting;
        m.in_flight.erase(r.key);
        if (m.frame.load() == claimed_in) {
          m.frame_uploads.fetch_sub(1);
          m.frame_upload_bytes.fetch_sub(bytes);
        }
        notify_if_idle_locked();
        continue;
      }
      m.in_flight.insert(r.key);  // being placed (a page deferred earlier had left it)
    }
    Kind& k = *kinds_[size_t(r.key.kind)];
    const uint32_t slot = k.slots.reserve(r.key.id);
    if (slot == kNoSlot) {
      // Placed, or being placed, by another thread (a blocking fetch won the race): dropped.
      // Or every slot of its shard is pinned: blocked until the next frame, while the pages
      // behind it are placed. Either way the budget goes back, unless frame_begin() has
      // renewed it since.
      const bool placed_elsewhere = k.slots.resident_or_reserved(r.key.id);
      std::lock_guard lock(m.queue_mutex);
      if (m.frame.load() == claimed_in) {
        m.frame_uploads.fetch_sub(1);
        m.frame_upload_bytes.fetch_sub(bytes);
      }
      m.in_flight.erase(r.key);
      if (!placed_elsewhere) {
        m.ready_keys.emplace(r.key, r.ticket);
        m.blocked.push_back(std::move(r));
        m.deferred.fetch_add(1, std::memory_order_relaxed);
      }
      notify_if_idle_locked();
      continue;
    }
    std::memcpy(k.pool.get() + size_t(slot) * k.page_bytes, r.data->data(), k.page_bytes);
    k.slots.publish(slot);
    k.uploads.fetch_add(1, std::memory_order_relaxed);
    m.latency.add(double(now_ns() - r.requested_ns) * 1e-9);
    if (m.trace) m.trace->add(r.key, uint32_t(m.frame.load()), uint32_t(k.page_bytes), AccessKind::prefetch_fill, 2);
    std::lock_guard lock(m.queue_mutex);  // counted, then out of flight: wait_idle() sees both
    m.in_flight.erase(r.key);
    notify_if_idle_locked();
  }
}

void PageCache::stop_loader() {
  {
    std::lock_guard lock(impl_->queue_mutex);
    impl_->stop = true;
  }
  impl_->work_cv.notify_all();
  impl_->idle_cv.notify_all();
  for (auto& t : impl_->workers) t.join();
  impl_->workers.clear();
}

void PageCache::close() {
  stop_loader();  // first: the loader records fills until it stops
  // Taken before writing, so that a failed write is reported once, here, and not retried by
  // the destructor.
  if (const std::unique_ptr<TraceRecorder> trace = std::move(impl_->trace)) trace->write();
}

PageCache::~PageCache() {
  try {
    close();
  } catch (...) {
    // A destructor must not throw; the trace is lost, the data is not. Callers that say the
    // trace was written call close() and see this error.
  }
}

uint64_t PageCache::frame() const { return impl_->frame.load(); }

PageHandle PageCache::fetch_or_failed(const PageKey& key) {
  try {
    return fetch(key);
  } catch (const Error&) {
    std::string error;
    {
      std::lock_guard lock(impl_->queue_mutex);
      auto f = impl_->failed.find(key);
      if (f == impl_->failed.end()) throw;  // not a load that failed: the caller's mistake
      error = f->second;
    }
    PageHandle h;
    set_failed(h, key, std::move(error));
    return h;
  }
}

std::vector<PageCache::FailedPage> PageCache::failed_pages() const {
  std::vector<FailedPage> out;
  {
    std::lock_guard lock(impl_->queue_mutex);
    for (const auto& [key, error] : impl_->failed) out.push_back({key, error});
  }
  std::sort(out.begin(), out.end(), [](const FailedPage& a, const FailedPage& b) { return a.key < b.key; });
  return out;
}

void PageCache::set_failed(PageHandle& h, const PageKey& key, std::string error) {
  h.key_ = key;
  h.state_ = PageHandle::State::failed;
  h.error_ = std::make_shared<const std::string>(std::move(error));
}

PageHandle PageCache::resident_handle(const PageKey& key, uint32_t slot) {
  PageHandle h;
  h.key_ = key;
  h.state_ = PageHandle::State::resident;
  h.cache_ = this;
  h.slot_ = slot;
  h.data_ = slot_data(key.kind, slot);
  return h;
}

void PageCache::lookup_into(PageHandle& out, const PageKey& key, float priority, bool request_on_miss) {
  out.release();
  Impl& m = *impl_;
  Kind* k = kinds_[size_t(key.kind)].get();
  if (!k)
    return set_failed(out, key, fmt::format("{}: key {}: the source holds no {} pages", source_.source_name(),
                                            source_.describe(key), to_string(key.kind)));
  auto& stripe = m.mark_stripes[stripe_of_this_thread()];
  const uint32_t slot = k->slots.lookup_and_pin(key.id);
  stripe.lookups.fetch_add(1, std::memory_order_relaxed);
  if (slot != kNoSlot) stripe.hits.fetch_add(1, std::memory_order_relaxed);
  if (m.trace) m.trace->add(key, uint32_t(m.frame.load()), uint32_t(k->page_bytes), AccessKind::demand, slot != kNoSlot ? 1 : 0);
  out.key_ = key;
  if (slot != kNoSlot) {
    out.cache_ = this;
    out.slot_ = slot;
    out.data_ = k->pool.get() + size_t(slot) * k->page_bytes;
    out.state_ = PageHandle::State::resident;
    return;
  }
  {
    std::lock_guard lock(m.queue_mutex);
    if (auto f = m.failed.find(key); f != m.failed.end()) return set_failed(out, key, f->second);
  }
  if (request_on_miss) request(key, priority);
  out.state_ = PageHandle::State::miss;
}

bool PageCache::resident(const PageKey& key) const {
  const Kind* k = kinds_[size_t(key.kind)].get();
  return k && k->slots.contains(key.id);
}

void PageCache::count_constant_hit(RecordKind kind) {
  auto& stripe = impl_->mark_stripes[stripe_of_this_thread()];
  stripe.lookups.fetch_add(1, std::memory_order_relaxed);
  stripe.hits.fetch_add(1, std::memory_order_relaxed);
  stripe.constant_hits[size_t(kind)].fetch_add(1, std::memory_order_relaxed);
}

void PageCache::request(const PageKey& key, float priority) {
  const Kind* k = kinds_[size_t(key.kind)].get();
  if (!k) return;
  Impl& m = *impl_;
  if (m.trace) m.trace->add(key, uint32_t(m.frame.load()), uint32_t(k->page_bytes), AccessKind::prefetch_request, 0);
  auto& s = m.request_stripes[stripe_of_this_thread()];
  std::vector<PageRequest> batch;
  {
    std::lock_guard lock(s.mutex);
    s.staged.push_back({key, priority});
    if (s.staged.size() < 64) return;
    batch.swap(s.staged);
  }
  // A full stripe goes to the loader now, so loading overlaps rendering.
  {
    std::lock_guard lock(m.queue_mutex);
    enqueue_locked(batch);
  }
  m.work_cv.notify_all();
}

std::vector<PageRequest> PageCache::take_staged() {
  std::vector<PageRequest> staged;
  for (auto& s : impl_->request_stripes) {
    std::lock_guard lock(s.mutex);
    staged.insert(staged.end(), s.staged.begin(), s.staged.end());
    s.staged.clear();
  }
  return staged;
}

void PageCache::enqueue_locked(const std::vector<PageRequest>& batch) {
  Impl& m = *impl_;
  const uint64_t frame = m.frame.load();
  const uint64_t now = now_ns();
  for (const auto& r : batch) {
    auto [best, fresh] = m.this_frame_requests.try_emplace(r.key, r.priority);
    if (!fresh) best->second = std::max(best->second, r.priority);
    if (m.failed.contains(r.key)) continue;  // failed once: never retried
    if (auto it = m.pending.find(r.key); it != m.pending.end()) {
      ++m.merged;
      it->second.frame = frame;
      if (r.priority > it->second.priority) {
        it->second.priority = r.priority;
        m.heap.push({r.priority, m.seq++, r.key});
      }
      continue;
    }
    if (m.in_flight.contains(r.key) || m.ready_keys.contains(r.key) ||
        kinds_[size_t(r.key.kind)]->slots.resident_or_reserved(r.key.id)) {
      ++m.merged;
      continue;
    }
    ++m.requests;
    m.pending.emplace(r.key, Impl::Pending{r.priority, frame, now});
    m.heap.push({r.priority, m.seq++, r.key});
  }
}

PageHandle PageCache::fetch(const PageKey& key) {
  Impl& m = *impl_;
  Kind* k = kinds_[size_t(key.kind)].get();
  if (!k)
    throw Error(Errc::not_found, fmt::format("the source holds no {} pages", to_string(key.kind)))
        .with_file(source_.source_name())
        .with_key(source_.describe(key));
  if (const uint32_t slot = k->slots.lookup_and_pin(key.id); slot != kNoSlot) {
    if (m.trace) m.trace->add(key, uint32_t(m.frame.load()), uint32_t(k->page_bytes), AccessKind::blocking, 1);
    return resident_handle(key, slot);
  }
  {
    std::lock_guard lock(m.queue_mutex);
    if (auto f = m.failed.find(key); f != m.failed.end()) throw Error(Errc::corrupt, f->second);
  }
  k->stalls.fetch_add(1, std::memory_order_relaxed);
  const uint64_t started = now_ns();
  PageBuffer data = k->l2.find(key.id);
  uint8_t level = 2;
  if (!data) {
    level = 3;
    try {
      data = load_from_source(*source_.open_reader(), *k, key);
    } catch (const Error& e) {
      std::lock_guard lock(m.queue_mutex);
      m.failed.emplace(key, e.what());
      throw;
    }
  }
  if (m.trace) m.trace->add(key, uint32_t(m.frame.load()), uint32_t(k->page_bytes), AccessKind::blocking, level);
  // Into the pool, pinned for the caller. Another thread may be placing the same page: then
  // use its slot once published, or keep a private copy rather than wait.
  const uint32_t slot = k->slots.reserve(key.id);
  if (slot != kNoSlot) {
    std::memcpy(k->pool.get() + size_t(slot) * k->page_bytes, data->data(), k->page_bytes);
    k->slots.publish(slot, 1);
    k->uploads.fetch_add(1, std::memory_order_relaxed);
    m.latency.add(double(now_ns() - started) * 1e-9);
    return resident_handle(key, slot);
  }
  if (const uint32_t s = k->slots.lookup_and_pin(key.id); s != kNoSlot) return resident_handle(key, s);
  PageHandle r;
  r.key_ = key;
  r.state_ = PageHandle::State::resident;
  r.owned_ = data;
  r.data_ = data->data();
  return r;
}

void PageCache::mark_used(const PageKey& key) {
  if (Kind* k = kinds_[size_t(key.kind)].get()) k->slots.touch(key.id);
}

void PageCache::mark_visible(const PageKey& key, bool visible) {
  auto& s = impl_->mark_stripes[stripe_of_this_thread()];
  std::lock_guard lock(s.mutex);
  s.visible.emplace_back(key, visible);
}

std::optional<bool> PageCache::visibility(const PageKey& key) const {
  std::shared_lock lock(impl_->visibility_mutex);
  auto it = impl_->visibility.find(key);
  if (it == impl_->visibility.end()) return std::nullopt;
  return it->second;
}

void PageCache::frame_begin() {
  Impl& m = *impl_;
  uint64_t f = 0;
  {
    // With the queue mutex, under which drain_ready() gives back a budget it claimed: never
    // into the new frame's (the counters would wrap below zero).
    std::lock_guard lock(m.queue_mutex);
    f = m.frame.fetch_add(1) + 1;
    m.frame_uploads.store(0);
    m.frame_upload_bytes.store(0);
    m.ready.insert(m.ready.begin(), std::make_move_iterator(m.blocked.begin()), std::make_move_iterator(m.blocked.end()));
    m.blocked.clear();
  }
  for (auto& k : kinds_)
    if (k) k->slots.frame(f);
  drain_ready();  // pages the last frame's budget or pins deferred
}

FrameReport PageCache::frame_end() {
  Impl& m = *impl_;
  FrameReport report;
  report.frame = m.frame.load();
  // Step 1: staged requests reach the loader; requests not renewed this frame are dropped.
  const std::vector<PageRequest> staged = take_staged();
  {
    std::lock_guard lock(m.queue_mutex);
    enqueue_locked(staged);
    const uint64_t frame = m.frame.load();
    for (auto it = m.pending.begin(); it != m.pending.end();) {
      if (it->second.frame < frame) {
        ++m.dropped;
        ++report.dropped;
        m.pending.erase(it++);
      } else {
        ++it;
      }
    }
    report.requests = m.this_frame_requests.size();
    m.last_frame_requests.clear();
    for (const auto& [key, priority] : m.this_frame_requests) m.last_frame_requests.push_back({key, priority});
    m.this_frame_requests.clear();
    ++m.frames_done;
  }
  m.work_cv.notify_all();
  std::sort(m.last_frame_requests.begin(), m.last_frame_requests.end(), [](const PageRequest& a, const PageRequest& b) {
    return a.priority != b.priority ? a.priority > b.priority : a.key < b.key;
  });
  // Step 2: visibility marks become readable.
  {
    std::unique_lock vlock(m.visibility_mutex);
    for (auto& s : m.mark_stripes) {
      std::lock_guard lock(s.mutex);
      for (const auto& [key, visible] : s.visible) m.visibility[key] = visible;
      s.visible.clear();
      report.lookups += s.lookups.exchange(0, std::memory_order_relaxed);
      report.hits += s.hits.exchange(0, std::memory_order_relaxed);
    }
  }
  report.uploads = m.frame_uploads.load();
  report.upload_bytes = m.frame_upload_bytes.load();
  return report;
}

std::vector<PageRequest> PageCache::frame_requests() const {
  std::lock_guard lock(impl_->queue_mutex);
  return impl_->last_frame_requests;
}

void PageCache::wait_idle() {
  Impl& m = *impl_;
  const std::vector<PageRequest> staged = take_staged();
  {
    std::lock_guard lock(m.queue_mutex);
    enqueue_locked(staged);
  }
  m.work_cv.notify_all();
  std::unique_lock lock(m.queue_mutex);
  m.idle_cv.wait(lock, [&] { return m.stop || idle_locked(); });  // closed: nothing will be served
}

CacheStats PageCache::kind_stats(const Kind& k) const {
  const Impl& m = *impl_;
  CacheStats s;
  const SlotCounters c1 = k.slots.counters();
  s.l1 = {c1.hits, c1.misses, c1.inserts, c1.evictions, c1.failed_evictions, k.slots.resident(), k.slots.capacity(),
          k.slots.metadata_bytes_per_entry()};
  const SlotCounters c2 = k.l2.counters();
  s.l2 = {c2.hits, c2.misses, c2.inserts, c2.evictions, c2.failed_evictions, k.l2.resident_bytes(), k.l2.budget(),
          k.l2.metadata_bytes_per_entry()};
  s.l3.hits = k.l3_reads.load();
  for (const PageKindInfo& info : source_.page_kinds())
    if (info.kind == k.kind) s.l3.resident = s.l3.capacity = info.records;
  s.l1_pool_bytes = uint64_t(k.slots.capacity()) * k.page_bytes;
  s.l2_peak_bytes = k.l2.peak_bytes();
  s.l3_bytes_read = k.l3_bytes_read.load();
  s.l3_bytes_decoded = k.l3_bytes_decoded.load();
  s.l3_decode_seconds = double(k.l3_decode_ns.load()) * 1e-9;
  for (const auto& stripe : m.mark_stripes) s.constant_hits += stripe.constant_hits[size_t(k.kind)].load(std::memory_order_relaxed);
  s.uploads = k.uploads.load();
  s.stalls = k.stalls.load();
  {
    std::lock_guard lock(m.queue_mutex);
    for (const auto& [key, error] : m.failed) s.failed_keys += key.kind == k.kind;
  }
  add_queue_stats(s);
  return s;
}

void PageCache::add_queue_stats(CacheStats& s) const {
  const Impl& m = *impl_;
  {
    std::lock_guard lock(m.queue_mutex);
    s.requests = m.requests;
    s.merged_requests = m.merged;
    s.dropped_requests = m.dropped;
    s.queue_length = m.pending.size();
    s.frames = m.frames_done;
    // A buffer L2 still holds has a second owner; one only the queue holds is memory beside L2.
    for (const auto* q : {&m.ready, &m.blocked})
      for (const Impl::Ready& r : *q) {
        ++s.waiting_pages;
        if (r.data && r.data.use_count() == 1) s.waiting_bytes_beside_l2 += r.data->size();
      }
    s.expired_waiting_pages = m.expired_waiting;
  }
  s.deferred_uploads = m.deferred.load();
  s.latency_p50_ms = m.latency.quantile_ms(0.5);
  s.latency_p99_ms = m.latency.quantile_ms(0.99);
}

CacheStats PageCache::stats(RecordKind kind) const {
  if (!holds(kind)) {
    CacheStats s;
    add_queue_stats(s);
    return s;
  }
  return kind_stats(*kinds_[size_t(kind)]);
}

CacheStats PageCache::stats() const {
  CacheStats total;
  size_t held = 0;
  for (const auto& k : kinds_) {
    if (!k) continue;
    ++held;
    const CacheStats s = kind_stats(*k);
    total.l1 += s.l1;
    total.l2 += s.l2;
    total.l3 += s.l3;
    total.l1_pool_bytes += s.l1_pool_bytes;
    total.l2_peak_bytes += s.l2_peak_bytes;
    total.l3_bytes_read += s.l3_bytes_read;
    total.l3_bytes_decoded += s.l3_bytes_decoded;
    total.l3_decode_seconds += s.l3_decode_seconds;
    total.constant_hits += s.constant_hits;
    total.uploads += s.uploads;
    total.stalls += s.stalls;
    total.failed_keys += s.failed_keys;
    total.kinds.emplace(k->kind, s);
  }
  if (held < 2) total.kinds.clear();
  add_queue_stats(total);
  return total;
}

namespace {
nlohmann::json stats_json(const CacheStats& s) {
  auto level = [](const CacheLevelStats& l) {
    return nlohmann::json{{"hits", l.hits},         {"misses", l.misses},
                          {"inserts", l.inserts},   {"evictions", l.evictions},
                          {"failed_evictions", l.failed_evictions},
                          {"resident", l.resident}, {"capacity", l.capacity},
                          {"metadata_bytes_per_entry", l.metadata_bytes_per_entry}};
  };
  nlohmann::json j = {{"l1", level(s.l1)},
                      {"l2", level(s.l2)},
                      {"l3", {{"reads", s.l3.hits}, {"records", s.l3.capacity}, {"bytes_read", s.l3_bytes_read},
                              {"bytes_decoded", s.l3_bytes_decoded}, {"decode_seconds", s.l3_decode_seconds}}},
                      {"l1_pool_bytes", s.l1_pool_bytes},
                      {"l2_peak_bytes", s.l2_peak_bytes},
                      {"constant_hits", s.constant_hits},
                      {"requests", s.requests},
                      {"merged_requests", s.merged_requests},
                      {"dropped_requests", s.dropped_requests},
                      {"queue_length", s.queue_length},
                      {"uploads", s.uploads},
                      {"deferred_uploads", s.deferred_uploads},
                      {"waiting_pages", s.waiting_pages},
                      {"waiting_bytes_beside_l2", s.waiting_bytes_beside_l2},
                      {"expired_waiting_pages", s.expired_waiting_pages},
                      {"stalls", s.stalls},
                      {"failed_keys", s.failed_keys},
                      {"latency_ms", {{"p50", s.latency_p50_ms}, {"p99", s.latency_p99_ms}}},
                      {"frames", s.frames}};
  if (!s.kinds.empty()) {
    nlohmann::json kinds = nlohmann::json::object();
    for (const auto& [kind, ks] : s.kinds) kinds[std::string(to_string(kind))] = stats_json(ks);
    j["kinds"] = kinds;
  }
  return j;
}
}  // namespace

std::string CacheStats::to_json() const { return stats_json(*this).dump(2); }

}  // namespace brickyard
