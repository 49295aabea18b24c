#pragma once
/// @file soak.h
/// @brief The memory soak (issue 42, item 5), shared by bench/bench_soak.cpp and its quick
/// ctest (tests/renderers/test_soak.cpp): one back end flies a random camera, a jump every
/// frame, over a store with small L1 and L2 budgets, and every frame the cache's resident
/// bytes and the process's RSS are sampled.
///
/// What is counted, per frame (SoakSample):
/// - data: L1 pages resident (slots in use x page size, every record kind), L2 bytes, decoded
///   pages waiting in the loader that L2 no longer holds (CacheStats::waiting_bytes_beside_l2),
///   and the back end's own page stores (gigavoxels' brick pool, which the session carves out
///   of the L1 budget; tet_bvh's cluster BVH cache);
/// - metadata: L1 and L2 entries in use times the cache's metadata bytes per entry;
/// - tables: what the store loads whole at open (node table, octree page table, cluster table).
/// The budget is L1 + L2 (+ tet_bvh's BVH cache budget, 1.5 x L1 by default). The fixed
/// overhead (SoakOverhead) is stated before the first frame: the tables, the metadata of a full
/// L1 and L2, one page per loader thread in flight (and, with an upload budget, one frame's
/// budget of decoded pages waiting beside L2), and the back end's fixed structures
/// (gigavoxels' node pool and per-pixel ray states). A frame passes when resident <= budget +
/// overhead. RSS (/proc/self/statm) is the independent check: its anonymous part (what the
/// process allocated) flat after warm-up; the file-backed part, the stores' memory maps, is
/// reported beside it.
///
/// Not counted: a handle's private copy when a blocking fetch found the pool pinned full
/// (PageHandle::owned_, released with the handle within the frame), frame buffers, TBB.

#include <malloc.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <functional>
#include <map>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "core/units.h"
#include "fields/random.h"
#include "renderers/common/metrics.h"
#include "renderers/common/scene.h"
#include "session/render_session.h"

namespace brickyard::soak {

/// @brief This process's resident memory (/proc/self/statm), in bytes: `anon` is what it
/// allocated (heap, pools, stacks), `file` the pages of mapped files, mostly the stores' LMDB
/// maps (clean page cache the kernel may drop, bounded by the store's size, not by a budget).
struct Rss {
  uint64_t anon = 0, file = 0;
  uint64_t total() const { return anon + file; }
};
inline Rss rss_now() {
  Rss r;
  std::FILE* f = std::fopen("/proc/self/statm", "r");
  if (!f) return r;
  unsigned long long size = 0, resident = 0, shared = 0;
  const int n = std::fscanf(f, "%llu %llu %llu", &size, &resident, &shared);
  std::fclose(f);
  if (n != 3) return r;
  const uint64_t page = uint64_t(::sysconf(_SC_PAGESIZE));
  r.anon = uint64_t(resident - std::min(resident, shared)) * page;
  r.file = uint64_t(shared) * page;
  return r;
}

/// @brief Bytes malloc has handed out and not had back, every arena and mmapped chunk
/// (mallinfo2): growth here is allocation, growth of RSS without it is fragmentation.
inline uint64_t heap_in_use() {
  const struct mallinfo2 m = ::mallinfo2();
  return uint64_t(m.uordblks) + uint64_t(m.hblkhd);
}

struct SoakOptions {
  std::string dataset;
  std::string backend;
  std::map<std::string, double> params;  ///< back-end parameters
  int frames = 2000;
  int size = 96;                         ///< image width and height
  uint64_t l1_bytes = uint64_t(16) << 20;
  uint64_t l2_bytes = uint64_t(64) << 20;
  int loader_threads = 2;
  uint32_t upload_pages_per_frame = 0;   ///< the cache's upload budget; 0: unlimited
  double lod_ratio = 0.1;                ///< small: level-of-detail back ends want fine levels (thrash)
  double isovalue = 0.5;                 ///< normalised to the dataset's value range
  uint64_t seed = 1;
  int warmup = 100;                      ///< the frame after which RSS must stay flat
  /// Zoom: the eye's distance from its target, log-uniform in [near, far] times the box's
  /// diagonal; the field of view uniform in [fov_lo, fov_hi] degrees.
  double near = 0.02, far = 2.5, fov_lo = 4, fov_hi = 75;
};

struct SoakSample {
  int frame = 0;
  double ms = 0;
  uint64_t l1_bytes = 0;      ///< cache L1 pages resident x page size
  uint64_t l1_slots = 0;      ///< cache L1 slots in use (every kind)
  uint64_t l2_bytes = 0;
  uint64_t waiting_bytes = 0;  ///< decoded pages waiting for an upload that L2 dropped
  uint64_t backend_bytes = 0;  ///< the back end's own page stores
  uint64_t metadata_bytes = 0;
  uint64_t resident = 0;       ///< everything above + the tables
  uint64_t rss = 0;            ///< anonymous RSS (Rss::anon)
  uint64_t rss_file = 0;       ///< file-backed RSS: the store's memory map
  uint64_t heap = 0;           ///< heap_in_use()
  uint64_t requests = 0;       ///< distinct requests this frame
  uint64_t uploads = 0;
  uint64_t l3_bytes_read = 0;  ///< so far
};

/// @brief The fixed overhead a soak allows above the budget, by part.
struct SoakOverhead {
  uint64_t tables = 0;          ///< node, octree page and cluster tables, loaded at open
  uint64_t metadata = 0;        ///< cache metadata of a full L1 and a full L2
  uint64_t loader = 0;          ///< one page per loader thread, and one upload budget's pages, beside L2 and L1
  uint64_t backend = 0;         ///< the back end's fixed structures
  std::string backend_what;
  uint64_t total() const { return tables + metadata + loader + backend; }
  std::string describe() const {
    return fmt::format("tables {} + cache metadata {} + loader {} + {} {}", format_bytes(double(tables)), format_bytes(double(metadata)),
                       format_bytes(double(loader)), backend_what.empty() ? "back end" : backend_what, format_bytes(double(backend)));
  }
};

struct SoakResult {
  std::string backend, dataset;
  uint64_t l1_budget = 0, l2_budget = 0, own_budget = 0;  ///< own: the back end's own cache (tet_bvh's BVHs)
  std::string own_what;
  SoakOverhead overhead;
  uint64_t l1_pool_bytes = 0;  ///< the cache's L1 pools as allocated (gigavoxels: beside its brick pool)
  uint64_t l2_peak = 0;        ///< the cache's own running peak of L2 bytes (intra-frame too)
  uint64_t peak_resident = 0;
  int peak_frame = 0;
  // Anonymous RSS (Rss::anon):
  uint64_t rss_start = 0;      ///< before the session
  int warm_frame = 0;          ///< `warmup`, or later: the first frame whose resident bytes reached 95% of their peak
  uint64_t rss_warm = 0;       ///< after frame warm_frame
  uint64_t rss_end = 0, rss_peak = 0;
  uint64_t rss_file_end = 0;   ///< file-backed RSS at the end (the store's map)
  uint64_t heap_warm = 0, heap_end = 0;  ///< heap_in_use() after warm_frame and at the end
  int frames = 0;
  int frames_over = 0;         ///< frames whose resident bytes exceeded budget + overhead
  int first_over = -1;
  double seconds = 0;
  double ms_median = 0, ms_p95 = 0;
  uint64_t l3_bytes_read = 0, l3_bytes_decoded = 0, l1_evictions = 0, l2_evictions = 0;
  uint64_t peak_waiting = 0;
  std::vector<SoakSample> samples;

  uint64_t budget() const { return l1_budget + l2_budget + own_budget; }
  uint64_t bound() const { return budget() + overhead.total(); }
  bool resident_ok() const { return frames_over == 0 && l2_peak <= l2_budget; }
  /// Anonymous RSS at the end no more than `slack` above RSS after the warm-up.
  bool rss_flat(uint64_t slack) const { return rss_end <= rss_warm + slack; }
};

/// @brief Frame f's camera: a random target in the box, a random direction, a random zoom.
inline Camera random_camera(SplitMix64& rng, const Box3d& box, const SoakOptions& o) {
  const Vec3d e = box.extent();
  const double diagonal = std::sqrt(dot(e, e));
  Camera c;
  c.target = box.lo + Vec3d(rng.uniform(), rng.uniform(), rng.uniform()) * e;
  const double z = rng.uniform(-1, 1), phi = rng.uniform(0, 2 * M_PI), r = std::sqrt(1 - z * z);
  const Vec3d dir(r * std::cos(phi), r * std::sin(phi), z);
  const double distance = diagonal * o.near * std::pow(o.far / o.near, rng.uniform());
  c.eye = c.target - dir * distance;
  c.up = std::abs(z) > 0.95 ? Vec3d(0, 1, 0) : Vec3d(0, 0, 1);
  c.fov_degrees = rng.uniform(o.fov_lo, o.fov_hi);
  return c;
}

inline Scene soak_scene(const SoakOptions& o) {
  const std::string text = fmt::format(
      R"({{"dataset": "{}", "backend": "{}", "image": {{"width": {}, "height": {}}}, "mode": "iso", "values": "normalized",
          "isosurfaces": [{{"value": {}}}], "shading": {{"light": "headlight"}}, "quality": {{"lod_ratio": {}}},
          "camera": {{"eye": [0.5, -1.5, 0.5], "target": [0.5, 0.5, 0.5]}}}})",
      o.dataset, o.backend, o.size, o.size, o.isovalue, o.lod_ratio);
  return parse_scene(text, "");
}

/// @brief A back end's figure of the frame, or -1 when it reports none of that name.
inline double figure(const FrameStats& st, const char* name) {
  for (const auto& [n, v] : st.backend)
    if (n == name) return v;
  return -1;
}

/// @brief Runs one soak; `on_frame` sees every sample as it is taken (a test asserts there).
inline SoakResult run_soak(const SoakOptions& o, const std::function<void(const SoakSample&, const SoakResult&)>& on_frame = {}) {
  SoakResult res;
  res.backend = o.backend;
  res.dataset = o.dataset;
  res.l1_budget = o.l1_bytes;
  res.l2_budget = o.l2_bytes;
  res.rss_start = rss_now().anon;
  const Scene scene = soak_scene(o);
  RenderSession::Options so;
  so.backend = o.backend;
  so.params = o.params;
  CacheConfig cc;
  cc.l1_slots = 0;
  cc.l1_bytes = o.l1_bytes;
  cc.l2_bytes = o.l2_bytes;
  cc.loader_threads = o.loader_threads;
  cc.upload_pages_per_frame = o.upload_pages_per_frame;
  so.cache = cc;
  RenderSession session(scene, so);
  PageCache& pages = session.pages();
  const Store& store = session.store();

  // The fixed overhead, before the first frame.
  SoakOverhead& ov = res.overhead;
  if (store.kind() == DataKind::structured) ov.tables += store.nodes().bytes();
  ov.tables += store.octree_pages().size() * sizeof(OctreePageRange);
  ov.tables += store.clusters().size() * sizeof(TetCluster) + store.step_ranges().size() * sizeof(TetStepRange);
  size_t max_page = 0;
  {
    const CacheStats s0 = pages.stats();
    for (RecordKind k : pages.kinds()) {
      const CacheStats s = pages.stats(k);
      const size_t page = pages.page_bytes(k);
      max_page = std::max(max_page, page);
      ov.metadata += uint64_t(double(s.l1.capacity) * s.l1.metadata_bytes_per_entry);
      ov.metadata += uint64_t(double(s.l2.capacity / page) * s.l2.metadata_bytes_per_entry);
      // A kind the back end does not read has a page of L1 and of L2 beyond the budgets
      // (RenderSession::build_cache): an octree beside a grid read by a brick back end.
      const auto& reads = session.backend().records;
      if (std::find(reads.begin(), reads.end(), k) == reads.end()) ov.tables += 2 * page;
    }
    res.l1_pool_bytes = s0.l1_pool_bytes;
  }
  // One page per loader thread in flight, and with an upload budget one frame's budget of
  // decoded pages waiting beside L2 (past it they wait only as L2's: PageCache::held_bytes).
  ov.loader = uint64_t(o.loader_threads + o.upload_pages_per_frame) * max_page;
  ov.backend = uint64_t(session.backend().pixel_state_bytes) * uint64_t(o.size) * uint64_t(o.size);
  if (ov.backend) ov.backend_what = "per-pixel ray states";

  SplitMix64 rng(o.seed);
  const Box3d box = session.context().geometry().world;
  FrameBuffers fb;
  std::vector<double> ms;
  const auto started = std::chrono::steady_clock::now();
  for (int f = 0; f < o.frames; ++f) {
    FrameSetup setup;
    setup.camera = random_camera(rng, box, o);
    setup.width = setup.height = o.size;
    setup.frame = f;
    const FrameStats st = session.render(setup, fb);

    SoakSample smp;
    smp.frame = f;
    smp.ms = st.seconds * 1e3;
    smp.requests = st.requests;
    smp.uploads = st.uploads;
    const CacheStats total = pages.stats();
    for (RecordKind k : pages.kinds()) {
      const CacheStats s = pages.stats(k);
      const size_t page = pages.page_bytes(k);
      smp.l1_slots += s.l1.resident;
      smp.l1_bytes += s.l1.resident * page;
      smp.l2_bytes += s.l2.resident;
      smp.metadata_bytes += uint64_t(double(s.l1.resident) * s.l1.metadata_bytes_per_entry) +
                            uint64_t(double(s.l2.resident / page) * s.l2.metadata_bytes_per_entry);
    }
    smp.waiting_bytes = total.waiting_bytes_beside_l2;
    smp.l3_bytes_read = total.l3_bytes_read;
    // The back ends' own stores, from their figures.
    if (const double pool = figure(st, "brick_pool_bytes"); pool >= 0) {
      smp.backend_bytes += uint64_t(pool);
      if (f == 0) {
        // gigavoxels: its brick pool is the L1 budget the cache's L1 left; its node pool
        // (64-bit nodes in blocks of N^3 = 8 for a store, with a parent index each) is fixed.
        ov.backend += uint64_t(std::max(0.0, figure(st, "node_blocks"))) * (8 * sizeof(uint64_t) + sizeof(uint32_t));
        ov.backend_what = ov.backend_what.empty() ? "node pool" : "node pool and " + ov.backend_what;
      }
    }
    if (const double bvh = figure(st, "bvh_bytes"); bvh >= 0) {
      // tet_bvh: cluster BVHs kept beside the cache, under their own budget (bvh_cache MiB, or
      // 1.5 x the L1 it has).
      smp.backend_bytes += uint64_t(bvh);
      if (f == 0) {
        const double mib = session.params()["bvh_cache"];
        const uint64_t l1 = uint64_t(pages.pool_slots(RecordKind::tet_cluster)) * pages.page_bytes(RecordKind::tet_cluster);
        res.own_budget = mib > 0 ? uint64_t(mib * double(1 << 20)) : l1 + l1 / 2;
        res.own_what = "BVH cache";
      }
    }
    smp.resident = smp.l1_bytes + smp.l2_bytes + smp.waiting_bytes + smp.backend_bytes + smp.metadata_bytes + ov.tables;
    const Rss rss = rss_now();
    smp.rss = rss.anon;
    smp.rss_file = rss.file;
    smp.heap = heap_in_use();

    res.peak_waiting = std::max(res.peak_waiting, smp.waiting_bytes);
    if (smp.resident > res.peak_resident) res.peak_resident = smp.resident, res.peak_frame = f;
    if (smp.resident > res.bound()) {
      if (res.first_over < 0) res.first_over = f;
      ++res.frames_over;
    }
    res.rss_peak = std::max(res.rss_peak, smp.rss);
    res.rss_end = smp.rss;
    res.heap_end = smp.heap;
    res.rss_file_end = smp.rss_file;
    ms.push_back(smp.ms);
    res.samples.push_back(smp);
    res.frames = f + 1;
    if (on_frame) on_frame(smp, res);
  }
  res.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  // Warm: after `warmup` frames and once the caches have filled (a back end that requests
  // within budgets of its own fills them over hundreds of frames).
  res.warm_frame = std::min(o.warmup, res.frames - 1);
  while (res.warm_frame + 1 < res.frames && res.samples[size_t(res.warm_frame)].resident * 20 < res.peak_resident * 19) ++res.warm_frame;
  res.rss_warm = res.samples[size_t(res.warm_frame)].rss;
  res.heap_warm = res.samples[size_t(res.warm_frame)].heap;
  const CacheStats s = pages.stats();
  res.l2_peak = s.l2_peak_bytes;
  res.l3_bytes_read = s.l3_bytes_read;
  res.l3_bytes_decoded = s.l3_bytes_decoded;
  res.l1_evictions = s.l1.evictions;
  res.l2_evictions = s.l2.evictions;
  res.ms_median = percentile(ms, 50);
  res.ms_p95 = percentile(ms, 95);  // percentile sorts: after the last use of the samples' order
  return res;
}

}  // namespace brickyard::soak
