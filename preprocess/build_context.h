#pragma once
/// @file build_context.h
/// @brief What a grid build keeps while it runs (internal to preprocess/): the state shared by
/// its levels, and what a build of several time steps carries from one step to the next.

#include <atomic>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include <tbb/enumerable_thread_specific.h>

#include "core/value_type.h"
#include "fields/field.h"
#include "preprocess/build_state.h"
#include "preprocess/builder.h"
#include "storage/manifest.h"

namespace brickyard {
class VolumeSource;
}

namespace brickyard::build_detail {

class RecordWriter;

// Per-build state shared by the levels.
struct BuildContext {
  BrickFormat format;
  GridLayout layout;
  NodeTable nodes;
  Downsample downsample = Downsample::average;
  double tolerance = 0;
  double background = 0;
  /// With a background given: the tolerance flattens only bricks within it of the background.
  bool flatten_background_only = false;
  RecordWriter* writer = nullptr;
  // Finest-level histogram: exact per integer value for the integer types (bin 0 is
  // integer_min), 256 bins over `hist_range` for f32.
  ValueRange hist_range;
  size_t hist_bins = 256;
  tbb::enumerable_thread_specific<std::vector<uint64_t>> histograms;
  std::vector<uint64_t> resumed_histogram;  ///< counted before the checkpoint a build resumed from

  /// Every count so far, the threads' and a resumed build's.
  std::vector<uint64_t> histogram() const {
    std::vector<uint64_t> sum = resumed_histogram;
    sum.resize(hist_bins, 0);
    for (const auto& h : histograms)
      for (size_t i = 0; i < h.size(); ++i) sum[i] += h[i];
    return sum;
  }
  struct AtomicStats {
    std::atomic<int64_t> constant{0}, empty{0};
    std::atomic<uint64_t> raw_bytes{0}, stored_bytes{0};
  };
  std::vector<AtomicStats> stats;

  explicit BuildContext(size_t levels) : stats(levels) {}
};

/// What a build of several time steps carries from one step to the next, and through its
/// checkpoints: the steps done, their value ranges, statistics and histograms. Every step is
/// flattened against step 0's background, so that "empty" means the same at every step.
struct SeriesState {
  int32_t step = 0;                      ///< the step being built; every one before it is done
  double background = 0;                 ///< step 0's, once step 0 has begun
  std::vector<StepValueRange> ranges;    ///< of the steps done
  std::vector<LevelStats> stats;         ///< summed over the steps done
  std::vector<uint64_t> counts;          ///< integer types: exact counts, summed over the steps done
  std::vector<Histogram> f32_histograms;  ///< f32: each step's bins over its own range

  void save(StateWriter& w) const {
    w.put(step), w.put(background);
    w.put_vector(ranges), w.put_vector(stats), w.put_vector(counts);
    w.put(uint64_t(f32_histograms.size()));
    for (const Histogram& h : f32_histograms) w.put(h.lo), w.put(h.hi), w.put_vector(h.counts);
  }
  void restore(StateReader& r) {
    step = r.get<int32_t>(), background = r.get<double>();
    ranges = r.get_vector<StepValueRange>(), stats = r.get_vector<LevelStats>(), counts = r.get_vector<uint64_t>();
    f32_histograms.resize(size_t(r.get<uint64_t>()));
    for (Histogram& h : f32_histograms) h.lo = r.get<double>(), h.hi = r.get<double>(), h.counts = r.get_vector<uint64_t>();
    if (step < 0 || ranges.size() != size_t(step)) throw Error(Errc::corrupt, "the build checkpoint's time steps do not add up");
  }
};


/// Refuses a series whose steps are not the same grid (Error(format) naming the step's file).
void check_series(std::span<VolumeSource* const> sources);
/// The provenance of a series: one source's own, or each step's in order.
std::string series_source_json(std::span<VolumeSource* const> sources);
/// Adds a finished step's node ranges, statistics and histogram to the series'.
void add_step(SeriesState& series, const BuildContext& ctx);
/// The manifest's value range, per-step ranges, histogram and per-level statistics.
void summarise(const SeriesState& series, const BrickFormat& format, Manifest& manifest);

}  // namespace brickyard::build_detail
