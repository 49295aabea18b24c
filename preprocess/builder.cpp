#include "preprocess/builder.h"

#include <algorithm>
#include <cerrno>
#include <atomic>
#include <cfloat>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <cstring>
#include <deque>
#include <filesystem>
#include <limits>
#include <mutex>
#include <thread>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/task_arena.h>

#include "core/error.h"
#include "core/raw_volume.h"
#include "core/parallel.h"
#include "core/progress.h"
#include "core/timing.h"
#include "preprocess/background.h"
#include "preprocess/build_context.h"
#include "preprocess/build_state.h"
#include "preprocess/record_writer.h"
#include "preprocess/box_filter.h"
#include "preprocess/volume_source.h"
#include "storage/store.h"

namespace brickyard {

std::string_view to_string(Downsample d) {
  switch (d) {
    case Downsample::average: return "average";
    case Downsample::min: return "min";
    case Downsample::max: return "max";
  }
  return "?";
}

std::string_view to_string(NonFinite n) {
  switch (n) {
    case NonFinite::reject: return "reject";
    case NonFinite::zero: return "zero";
    case NonFinite::clamp: return "clamp";
  }
  return "?";
}

Downsample parse_downsample(std::string_view s) {
  if (s == "average") return Downsample::average;
  if (s == "min") return Downsample::min;
  if (s == "max") return Downsample::max;
  throw Error(Errc::invalid_argument, fmt::format("unknown filter '{}' (expected auto, average, min or max)", s))
      .with_field("--downsample");
}

NonFinite parse_nonfinite(std::string_view s) {
  if (s == "reject") return NonFinite::reject;
  if (s == "zero") return NonFinite::zero;
  if (s == "clamp") return NonFinite::clamp;
  throw Error(Errc::invalid_argument, fmt::format("unknown repair '{}' (expected reject, zero or clamp)", s))
      .with_field("--nonfinite");
}

namespace {

using build_detail::BuildContext;
using build_detail::RecordWriter;
using build_detail::SeriesState;
using build_detail::add_step;
using build_detail::check_series;
using build_detail::series_source_json;
using build_detail::summarise;

// One level of the pyramid: a ring of slices, row-by-row brick output, and the 2x filter that
// feeds the next coarser level.
template <typename T>
class Level {
 public:
  Level(BuildContext& ctx, int level, Level* coarser)
      : ctx_(ctx), level_(level), coarser_(coarser), dims_(ctx.layout.level_dims(level)),
        bricks_(ctx.layout.level_bricks(level)), M_(ctx.format.brick_size), A_(ctx.format.apron),
        forward_(std::max(A_, 1)), capacity_(M_ + A_ + forward_) {
    ring_.resize(size_t(capacity_));
    for (auto& s : ring_) s.resize(size_t(dims_.x * dims_.y));
  }

  int64_t slice_voxels() const { return dims_.x * dims_.y; }
  /// The slot the next slice must be written into.
  T* next_slot() { return ring_[size_t(received_ % capacity_)].data(); }

  /// The slice in next_slot() is complete.
  void commit() {
    const int64_t z = received_++;
    if (coarser_ && (z & 1)) downsample(slice(z - 1), slice(z));
    while (next_row_ < bricks_.z && row_ready(next_row_)) process_row(next_row_++);
  }

  int64_t rows_done() const { return next_row_; }

  /// Its part of a checkpoint: the counters and the slices later rows and the coarser level
  /// still read, [next row's first slice - A, received), at most the ring's capacity.
  void save(StateWriter& w) const {
    const int64_t first = std::clamp<int64_t>(next_row_ * M_ - A_, 0, std::max<int64_t>(0, received_ - 1));
    w.put(received_), w.put(next_row_), w.put(first);
    for (int64_t z = first; z < received_; ++z)
      w.put_bytes({reinterpret_cast<const std::byte*>(slice(z)), size_t(slice_voxels()) * sizeof(T)});
  }
  void restore(StateReader& r) {
    received_ = r.get<int64_t>(), next_row_ = r.get<int64_t>();
    const int64_t first = r.get<int64_t>();
    if (received_ < 0 || received_ > dims_.z || next_row_ < 0 || next_row_ > bricks_.z || first < 0 || first > received_ ||
        received_ - first > capacity_)
      throw Error(Errc::corrupt, "the build checkpoint's level state does not fit the volume");
    for (int64_t z = first; z < received_; ++z)
      std::memcpy(ring_[size_t(z % capacity_)].data(), r.take(size_t(slice_voxels()) * sizeof(T)).data(),
                  size_t(slice_voxels()) * sizeof(T));
  }

  /// End of input: flushes the last odd slice and the remaining rows, then the coarser levels.
  void finish() {
    BY_CHECK_EQ(received_, dims_.z);
    if (coarser_ && (dims_.z & 1)) downsample(slice(dims_.z - 1), slice(dims_.z - 1));
    while (next_row_ < bricks_.z) process_row(next_row_++);
    if (coarser_) coarser_->finish();
  }

 private:
  const T* slice(int64_t z) const {
    z = std::clamp<int64_t>(z, 0, dims_.z - 1);
    return ring_[size_t(z % capacity_)].data();
  }

  bool row_ready(int64_t r) const { return received_ >= std::min<int64_t>((r + 1) * M_ + forward_, dims_.z); }

  void downsample(const T* s0, const T* s1) {
    T* out = coarser_->next_slot();
    const Vec3s cd = coarser_->dims_;
    const int64_t dx = dims_.x, dy = dims_.y;
    const Downsample mode = ctx_.downsample;
    parallel_for<int64_t>(0, cd.y, 8, [&](int64_t j0, int64_t j1) {
      for (int64_t j = j0; j < j1; ++j) {
        const int64_t y0 = 2 * j, y1 = std::min(2 * j + 1, dy - 1);
        T* dst = out + j * cd.x;
        for (int64_t i = 0; i < cd.x; ++i) {
          const int64_t x0 = 2 * i, x1 = std::min(2 * i + 1, dx - 1);
          const T v[8] = {s0[y0 * dx + x0], s0[y0 * dx + x1], s0[y1 * dx + x0], s0[y1 * dx + x1],
                          s1[y0 * dx + x0], s1[y0 * dx + x1], s1[y1 * dx + x0], s1[y1 * dx + x1]};
          dst[i] = filter_8(v, mode);
        }
      }
    });
    coarser_->commit();
  }

  void process_row(int64_t r) {
    const int64_t n = bricks_.x * bricks_.y;
    std::vector<std::vector<std::byte>> records(static_cast<size_t>(n));
    parallel_for<int64_t>(0, n, 1, [&](int64_t b0, int64_t b1) {
      for (int64_t b = b0; b < b1; ++b) records[size_t(b)] = process_brick(b % bricks_.x, b / bricks_.x, r);
    });
    for (int64_t b = 0; b < n; ++b)
      if (!records[size_t(b)].empty())
        ctx_.writer->push({uint32_t(level_), uint32_t(b % bricks_.x), uint32_t(b / bricks_.x), uint32_t(r)},
                          std::move(records[size_t(b)]));
  }

  std::vector<std::byte> process_brick(int64_t bx, int64_t by, int64_t bz) {
    const int G = M_ + A_ + forward_;  // gathered edge: payload plus the forward neighbours
    const int E = M_ + 2 * A_;         // payload edge
    thread_local std::vector<T> gathered, payload_buffer;
    gathered.resize(size_t(G) * G * G);
    const int64_t x0 = bx * M_ - A_, y0 = by * M_ - A_, z0 = bz * M_ - A_;

    // Step 1: gather with replicated borders.
    const int lx_lo = int(std::clamp<int64_t>(-x0, 0, G));
    const int lx_hi = int(std::clamp<int64_t>(dims_.x - x0, lx_lo, G));
    for (int lz = 0; lz < G; ++lz) {
      const T* s = slice(z0 + lz);
      for (int ly = 0; ly < G; ++ly) {
        const T* row = s + std::clamp<int64_t>(y0 + ly, 0, dims_.y - 1) * dims_.x;
        T* dst = gathered.data() + (size_t(lz) * G + ly) * G;
        for (int lx = 0; lx < lx_lo; ++lx) dst[lx] = row[0];
        if (lx_hi > lx_lo) std::memcpy(dst + lx_lo, row + x0 + lx_lo, size_t(lx_hi - lx_lo) * sizeof(T));
        for (int lx = lx_hi; lx < G; ++lx) dst[lx] = row[dims_.x - 1];
      }
    }
    const T* payload = gathered.data();
    if (G != E) {  // no apron: the payload is the leading E^3 corner of the gather
      payload_buffer.resize(size_t(E) * E * E);
      for (int lz = 0; lz < E; ++lz)
        for (int ly = 0; ly < E; ++ly)
          std::memcpy(payload_buffer.data() + (size_t(lz) * E + ly) * E, gathered.data() + (size_t(lz) * G + ly) * G,
                      size_t(E) * sizeof(T));
      payload = payload_buffer.data();
    }

    // Step 2: value ranges, of the payload (record header) and of the node's trilinear cells.
    const size_t voxels = size_t(E) * E * E;
    T pmin = payload[0], pmax = payload[0];
    for (size_t i = 1; i < voxels; ++i) {
      pmin = std::min(pmin, payload[i]);
      pmax = std::max(pmax, payload[i]);
    }
    const int nx = int(std::min<int64_t>(M_, dims_.x - 1 - bx * M_)), ny = int(std::min<int64_t>(M_, dims_.y - 1 - by * M_)),
              nz = int(std::min<int64_t>(M_, dims_.z - 1 - bz * M_));
    T nmin = std::numeric_limits<T>::max(), nmax = std::numeric_limits<T>::lowest();
    for (int lz = A_; lz <= A_ + nz; ++lz)
      for (int ly = A_; ly <= A_ + ny; ++ly) {
        const T* row = gathered.data() + (size_t(lz) * G + ly) * G;
        for (int lx = A_; lx <= A_ + nx; ++lx) {
          nmin = std::min(nmin, row[lx]);
          nmax = std::max(nmax, row[lx]);
        }
      }

    // Step 3: the finest level's histogram, each voxel counted once (interiors only).
    if (level_ == ctx_.layout.finest()) count_histogram(gathered.data(), G, bx, by, bz);

    // Step 4: node record, and the payload unless the brick is constant.
    const BrickKey key{uint32_t(level_), uint32_t(bx), uint32_t(by), uint32_t(bz)};
    NodeRecord& node = ctx_.nodes.at(key);
    node.min = float(nmin);
    node.max = float(nmax);
    node.flags = level_ == ctx_.layout.finest() ? kNodeFinest : kNodeHasChildren;
    auto& stats = ctx_.stats[size_t(level_)];
    std::optional<T> constant;
    bool empty = false;
    const double lo = double(pmin), hi = double(pmax), bg = ctx_.background, tol = ctx_.tolerance;
    if (hi - lo == 0) {  // not for infinities (inf - inf is NaN): an overflowed average stays data
      constant = pmin;
      empty = std::abs(lo - bg) <= tol;
    } else if (ctx_.flatten_background_only) {
      // Noise around the background (CT air, padding) becomes empty space; data stays exact.
      if (std::max(std::abs(hi - bg), std::abs(lo - bg)) <= tol) constant = round_to<T>(bg), empty = true;
    } else if (hi - lo <= tol) {
      constant = round_to<T>((lo + hi) / 2);
      empty = std::abs(double(*constant) - bg) <= tol;
    }
    if (constant) {
      // The range stays the data's (conservative for the neighbours' cells) and covers the value.
      node.constant = float(*constant);
      node.min = std::min(node.min, node.constant), node.max = std::max(node.max, node.constant);
      node.flags |= kNodeConstant;
      stats.constant.fetch_add(1, std::memory_order_relaxed);
      if (empty) {
        node.flags |= kNodeEmpty;
        stats.empty.fetch_add(1, std::memory_order_relaxed);
      }
      return {};
    }
    auto record = encode_brick(ctx_.format, key,
                               {reinterpret_cast<const std::byte*>(payload), voxels * sizeof(T)}, float(pmin), float(pmax));
    stats.raw_bytes.fetch_add(voxels * sizeof(T), std::memory_order_relaxed);
    stats.stored_bytes.fetch_add(record.size(), std::memory_order_relaxed);
    return record;
  }

  void count_histogram(const T* gathered, int G, int64_t bx, int64_t by, int64_t bz) {
    // Interior voxels of this brick: [b*M, min((b+1)*M, dims)) along each axis.
    const int ex = int(std::min<int64_t>(M_, dims_.x - bx * M_)), ey = int(std::min<int64_t>(M_, dims_.y - by * M_)),
              ez = int(std::min<int64_t>(M_, dims_.z - bz * M_));
    auto& h = ctx_.histograms.local();
    if (h.empty()) h.assign(ctx_.hist_bins, 0);
    const double lo = ctx_.hist_range.lo, scale = double(ctx_.hist_bins) / std::max(1e-300, ctx_.hist_range.hi - lo);
    for (int lz = A_; lz < A_ + ez; ++lz)
      for (int ly = A_; ly < A_ + ey; ++ly) {
        const T* row = gathered + (size_t(lz) * G + ly) * G;
        for (int lx = A_; lx < A_ + ex; ++lx) {
          if constexpr (std::is_same_v<T, float>) {
            const double b = (double(row[lx]) - lo) * scale;
            h[size_t(std::clamp(b, 0.0, double(ctx_.hist_bins - 1)))]++;
          } else {
            h[size_t(int32_t(row[lx]) - int32_t(integer_min(ValueTypeOf<T>::value)))]++;
          }
        }
      }
  }

  BuildContext& ctx_;
  int level_;
  Level* coarser_;
  Vec3s dims_, bricks_;
  int M_, A_, forward_, capacity_;
  std::vector<std::vector<T>> ring_;
  int64_t received_ = 0;
  int64_t next_row_ = 0;
};

// ---------------------------------------------------------------------------------------------

struct ScanResult {
  uint64_t nonfinite = 0;
  Vec3s first{-1};
  double min = std::numeric_limits<double>::infinity(), max = -std::numeric_limits<double>::infinity();
};

// The f32 pre-pass: finds non-finite voxels before anything is written, and the finite range.
// Blocks are scanned branch-free in parallel (exponent bits all set = NaN or infinity); only a
// block that holds a non-finite value is walked again to count them and find the first.
ScanResult scan_source(VolumeSource& source, Progress* progress) {
  const Vec3s d = source.dims();
  const int64_t slab = std::max<int64_t>(1, std::min<int64_t>(d.z, (32 << 20) / (d.x * d.y * 4)));
  std::vector<float> buffer(size_t(slab * d.x * d.y));
  ScanResult result;
  constexpr int64_t kBlock = 1 << 14;
  for (int64_t z0 = 0; z0 < d.z; z0 += slab) {
    const int64_t z1 = std::min(d.z, z0 + slab);
    const int64_t n = (z1 - z0) * d.x * d.y;
    source.read_slab(z0, z1, {reinterpret_cast<std::byte*>(buffer.data()), size_t(n) * 4});
    const int64_t blocks = (n + kBlock - 1) / kBlock;
    std::vector<ScanResult> partial(static_cast<size_t>(blocks));
    parallel_for<int64_t>(0, blocks, 1, [&](int64_t b0, int64_t b1) {
      for (int64_t b = b0; b < b1; ++b) {
        const int64_t lo = b * kBlock, hi = std::min(n, lo + kBlock);
        const uint32_t* bits = reinterpret_cast<const uint32_t*>(buffer.data());
        uint32_t any_nonfinite = 0;
        float mn = std::numeric_limits<float>::infinity(), mx = -mn;
        for (int64_t i = lo; i < hi; ++i) {
          const bool bad = (bits[i] & 0x7f800000u) == 0x7f800000u;
          any_nonfinite |= uint32_t(bad);
          const float v = bad ? mn : buffer[size_t(i)];  // keeps NaN out of the comparisons
          mn = std::min(mn, v);
          mx = std::max(mx, bad ? mx : v);
        }
        ScanResult& r = partial[size_t(b)];
        r.min = mn;
        r.max = mx;
        if (!any_nonfinite) continue;
        for (int64_t i = lo; i < hi; ++i)
          if (!std::isfinite(buffer[size_t(i)]) && r.nonfinite++ == 0)
            r.first = {i % d.x, (i / d.x) % d.y, z0 + i / (d.x * d.y)};
      }
    });
    for (const ScanResult& r : partial) {
      if (r.nonfinite && result.nonfinite == 0) result.first = r.first;
      result.nonfinite += r.nonfinite;
      result.min = std::min(result.min, r.min);
      result.max = std::max(result.max, r.max);
    }
    if (progress) progress->advance(uint64_t(n));
  }
  source.rewind();
  return result;
}

template <typename T>
void repair_slice(T* data, int64_t n, const BuildOptions& o, const ScanResult& scan) {
  if constexpr (std::is_same_v<T, float>) {
    if (o.nonfinite != NonFinite::reject && scan.nonfinite > 0) {
      for (int64_t i = 0; i < n; ++i) {
        float& v = data[i];
        if (std::isfinite(v)) continue;
        if (o.nonfinite == NonFinite::zero || std::isnan(v)) v = o.nonfinite == NonFinite::zero ? 0.0f : float(std::clamp(0.0, scan.min, scan.max));
        else v = v > 0 ? float(scan.max) : float(scan.min);
      }
    }
  }
  if (o.clamp) {
    const T lo = round_to<T>(o.clamp->first), hi = round_to<T>(o.clamp->second);
    for (int64_t i = 0; i < n; ++i) data[i] = std::clamp(data[i], lo, hi);
  }
}

/// The build's parameters, the store's identity beside its source: an automatic background is
/// recorded as "auto" (what it found is the manifest's background), so that an identical
/// import is known to be up to date before the source is read.
std::string build_params_json(const BuildOptions& o, double source_background) {
  nlohmann::json j = {{"brick_size", o.brick_size},
                      {"apron", o.apron},
                      {"codec", std::string(to_string(o.codec))},
                      {"hc_level", o.hc_level},
                      {"shuffle", o.shuffle},
                      {"downsample", std::string(to_string(o.downsample.value_or(Downsample::average)))},
                      {"constant_tolerance", o.constant_tolerance},
                      {"nonfinite", std::string(to_string(o.nonfinite))},
                      {"background", o.background_auto ? nlohmann::json("auto")
                                                       : nlohmann::json(o.background.value_or(source_background))}};
  j["clamp"] = o.clamp ? nlohmann::json{o.clamp->first, o.clamp->second} : nlohmann::json(nullptr);
  // Recorded only when it applies, so that stores built before it stay up to date.
  if (o.background || o.background_auto) j["flatten"] = "background";
  if (o.level_set) j["level_set"] = true;
  return j.dump();
}

// ---------------------------------------------------------------------------------------------
// Checkpoints: everything but the levels' slices (those are Level::save's), after the identity.

void save_common(StateWriter& w, const BuildIdentity& id, const SeriesState& series, const BuildContext& ctx,
                 const ScanResult& scan, int64_t z) {
  put_identity(w, id);
  series.save(w);
  w.put(uint8_t(1));  // a step under way: its state follows
  w.put(z), w.put(ctx.background);
  w.put(scan.nonfinite), w.put(scan.first), w.put(scan.min), w.put(scan.max);
  w.put(ctx.hist_range), w.put(uint64_t(ctx.hist_bins));
  for (const auto& s : ctx.stats) w.put(s.constant.load()), w.put(s.empty.load()), w.put(s.raw_bytes.load()), w.put(s.stored_bytes.load());
  w.put_vector(ctx.histogram());
  for (int l = 0; l < ctx.layout.levels; ++l) w.put_vector(ctx.nodes.level(l));
}

/// The identity and series part of a checkpoint; returns whether a step's state follows
/// (restore_common), or whether it was taken between two steps.
bool restore_series(StateReader& r, SeriesState& series) {
  if (!get_identity(r)) throw Error(Errc::corrupt, "the build checkpoint is of another format version");
  series.restore(r);
  return r.get<uint8_t>() != 0;
}

/// Restores a step's state, as save_common wrote it after the series part, into a context set
/// up for the same volume and parameters; returns the finest slices done.
int64_t restore_common(StateReader& r, BuildContext& ctx, ScanResult& scan) {
  const int64_t z = r.get<int64_t>();
  ctx.background = r.get<double>();
  scan.nonfinite = r.get<uint64_t>(), scan.first = r.get<Vec3s>(), scan.min = r.get<double>(), scan.max = r.get<double>();
  ctx.hist_range = r.get<ValueRange>();
  ctx.hist_bins = size_t(r.get<uint64_t>());
  for (auto& s : ctx.stats) {
    s.constant = r.get<int64_t>(), s.empty = r.get<int64_t>();
    s.raw_bytes = r.get<uint64_t>(), s.stored_bytes = r.get<uint64_t>();
  }
  ctx.resumed_histogram = r.get_vector<uint64_t>();
  bool fits = z > 0 && z <= ctx.layout.dims.z && ctx.resumed_histogram.size() == ctx.hist_bins;
  for (int l = 0; l < ctx.layout.levels; ++l) {
    auto nodes = r.get_vector<NodeRecord>();
    fits = fits && nodes.size() == ctx.nodes.level(l).size();
    if (fits) ctx.nodes.level(l) = std::move(nodes);
  }
  if (!fits) throw Error(Errc::corrupt, "the build checkpoint does not fit the volume it claims to be of");
  return z;
}

/// What a build that starts from the beginning finds before it writes anything: the f32
/// pre-pass (non-finite voxels and the value range), the background, and the histogram's bins.
void prepare_fresh_build(VolumeSource& source, const BuildOptions& options, BuildContext& ctx, ScanResult& scan,
                         Progress* progress) {
  std::optional<ValueRange> range = source.value_range_hint();
  if (source.may_contain_nonfinite() || (source.type() == ValueType::f32 && !range)) {
    std::unique_ptr<Progress> scan_progress;
    if (progress) scan_progress = std::make_unique<Progress>("scan", uint64_t(volume(source.dims())), "voxels");
    scan = scan_source(source, scan_progress.get());
    if (scan.nonfinite > 0 && options.nonfinite == NonFinite::reject)
      throw Error(Errc::format, fmt::format("{} non-finite voxels (NaN or infinity), the first at ({}, {}, {}); "
                                            "repair them with --nonfinite=zero or --nonfinite=clamp",
                                            scan.nonfinite, scan.first.x, scan.first.y, scan.first.z))
          .with_file(source.name());
    if (!(scan.min <= scan.max)) scan.min = scan.max = 0;  // nothing finite at all
    range = ValueRange{scan.min, scan.max};
  }
  ctx.background = options.background.value_or(source.background());
  if (options.background_auto) ctx.background = estimate_background(source);
  if (ctx.format.type == ValueType::f32) {
    ValueRange r = range.value_or(ValueRange{0, 1});
    if (options.clamp) r = {std::max(r.lo, options.clamp->first), std::min(r.hi, options.clamp->second)};
    ctx.hist_range = r;
    ctx.hist_bins = 256;
  } else {
    ctx.hist_range = {integer_min(ctx.format.type), integer_max(ctx.format.type)};
    ctx.hist_bins = integer_count(ctx.format.type);
  }
}

/// Input bytes of the first z finest slices, for progress in bytes of the source.
uint64_t input_bytes_before(const VolumeSource& source, int64_t z) {
  return uint64_t(double(source.input_bytes()) * double(z) / double(std::max<int64_t>(1, source.dims().z)));
}

template <typename T>
void run_levels(VolumeSource& source, BuildContext& ctx, const BuildOptions& options, const ScanResult& scan,
                Progress* progress, const BuildIdentity& identity, const SeriesState& series, StateReader* resume,
                int64_t z_start) {
  // Coarsest first in memory so each level can point at its coarser neighbour.
  std::vector<std::unique_ptr<Level<T>>> levels(size_t(ctx.layout.levels));
  for (int l = 0; l < ctx.layout.levels; ++l)
    levels[size_t(l)] = std::make_unique<Level<T>>(ctx, l, l > 0 ? levels[size_t(l - 1)].get() : nullptr);
  Level<T>& finest = *levels.back();
  const Vec3s d = ctx.layout.dims;
  const size_t slice_bytes = size_t(finest.slice_voxels()) * sizeof(T);
  if (resume) {
    for (auto& level : levels) level->restore(*resume);
    if (!resume->done()) throw Error(Errc::corrupt, "the build checkpoint has bytes past its last level");
    if (!source.can_skip()) {  // a stream (gzip) is read up to where the build stopped
      std::vector<std::byte> discard(slice_bytes);
      for (int64_t z = 0; z < z_start; ++z) source.read_slab(z, z + 1, discard);
    }
  }
  // A checkpoint right after a finest row is written, when the finest ring holds least; at
  // most every checkpoint_seconds, and never costing over 5% of the time since the last.
  Stopwatch since_checkpoint;
  double last_cost = 0;
  int64_t rows = finest.rows_done();
  for (int64_t z = z_start; z < d.z; ++z) {
    T* slot = finest.next_slot();
    source.read_slab(z, z + 1, {reinterpret_cast<std::byte*>(slot), slice_bytes});
    repair_slice(slot, finest.slice_voxels(), options, scan);
    finest.commit();
    if (progress) progress->advance(input_bytes_before(source, z + 1) - input_bytes_before(source, z));
    if (finest.rows_done() == rows || z + 1 == d.z) continue;
    rows = finest.rows_done();
    const double cost = last_cost + ctx.writer->last_checkpoint_seconds();
    const bool due = options.checkpoint_seconds == 0 ||
                     since_checkpoint.seconds() >= std::max(options.checkpoint_seconds, 20 * cost);
    if (!due) continue;
    const Stopwatch watch;
    StateWriter w;
    save_common(w, identity, series, ctx, scan, z + 1);
    for (const auto& level : levels) level->save(w);
    ctx.writer->push_checkpoint(std::move(w.bytes()));
    last_cost = watch.seconds();
    since_checkpoint.restart();
  }
  finest.finish();
}

void validate(const BuildOptions& o) {
  if (o.apron < 0 || o.apron > 4)
    throw Error(Errc::invalid_argument, fmt::format("apron {} is outside [0, 4]", o.apron)).with_field("--apron");
  if (o.hc_level < 1 || o.hc_level > 12)
    throw Error(Errc::invalid_argument, fmt::format("LZ4-HC level {} is outside [1, 12]", o.hc_level)).with_field("--hc-level");
  if (!(o.constant_tolerance >= 0))
    throw Error(Errc::invalid_argument, "the constant tolerance must be at least 0").with_field("--constant-tolerance");
  if (o.background && !std::isfinite(*o.background))
    throw Error(Errc::invalid_argument, fmt::format("background {} is not a finite number", *o.background))
        .with_field("--background");
  if (o.clamp && !(o.clamp->first <= o.clamp->second))
    throw Error(Errc::invalid_argument, fmt::format("range [{}, {}] is empty", o.clamp->first, o.clamp->second))
        .with_field("--range");
}

}  // namespace

ResourceNeeds estimate_build_needs(const Vec3s& dims, ValueType type, const BuildOptions& o, int threads) {
  const GridLayout layout = GridLayout::make(dims, o.brick_size);
  const double T = double(size_of(type)), M = o.brick_size, A = o.apron;
  const double ring_slices = M + A + std::max(A, 1.0), E = M + 2 * A, G = ring_slices;
  const double payload = E * E * E * T;
  const double record = double(sizeof(BrickHeader)) + payload + std::floor(payload / 255) + 16;  // LZ4_COMPRESSBOUND
  constexpr double kPage = 4096, kPageHeader = 16;
  const double record_on_disk = std::ceil((record + kPageHeader) / kPage) * kPage;

  double rings = 0, bricks = 0;
  for (int l = 0; l < layout.levels; ++l) {
    const Vec3s d = layout.level_dims(l), b = layout.level_bricks(l);
    rings += ring_slices * double(d.x) * double(d.y) * T;
    bricks += double(b.x) * double(b.y) * double(b.z);
  }
  const Vec3s fb = layout.level_bricks(layout.finest());
  const double row = double(fb.x) * double(fb.y) * record;
  const double nodes = bricks * double(sizeof(NodeRecord));
  const double stored = bricks * record_on_disk;
  const double queues = std::min(double(uint64_t(64) << 20) + double(o.batch_bytes), stored);
  const double histogram = double(std::max<size_t>(256, integer_count(type))) * 8;
  const double per_thread = G * G * G * T + 2 * payload + histogram;
  const double build = rings + row + nodes + queues + std::max(1, threads) * per_thread;
  const double slice = double(dims.x) * double(dims.y) * 4;
  const double scan = type == ValueType::f32 ? std::max(slice, std::min(double(32 << 20), slice * double(dims.z))) : 0;

  ResourceNeeds needs;
  needs.task = fmt::format("import of {}x{}x{} {}", dims.x, dims.y, dims.z, to_string(type));
  needs.memory.bytes = saturating_bytes(std::max(build, scan));
  needs.memory.why = fmt::format("{:g} slices of each of its {} levels and a row of {}x{} compressed bricks", ring_slices,
                                 layout.levels, fb.x, fb.y);
  // Smaller bricks mean fewer slices and a thinner row but more nodes: say which way helps.
  needs.memory.lower = fmt::format("a smaller grid (--size for field: sources) or a {} --brick-size lowers it",
                                   rings + row > nodes ? "smaller" : "larger");
  needs.disk.bytes = saturating_bytes((stored + nodes) * 9 / 8);
  needs.disk.why = "every brick at LZ4's worst case, on whole LMDB pages";
  needs.disk.lower = "a smaller grid (--size for field: sources) lowers it, and --no-disk-check starts anyway for data "
                     "that compresses well";
  return needs;
}

BuildResult build_store(VolumeSource& source, const std::string& dir, const BuildOptions& options, Progress* progress) {
  VolumeSource* const one[] = {&source};
  return build_series(one, dir, options, progress);
}

BuildResult build_series(std::span<VolumeSource* const> sources, const std::string& dir, const BuildOptions& given,
                         Progress* progress) {
  BY_CHECK(!sources.empty());
  validate(given);
  VolumeSource& first = *sources[0];
  const int steps = int(sources.size());
  BuildOptions options = given;
  options.level_set = given.level_set || first.is_level_set();
  // A level set's thin parts (a one-voxel shell) average away at coarser levels, where
  // level-of-detail renderers would lose them; the minimum of the signed distance keeps every
  // block that holds some inside, dilating the surface by at most a voxel of that level.
  if (!options.downsample) options.downsample = options.level_set ? Downsample::min : Downsample::average;
  if (const std::string problem = spacing_problem(first.spacing()); !problem.empty())
    throw Error(Errc::format, problem).with_file(first.name()).with_field("spacing");
  check_series(sources);
  if (steps > 1 && options.octree)
    throw Error(Errc::invalid_argument, fmt::format("an octree volume is built over a grid of one time step; these are {}", steps))
        .with_field("--octree");
  Stopwatch watch;
  BuildResult result;
  const GridLayout layout = GridLayout::make(first.dims(), options.brick_size);
  const std::string source_json = series_source_json(sources);
  const std::string build_json = build_params_json(options, first.background());

  StoreBuildTarget target(dir, source_json, build_json, options.force, result, options.octree.has_value());
  // A rerun (up to date, or resuming a killed build) of a file checked then and unchanged
  // since need not read all of it again first: 2 s of an 8 GiB file's 5 s resumption.
  if (!target.source_checked_before(source_json))
    for (VolumeSource* s : sources) s->verify_content();
  if (target.up_to_date()) {
    result.up_to_date = true;
    return result;
  }
  ResourceNeeds needs = estimate_build_needs(first.dims(), first.type(), options, tbb::this_task_arena::max_concurrency());
  needs.disk.bytes *= uint64_t(steps);
  if (!options.check_disk) needs.disk.bytes = 0;
  needs.disk_path = dir;  // a rebuild beside it is on the same file system
  check_resources(needs);

  BrickFormat format;
  format.type = first.type();
  format.brick_size = options.brick_size;
  format.apron = options.apron;
  format.codec = options.codec;
  format.hc_level = options.hc_level;
  format.shuffle = options.shuffle;

  const BuildIdentity identity{source_json, build_json};
  SeriesState series;
  std::optional<StateReader> resume;
  bool resume_in_step = false;
  if (const auto& state = target.resume_state()) {
    // An interrupted build of this same import: the steps it finished, and where it stopped.
    resume.emplace(*state);
    try {
      resume_in_step = restore_series(*resume, series);
      result.resumed_at_step = series.step;
      if (series.step > steps || (series.step == steps && resume_in_step))
        throw Error(Errc::corrupt, "the build checkpoint's time steps do not add up");
    } catch (Error& e) {
      throw e.with_file(target.path());
    }
  }

  Manifest manifest;
  manifest.time_steps = steps;
  manifest.dims = layout.dims;
  manifest.spacing = first.spacing();
  manifest.origin = first.origin();
  manifest.format = format;
  manifest.levels = layout.levels;
  manifest.source = nlohmann::json::parse(source_json).dump();
  manifest.build = build_json;

  lmdb::EnvOptions env;
  const uint64_t raw_bytes = uint64_t(volume(layout.dims)) * size_of(format.type) * uint64_t(steps);
  env.map_size = options.map_size ? options.map_size : std::max<uint64_t>(uint64_t(64) << 20, raw_bytes + raw_bytes / 2);
  env.growth = options.map_growth;
  env.max_map_size = options.map_growth ? uint64_t(1) << 44 : env.map_size;
  env.no_sync = true;  // the final transaction syncs everything before it
  std::unique_ptr<StoreWriter> store;  // opened once the first step is prepared: a refused volume writes nothing

  std::optional<BuildContext> last;  // the last step's context: its node table for a one-step store
  const int first_step = series.step;  // where this run starts: a resumed build's step, else 0
  for (int step = first_step; step < steps; ++step) {
    VolumeSource& source = *sources[size_t(step)];
    BuildContext& ctx = last.emplace(size_t(layout.levels));
    ctx.format = format;
    ctx.layout = layout;
    ctx.nodes = NodeTable(layout);
    ctx.downsample = *options.downsample;
    ctx.tolerance = options.constant_tolerance;
    ctx.flatten_background_only = options.background.has_value() || options.background_auto;
    ScanResult scan;
    int64_t z_start = 0;
    const bool resuming = resume && step == series.step && resume_in_step;
    if (resuming) {
      try {
        z_start = restore_common(*resume, ctx, scan);
      } catch (Error& e) {
        throw e.with_file(target.path());
      }
      result.resumed_at_slice = z_start;
    } else {
      BuildOptions step_options = options;
      if (step > 0) step_options.background = series.background, step_options.background_auto = false;
      prepare_fresh_build(source, step_options, ctx, scan, progress);
    }
    if (step == 0) series.background = ctx.background;
    if (!store)
      store = resume ? StoreWriter::reopen(target.path(), env, options.batch_bytes)
                     : std::make_unique<StoreWriter>(target.path(), manifest, env, options.batch_bytes);
    if (progress && step == first_step && (z_start > 0 || step > 0)) {
      uint64_t done = input_bytes_before(source, z_start);
      for (int s = 0; s < step; ++s) done += sources[size_t(s)]->input_bytes();
      progress->start_at(done);
    }
    {
      RecordWriter writer(*store, size_t(64) << 20, step);
      ctx.writer = &writer;
      try {
        dispatch_value_type(format.type, [&](auto tag) {
          run_levels<decltype(tag)>(source, ctx, options, scan, progress, identity, series, resuming ? &*resume : nullptr,
                                    z_start);
        });
      } catch (...) {
        // A source that fails (a read error, a damaged stream) after hours of work: the
        // checkpoints already queued are committed, so that the rerun resumes from the last.
        try {
          writer.close();
        } catch (...) {
        }
        throw;
      }
      writer.close();
      ctx.writer = nullptr;
    }
    if (resuming) {
      resume.reset();
      target.resume_state().reset();  // its slices are no longer needed
    }
    add_step(series, ctx);
    if (steps > 1) {
      // The step's node table, and a checkpoint between steps, in one transaction.
      store->put_step_nodes(step, ctx.nodes);
      StateWriter w;
      put_identity(w, identity);
      series.save(w);
      w.put(uint8_t(0));
      store->put_checkpoint(w.bytes());
    }
  }

  // A series killed after its last step's checkpoint has no step left to build: only the end.
  if (!store) store = StoreWriter::reopen(target.path(), env, options.batch_bytes);
  manifest.background = series.background;
  summarise(series, format, manifest);
  for (const LevelStats& s : manifest.stats) result.stored_bytes += s.stored_bytes;
  result.warnings = value_range_warnings(manifest.min_value, manifest.max_value);
  if (const auto c = first.conversion()) result.conversion = c->summary();
  if (steps > 1) store->finish_series(manifest);
  else store->finish(manifest, last->nodes);
  store.reset();  // closed before its directory is swapped into place
  manifest.complete = true;
  result.manifest = manifest;
  result.seconds = watch.seconds();  // the bricks' time: the octree reports its own
  if (options.octree) {
    std::unique_ptr<Progress> octree_progress;
    if (progress) octree_progress = std::make_unique<Progress>("build-octree", uint64_t(volume(manifest.dims)), "voxels");
    result.octree_seconds = build_octree(target.path(), *options.octree, target.lock(), octree_progress.get()).seconds;
    if (octree_progress) octree_progress->finish();
    result.manifest = read_manifest(target.path());
  }
  target.commit();
  for (VolumeSource* s : sources) result.input_bytes += s->input_bytes();
  return result;
}

std::vector<std::string> value_range_warnings(double min_value, double max_value) {
  std::vector<std::string> warnings;
  const double largest = std::max(std::fabs(min_value), std::fabs(max_value));
  if (!(largest < std::numeric_limits<double>::infinity())) return warnings;  // an empty store
  if (largest >= double(FLT_MAX) / 2) {
    warnings.push_back(fmt::format(
        "values reach {:g}, within a factor of 2 of the largest float ({:g}): the renderers interpolate in single "
        "precision, and their gradients and crossings lose accuracy there; scaling the data down by a power of two "
        "(exact) avoids it",
        largest, double(FLT_MAX)));
  } else if (largest > 0 && largest < double(FLT_MIN)) {
    warnings.push_back(fmt::format(
        "every value is denormal (at most {:g} in magnitude, below the smallest normal float, {:g}): single precision "
        "keeps few significant bits there; scaling the data up by a power of two (exact) avoids it",
        largest, double(FLT_MIN)));
  }
  return warnings;
}

}  // namespace brickyard
