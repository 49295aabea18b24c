#include <algorithm>
#include <limits>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "preprocess/build_context.h"
#include "preprocess/volume_source.h"

namespace brickyard::build_detail {

/// Refuses a series whose steps are not the same grid: each step must have step 0's dims, value
/// type, spacing and origin (a time step of another shape is another dataset).
void check_series(std::span<VolumeSource* const> sources) {
  const VolumeSource& first = *sources[0];
  for (size_t i = 1; i < sources.size(); ++i) {
    const VolumeSource& s = *sources[i];
    std::string what;
    if (s.dims() != first.dims())
      what = fmt::format("is {}x{}x{} voxels", s.dims().x, s.dims().y, s.dims().z);
    else if (s.type() != first.type())
      what = fmt::format("holds {} values", to_string(s.type()));
    else if (s.spacing() != first.spacing() || s.origin() != first.origin())
      what = fmt::format("has spacing {},{},{} and origin {},{},{}", s.spacing().x, s.spacing().y, s.spacing().z, s.origin().x,
                         s.origin().y, s.origin().z);
    if (what.empty()) continue;
    throw Error(Errc::format,
                fmt::format("time step {} {}, but step 0 ({}) is {}x{}x{} {} voxels with spacing {},{},{} and origin "
                            "{},{},{}: every time step must be the same grid",
                            i, what, first.name(), first.dims().x, first.dims().y, first.dims().z, to_string(first.type()),
                            first.spacing().x, first.spacing().y, first.spacing().z, first.origin().x, first.origin().y,
                            first.origin().z))
        .with_file(s.name());
  }
}

/// The provenance of a series: each step's own, in order.
std::string series_source_json(std::span<VolumeSource* const> sources) {
  if (sources.size() == 1) return sources[0]->describe_json();
  nlohmann::json steps = nlohmann::json::array();
  for (VolumeSource* s : sources) steps.push_back(nlohmann::json::parse(s->describe_json()));
  return nlohmann::json{{"kind", "time_series"}, {"steps", steps}}.dump();
}

/// Adds a finished step's node ranges, statistics and histogram to the series'.
void add_step(SeriesState& series, const BuildContext& ctx) {
  StepValueRange range{std::numeric_limits<double>::infinity(), -std::numeric_limits<double>::infinity()};
  for (const NodeRecord& n : ctx.nodes.level(ctx.layout.finest())) {
    range.min = std::min(range.min, double(n.min));
    range.max = std::max(range.max, double(n.max));
  }
  series.ranges.push_back(range);
  series.stats.resize(size_t(ctx.layout.levels));
  for (int l = 0; l < ctx.layout.levels; ++l) {
    const auto& s = ctx.stats[size_t(l)];
    LevelStats& sum = series.stats[size_t(l)];
    sum.bricks += ctx.layout.brick_count(l);
    sum.constant += s.constant.load(), sum.empty += s.empty.load();
    sum.raw_bytes += s.raw_bytes.load(), sum.stored_bytes += s.stored_bytes.load();
  }
  const std::vector<uint64_t> counts = ctx.histogram();
  if (ctx.format.type == ValueType::f32) {
    series.f32_histograms.push_back({ctx.hist_range.lo, ctx.hist_range.hi, counts});
  } else {
    series.counts.resize(counts.size(), 0);
    for (size_t i = 0; i < counts.size(); ++i) series.counts[i] += counts[i];
  }
  ++series.step;
}

/// The manifest's value range, per-step ranges, histogram (256 bins over every step's voxels)
/// and per-level statistics, from the finished series.
void summarise(const SeriesState& series, const BrickFormat& format, Manifest& manifest) {
  manifest.min_value = std::numeric_limits<double>::infinity();
  manifest.max_value = -std::numeric_limits<double>::infinity();
  for (const StepValueRange& r : series.ranges) {
    manifest.min_value = std::min(manifest.min_value, r.min);
    manifest.max_value = std::max(manifest.max_value, r.max);
  }
  if (manifest.time_steps > 1) manifest.step_ranges = series.ranges;
  Histogram& h = manifest.histogram;
  h.counts.assign(256, 0);
  if (format.type == ValueType::f32 && series.f32_histograms.size() == 1) {
    h = series.f32_histograms.front();
  } else if (format.type == ValueType::f32) {
    // Each step's bins over its own range, put into 256 over all of them by their centres.
    h.lo = std::numeric_limits<double>::infinity(), h.hi = -std::numeric_limits<double>::infinity();
    for (const Histogram& s : series.f32_histograms) h.lo = std::min(h.lo, s.lo), h.hi = std::max(h.hi, s.hi);
    const double span = h.hi > h.lo ? h.hi - h.lo : 1.0;
    for (const Histogram& s : series.f32_histograms)
      for (size_t i = 0; i < s.counts.size(); ++i) {
        const double centre = s.lo + (s.hi - s.lo) * (double(i) + 0.5) / double(s.counts.size());
        h.counts[size_t(std::clamp((centre - h.lo) / span * 256, 0.0, 255.0))] += s.counts[i];
      }
  } else {
    // Exact integer counts, rebinned onto 256 bins over the values that occur.
    h.lo = manifest.min_value;
    h.hi = manifest.max_value;
    const double span = std::max(1.0, manifest.max_value - manifest.min_value + 1);
    for (size_t v = 0; v < series.counts.size(); ++v)
      if (series.counts[v])
        h.counts[size_t(std::clamp((double(v) + integer_min(format.type) - manifest.min_value) / span * 256, 0.0, 255.0))] +=
            series.counts[v];
  }
  manifest.stats = series.stats;
}

}  // namespace brickyard::build_detail
