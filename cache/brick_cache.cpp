#include "cache/brick_cache.h"

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

uint32_t slots_for(const CacheConfig& c, size_t brick_bytes) {
  const uint64_t slots = c.l1_slots ? c.l1_slots : c.l1_bytes / brick_bytes;
  if (slots == 0)
    throw Error(Errc::invalid_argument, fmt::format("the L1 budget of {} is smaller than one brick ({})",
                                                    format_bytes(double(c.l1_bytes)), format_bytes(double(brick_bytes))))
        .with_field("l1_bytes");
  if (slots > UINT32_MAX / 2) throw Error(Errc::invalid_argument, "too many L1 slots").with_field("l1_slots");
  return uint32_t(slots);
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
  void add(const BrickKey& key, uint32_t frame, uint32_t size, AccessKind kind, uint8_t hit_level) {
    const uint64_t seq = seq_.fetch_add(1, std::memory_order_relaxed);
    Stripe& s = stripes_[stripe_of_this_thread()];
    std::lock_guard lock(s.mutex);
    s.records.push_back({seq, {key.code(), frame, size, kind, hit_level, uint32_t(stripe_of_this_thread())}});
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

struct BrickCache::Impl {
  struct Pending {
    float priority;
    uint64_t frame;
    uint64_t requested_ns;
  };
  struct HeapEntry {
    float priority;
    uint64_t seq;
    uint64_t key;
    bool operator<(const HeapEntry& o) const {
      return priority != o.priority ? priority < o.priority : seq > o.seq;  // FIFO among equals
    }
  };
  struct Ready {
    uint64_t key;
    BrickBuffer data;
    uint64_t requested_ns;
    uint64_t ticket;  // which load of the key this is (ready_keys)
  };
  struct alignas(64) RequestStripe {
    std::mutex mutex;
    std::vector<BrickRequest> staged;
  };
  struct alignas(64) MarkStripe {
    std::mutex mutex;  // guards visible
    std::vector<std::pair<uint64_t, bool>> visible;
    // Counted on the hit path: relaxed atomics on a line that one thread mostly owns.
    std::atomic<uint64_t> lookups{0}, hits{0}, constant_hits{0};
  };

  // Loader queue. queue_mutex guards heap, pending, in_flight, ready, blocked, ready_keys,
  // failed, frame_requests, the request counters and every change to the per-frame upload
  // budget (frame_end() only reads it); the workers wait on work_cv, wait_idle() on idle_cv.
  mutable std::mutex queue_mutex;
  std::condition_variable work_cv, idle_cv;
  std::priority_queue<HeapEntry> heap;
  absl::flat_hash_map<uint64_t, Pending> pending;
  // Keys being read and decoded, or placed in the pool; a decoded key waits in ready as in
  // flight until its loader's drain_ready() returns, and after that as deferred.
  absl::flat_hash_set<uint64_t> in_flight;
  std::deque<Ready> ready;
  // Decoded bricks that no unpinned slot could take, tried again at the next frame_begin()
  // (pins are released between frames): once a frame each, not at every drain.
  std::deque<Ready> blocked;
  // The keys of ready and blocked (decoded, waiting for an upload budget or a slot) and their
  // loads' tickets: requests for them are merged, and a loader leaves in_flight only for its
  // own load of a key.
  absl::flat_hash_map<uint64_t, uint64_t> ready_keys;
  uint64_t next_ticket = 1;  // 0: no load queued
  absl::flat_hash_map<uint64_t, std::string> failed;
  absl::flat_hash_map<uint64_t, float> this_frame_requests;
  std::vector<BrickRequest> last_frame_requests;
  uint64_t seq = 0;
  uint64_t requests = 0, merged = 0, dropped = 0, frame_dropped = 0;
  bool stop = false;

  RequestStripe request_stripes[kStripes];
  MarkStripe mark_stripes[kStripes];

  mutable std::shared_mutex visibility_mutex;
  absl::flat_hash_map<uint64_t, bool> visibility;

  std::atomic<uint64_t> frame{0};
  std::atomic<uint64_t> frame_uploads{0}, frame_upload_bytes{0};
  std::atomic<uint64_t> uploads{0}, deferred{0}, stalls{0};
  std::atomic<uint64_t> l3_reads{0}, l3_bytes_read{0}, l3_bytes_decoded{0}, l3_decode_ns{0};
  uint64_t frames_done = 0;
  LatencyHistogram latency;
  std::unique_ptr<TraceRecorder> trace;
  std::vector<std::thread> workers;
};

// ---------------------------------------------------------------------------------------------

BrickHandle& BrickHandle::operator=(BrickHandle&& o) noexcept {
  if (this != &o) {
    release();
    cache_ = o.cache_;
    state_ = o.state_;
    key_ = o.key_;
    slot_ = o.slot_;
    data_ = o.data_;
    owned_ = std::move(o.owned_);
    min_ = o.min_;
    max_ = o.max_;
    constant_ = o.constant_;
    error_ = std::move(o.error_);
    o.cache_ = nullptr;
    o.slot_ = kNoSlot;
    o.state_ = State::miss;
    o.data_ = nullptr;
  }
  return *this;
}

void BrickHandle::release() {
  if (cache_ && slot_ != kNoSlot) cache_->unpin(slot_);
  cache_ = nullptr;
  slot_ = kNoSlot;
  data_ = nullptr;
  owned_.reset();
  if (state_ == State::resident) state_ = State::miss;
}

// ---------------------------------------------------------------------------------------------

BrickCache::BrickCache(const BrickStore& store, const CacheConfig& config)
    : store_(store),
      config_(config),
      brick_bytes_(store.format().bytes()),
      slots_(slots_for(config, store.format().bytes()), config.l1_policy),
      // Value-initialised: the pool is faulted in (and its memory committed) once, up front, as a
      // fixed GPU pool would be, not page by page inside the first frames' uploads.
      pool_(new std::byte[size_t(slots_for(config, store.format().bytes())) * store.format().bytes()]()),
      l2_(config.l2_bytes, store.format().bytes(), config.l2_policy),
      impl_(std::make_unique<Impl>()) {
  if (config.loader_threads < 1 || config.loader_threads > 256)
    throw Error(Errc::invalid_argument, fmt::format("{} loader threads (need 1 to 256)", config.loader_threads))
        .with_field("loader_threads");
  if (!config.trace_path.empty()) impl_->trace = std::make_unique<TraceRecorder>(config.trace_path);

  for (int t = 0; t < config.loader_threads; ++t) impl_->workers.emplace_back([this] { worker_loop(); });
}

void BrickCache::worker_loop() {
  Impl& m = *impl_;
  auto txn = store_.begin_read();  // one snapshot per worker: the store is immutable
  while (true) {
    uint64_t key = 0, requested_ns = 0;
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
    // Step 1: L2, else read and decode from the store (outside every lock).
    const BrickKey k = BrickKey::from_code(key);
    std::string error;
    BrickBuffer data;
    if (!slots_.resident_or_reserved(key)) {  // else placed, or being placed by a blocking fetch
      data = l2_.find(key);
      if (!data) {
        try {
          data = load_from_store(txn, k);
        } catch (const Error& e) {
          error = e.what();
        }
      }
    }
    // Step 2: hand the brick to the upload queue, and upload what the budget allows. It stays
    // in flight until it is placed (by whichever thread drains it) or left for a later frame's
    // budget: until then wait_idle() must not return, nor a renewed request queue it again.
    uint64_t ticket = 0;  // none queued
    {
      std::lock_guard lock(m.queue_mutex);
      if (!error.empty()) m.failed.emplace(key, error);
      if (data) {
        ticket = m.next_ticket++;
        m.ready.push_back({key, std::move(data), requested_ns, ticket});
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

bool BrickCache::idle_locked() const { return impl_->pending.empty() && impl_->in_flight.empty(); }

void BrickCache::notify_if_idle_locked() {
  if (idle_locked()) impl_->idle_cv.notify_all();
}

BrickBuffer BrickCache::load_from_store(const lmdb::ReadTxn& txn, const BrickKey& key) {
  Impl& m = *impl_;
  try {
    auto record = store_.record(txn, key);
    if (!record) throw Error(Errc::corrupt, "brick record is missing").with_key(key.to_string());
    Stopwatch watch;
    auto buffer = std::make_shared<std::vector<std::byte>>(brick_bytes_);
    decode_brick(store_.format(), key, *record, *buffer);
    m.l3_decode_ns.fetch_add(uint64_t(watch.nanoseconds()), std::memory_order_relaxed);
    m.l3_reads.fetch_add(1, std::memory_order_relaxed);
    m.l3_bytes_read.fetch_add(record->size(), std::memory_order_relaxed);
    m.l3_bytes_decoded.fetch_add(brick_bytes_, std::memory_order_relaxed);
    BrickBuffer data = std::move(buffer);
    l2_.insert(key.code(), data);
    return data;
  } catch (Error& e) {
    if (e.file().empty()) e.with_file(store_.path());
    throw;
  }
}

void BrickCache::drain_ready() {
  Impl& m = *impl_;
  const uint64_t brick_limit = config_.upload_bricks_per_frame, byte_limit = config_.upload_bytes_per_frame;
  while (true) {
    Impl::Ready r;
    uint64_t claimed_in = 0;  // the frame whose budget this brick claimed
    {
      std::lock_guard lock(m.queue_mutex);
      if (m.ready.empty()) break;
      if (!claim_budget(m.frame_uploads, 1, brick_limit)) break;
      if (!claim_budget(m.frame_upload_bytes, brick_bytes_, byte_limit)) {
        m.frame_uploads.fetch_sub(1);
        break;
      }
      // A claim outlived by frame_begin() is charged to no frame: a frame may place one brick
      // more than its limit for each drain under way as it begins.
      claimed_in = m.frame.load();
      r = std::move(m.ready.front());
      m.ready.pop_front();
      m.ready_keys.erase(r.key);
      m.in_flight.insert(r.key);  // being placed (a brick deferred earlier had left it)
    }
    const uint32_t slot = slots_.reserve(r.key);
    if (slot == kNoSlot) {
      // Placed, or being placed, by another thread (a blocking fetch won the race): dropped.
      // Or every slot of its shard is pinned: blocked until the next frame, while the bricks
      // behind it are placed. Either way the budget goes back, unless frame_begin() has
      // renewed it since.
      const bool placed_elsewhere = slots_.resident_or_reserved(r.key);
      std::lock_guard lock(m.queue_mutex);
      if (m.frame.load() == claimed_in) {
        m.frame_uploads.fetch_sub(1);
        m.frame_upload_bytes.fetch_sub(brick_bytes_);
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
    std::memcpy(pool_.get() + size_t(slot) * brick_bytes_, r.data->data(), brick_bytes_);
    slots_.publish(slot);
    m.uploads.fetch_add(1, std::memory_order_relaxed);
    m.latency.add(double(now_ns() - r.requested_ns) * 1e-9);
    if (m.trace)
      m.trace->add(BrickKey::from_code(r.key), uint32_t(m.frame.load()), uint32_t(brick_bytes_), AccessKind::prefetch_fill, 2);
    std::lock_guard lock(m.queue_mutex);  // counted, then out of flight: wait_idle() sees both
    m.in_flight.erase(r.key);
    notify_if_idle_locked();
  }
}

BrickCache::~BrickCache() {
  {
    std::lock_guard lock(impl_->queue_mutex);
    impl_->stop = true;
  }
  impl_->work_cv.notify_all();
  for (auto& t : impl_->workers) t.join();
  if (impl_->trace) {
    try {
      impl_->trace->write();
    } catch (...) {
      // A destructor must not throw; the trace is lost, the data is not.
    }
  }
}

uint64_t BrickCache::frame() const { return impl_->frame.load(); }

BrickHandle BrickCache::make_handle(const BrickKey& key, BrickHandle::State state) const {
  BrickHandle h;
  h.key_ = key;
  h.state_ = state;
  const NodeRecord& n = store_.nodes().at(key);
  h.min_ = n.min;
  h.max_ = n.max;
  h.constant_ = n.constant;
  return h;
}


BrickHandle BrickCache::lookup(const BrickKey& key, float priority, bool request_on_miss) {
  Impl& m = *impl_;
  if (!store_.layout().contains(key)) {
    BrickHandle h;
    h.key_ = key;
    h.state_ = BrickHandle::State::failed;
    h.error_ = fmt::format("{}: key {}: brick is outside the store's {} levels", store_.path(), key.to_string(),
                           store_.layout().levels);
    return h;
  }
  auto& stripe = m.mark_stripes[stripe_of_this_thread()];
  const NodeRecord& node = store_.nodes().at(key);
  if (node.is_constant()) {
    stripe.lookups.fetch_add(1, std::memory_order_relaxed);
    stripe.hits.fetch_add(1, std::memory_order_relaxed);
    stripe.constant_hits.fetch_add(1, std::memory_order_relaxed);
    return make_handle(key, BrickHandle::State::constant);
  }
  const uint64_t code = key.code();
  const uint32_t slot = slots_.lookup_and_pin(code);
  stripe.lookups.fetch_add(1, std::memory_order_relaxed);
  if (slot != kNoSlot) stripe.hits.fetch_add(1, std::memory_order_relaxed);
  if (m.trace) m.trace->add(key, uint32_t(m.frame.load()), uint32_t(brick_bytes_), AccessKind::demand, slot != kNoSlot ? 1 : 0);
  if (slot != kNoSlot) {
    BrickHandle h = make_handle(key, BrickHandle::State::resident);
    h.cache_ = this;
    h.slot_ = slot;
    h.data_ = slot_data(slot);
    return h;
  }
  {
    std::lock_guard lock(m.queue_mutex);
    if (auto f = m.failed.find(code); f != m.failed.end()) {
      BrickHandle h = make_handle(key, BrickHandle::State::failed);
      h.error_ = f->second;
      return h;
    }
  }
  if (request_on_miss) request(key, priority);
  return make_handle(key, BrickHandle::State::miss);
}

void BrickCache::request(const BrickKey& key, float priority) {
  if (!store_.layout().contains(key) || store_.nodes().at(key).is_constant()) return;
  Impl& m = *impl_;
  if (m.trace) m.trace->add(key, uint32_t(m.frame.load()), uint32_t(brick_bytes_), AccessKind::prefetch_request, 0);
  auto& s = m.request_stripes[stripe_of_this_thread()];
  std::vector<BrickRequest> batch;
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

std::vector<BrickRequest> BrickCache::take_staged() {
  std::vector<BrickRequest> staged;
  for (auto& s : impl_->request_stripes) {
    std::lock_guard lock(s.mutex);
    staged.insert(staged.end(), s.staged.begin(), s.staged.end());
    s.staged.clear();
  }
  return staged;
}

void BrickCache::enqueue_locked(const std::vector<BrickRequest>& batch) {
  Impl& m = *impl_;
  const uint64_t frame = m.frame.load();
  const uint64_t now = now_ns();
  for (const auto& r : batch) {
    const uint64_t code = r.key.code();
    auto [best, fresh] = m.this_frame_requests.try_emplace(code, r.priority);
    if (!fresh) best->second = std::max(best->second, r.priority);
    if (m.failed.contains(code)) continue;  // failed once: never retried
    if (auto it = m.pending.find(code); it != m.pending.end()) {
      ++m.merged;
      it->second.frame = frame;
      if (r.priority > it->second.priority) {
        it->second.priority = r.priority;
        m.heap.push({r.priority, m.seq++, code});
      }
      continue;
    }
    if (m.in_flight.contains(code) || m.ready_keys.contains(code) || slots_.resident_or_reserved(code)) {
      ++m.merged;
      continue;
    }
    ++m.requests;
    m.pending.emplace(code, Impl::Pending{r.priority, frame, now});
    m.heap.push({r.priority, m.seq++, code});
  }
}

BrickHandle BrickCache::fetch(const BrickKey& key) {
  Impl& m = *impl_;
  if (!store_.layout().contains(key))
    throw Error(Errc::not_found, fmt::format("brick is outside the store's {} levels", store_.layout().levels))
        .with_file(store_.path())
        .with_key(key.to_string());
  if (store_.nodes().at(key).is_constant()) return make_handle(key, BrickHandle::State::constant);
  const uint64_t code = key.code();
  if (const uint32_t slot = slots_.lookup_and_pin(code); slot != kNoSlot) {
    if (m.trace) m.trace->add(key, uint32_t(m.frame.load()), uint32_t(brick_bytes_), AccessKind::blocking, 1);
    return resident_handle(key, slot);
  }
  {
    std::lock_guard lock(m.queue_mutex);
    if (auto f = m.failed.find(code); f != m.failed.end()) throw Error(Errc::corrupt, f->second);
  }
  m.stalls.fetch_add(1, std::memory_order_relaxed);
  const uint64_t started = now_ns();
  BrickBuffer data = l2_.find(code);
  uint8_t level = 2;
  if (!data) {
    level = 3;
    try {
      data = load_from_store(store_.begin_read(), key);
    } catch (const Error& e) {
      std::lock_guard lock(m.queue_mutex);
      m.failed.emplace(code, e.what());
      throw;
    }
  }
  if (m.trace) m.trace->add(key, uint32_t(m.frame.load()), uint32_t(brick_bytes_), AccessKind::blocking, level);
  // Into the pool, pinned for the caller. Another thread may be placing the same brick: then
  // use its slot once published, or keep a private copy rather than wait.
  const uint32_t slot = slots_.reserve(code);
  if (slot != kNoSlot) {
    std::memcpy(pool_.get() + size_t(slot) * brick_bytes_, data->data(), brick_bytes_);
    slots_.publish(slot, 1);
    m.uploads.fetch_add(1, std::memory_order_relaxed);
    m.latency.add(double(now_ns() - started) * 1e-9);
    return resident_handle(key, slot);
  }
  if (const uint32_t s = slots_.lookup_and_pin(code); s != kNoSlot) return resident_handle(key, s);
  BrickHandle r = make_handle(key, BrickHandle::State::resident);
  r.owned_ = data;
  r.data_ = data->data();
  return r;
}

void BrickCache::mark_used(const BrickKey& key) { slots_.touch(key.code()); }

void BrickCache::mark_visible(const BrickKey& key, bool visible) {
  auto& s = impl_->mark_stripes[stripe_of_this_thread()];
  std::lock_guard lock(s.mutex);
  s.visible.emplace_back(key.code(), visible);
}

std::optional<bool> BrickCache::visibility(const BrickKey& key) const {
  std::shared_lock lock(impl_->visibility_mutex);
  auto it = impl_->visibility.find(key.code());
  if (it == impl_->visibility.end()) return std::nullopt;
  return it->second;
}

void BrickCache::frame_begin() {
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
  slots_.frame(f);
  drain_ready();  // bricks the last frame's budget or pins deferred
}

FrameReport BrickCache::frame_end() {
  Impl& m = *impl_;
  FrameReport report;
  report.frame = m.frame.load();
  // Step 1: staged requests reach the loader; requests not renewed this frame are dropped.
  const std::vector<BrickRequest> staged = take_staged();
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
    for (const auto& [code, priority] : m.this_frame_requests)
      m.last_frame_requests.push_back({BrickKey::from_code(code), priority});
    m.this_frame_requests.clear();
    ++m.frames_done;
  }
  m.work_cv.notify_all();
  std::sort(m.last_frame_requests.begin(), m.last_frame_requests.end(), [](const BrickRequest& a, const BrickRequest& b) {
    return a.priority != b.priority ? a.priority > b.priority : a.key < b.key;
  });
  // Step 2: visibility marks become readable.
  {
    std::unique_lock vlock(m.visibility_mutex);
    for (auto& s : m.mark_stripes) {
      std::lock_guard lock(s.mutex);
      for (const auto& [code, visible] : s.visible) m.visibility[code] = visible;
      s.visible.clear();
      report.lookups += s.lookups.exchange(0, std::memory_order_relaxed);
      report.hits += s.hits.exchange(0, std::memory_order_relaxed);
    }
  }
  report.uploads = m.frame_uploads.load();
  report.upload_bytes = m.frame_upload_bytes.load();
  return report;
}

std::vector<BrickRequest> BrickCache::frame_requests() const {
  std::lock_guard lock(impl_->queue_mutex);
  return impl_->last_frame_requests;
}

void BrickCache::wait_idle() {
  Impl& m = *impl_;
  const std::vector<BrickRequest> staged = take_staged();
  {
    std::lock_guard lock(m.queue_mutex);
    enqueue_locked(staged);
  }
  m.work_cv.notify_all();
  std::unique_lock lock(m.queue_mutex);
  m.idle_cv.wait(lock, [&] { return idle_locked(); });
}

BrickHandle BrickCache::resident_handle(const BrickKey& key, uint32_t slot) {
  BrickHandle h = make_handle(key, BrickHandle::State::resident);
  h.cache_ = this;
  h.slot_ = slot;
  h.data_ = slot_data(slot);
  return h;
}

CacheStats BrickCache::stats() const {
  const Impl& m = *impl_;
  CacheStats s;
  const SlotCounters c1 = slots_.counters();
  s.l1 = {c1.hits, c1.misses, c1.inserts, c1.evictions, c1.failed_evictions, slots_.resident(), slots_.capacity(),
          slots_.metadata_bytes_per_entry()};
  const SlotCounters c2 = l2_.counters();
  s.l2 = {c2.hits, c2.misses, c2.inserts, c2.evictions, c2.failed_evictions, l2_.resident_bytes(), l2_.budget(),
          l2_.metadata_bytes_per_entry()};
  s.l3.hits = m.l3_reads.load();
  s.l3.resident = s.l3.capacity = store_.layout().total_bricks();
  s.l1_pool_bytes = uint64_t(slots_.capacity()) * brick_bytes_;
  s.l2_peak_bytes = l2_.peak_bytes();
  s.l3_bytes_read = m.l3_bytes_read.load();
  s.l3_bytes_decoded = m.l3_bytes_decoded.load();
  s.l3_decode_seconds = double(m.l3_decode_ns.load()) * 1e-9;
  for (const auto& stripe : m.mark_stripes) s.constant_hits += stripe.constant_hits.load(std::memory_order_relaxed);
  {
    std::lock_guard lock(m.queue_mutex);
    s.requests = m.requests;
    s.merged_requests = m.merged;
    s.dropped_requests = m.dropped;
    s.queue_length = m.pending.size();
    s.failed_keys = m.failed.size();
    s.frames = m.frames_done;
  }
  s.uploads = m.uploads.load();
  s.deferred_uploads = m.deferred.load();
  s.stalls = m.stalls.load();
  s.latency_p50_ms = m.latency.quantile_ms(0.5);
  s.latency_p99_ms = m.latency.quantile_ms(0.99);
  return s;
}

std::string CacheStats::to_json() const {
  auto level = [](const CacheLevelStats& l) {
    return nlohmann::json{{"hits", l.hits},         {"misses", l.misses},
                          {"inserts", l.inserts},   {"evictions", l.evictions},
                          {"failed_evictions", l.failed_evictions},
                          {"resident", l.resident}, {"capacity", l.capacity},
                          {"metadata_bytes_per_entry", l.metadata_bytes_per_entry}};
  };
  nlohmann::json j = {{"l1", level(l1)},
                      {"l2", level(l2)},
                      {"l3", {{"reads", l3.hits}, {"records", l3.capacity}, {"bytes_read", l3_bytes_read},
                              {"bytes_decoded", l3_bytes_decoded}, {"decode_seconds", l3_decode_seconds}}},
                      {"l1_pool_bytes", l1_pool_bytes},
                      {"l2_peak_bytes", l2_peak_bytes},
                      {"constant_hits", constant_hits},
                      {"requests", requests},
                      {"merged_requests", merged_requests},
                      {"dropped_requests", dropped_requests},
                      {"queue_length", queue_length},
                      {"uploads", uploads},
                      {"deferred_uploads", deferred_uploads},
                      {"stalls", stalls},
                      {"failed_keys", failed_keys},
                      {"latency_ms", {{"p50", latency_p50_ms}, {"p99", latency_p99_ms}}},
                      {"frames", frames}};
  return j.dump(2);
}

NodePool::NodePool(uint32_t slots, size_t record_bytes, const std::string& policy)
    : record_bytes_(record_bytes), slots_(slots, policy), records_(size_t(slots) * record_bytes) {
  if (record_bytes == 0) throw Error(Errc::invalid_argument, "node records need at least one byte").with_field("record_bytes");
}

}  // namespace brickyard
