#pragma once
/// @file bench_report.h
/// @brief The report of `brickyard bench`: every back end at every setting of its quality
/// knob, its cold- and warm-cache frame times, and its image error against the reference
/// renderer, as a CSV, a Markdown page and two gnuplot charts (error against time, and a
/// contact sheet of the images).
///
/// Every file is written under a temporary name and renamed into place, so an interrupted
/// bench leaves either the previous file or the new one, never half of one. Pure functions
/// of their arguments apart from the files; nothing here is shared between calls.

#include <cstddef>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "renderers/common/metrics.h"

namespace brickyard {

/// @brief One back end at one quality setting: how fast, and how far from the truth.
struct BenchRow {
  std::string backend;          ///< "reference", "raymarch", ...
  std::string quality;          ///< human label of the knob setting, e.g. "step=0.5" ("" for none)
  double quality_value = 0;     ///< the knob's value: orders a back end's rows in the plot
  int width = 0, height = 0, threads = 0;
  /// The first frame from empty caches (each cold run starts with new, empty caches): for a
  /// back end that refines over frames, a coarse or incomplete image (see first_error).
  double cold_median_s = 0, cold_p95_s = 0;
  double warm_median_s = 0, warm_p95_s = 0;  ///< a frame again with the caches filled and the image converged
  int cold_runs = 0, warm_runs = 0;
  /// From empty caches to the converged image, the wait a user starting cold has: the wall
  /// time of the frames rendered one after another as they would be shown, each followed by
  /// the loads it asked for, until the back end reports a converged frame (median over the
  /// cold runs; NaN when there were none), and how many frames that took (1 when the first
  /// frame is already complete).
  double converged_median_s = std::numeric_limits<double>::quiet_NaN();
  int converged_frames = 0;
  /// From empty caches to a still camera's converged image asked for at once, the wait of
  /// `brickyard render` (or a viewer whose camera stops): no frame before it is shown, so a
  /// back end may complete each one (RenderSession::complete); the frames that took. For a peer,
  /// its first frame. NaN when there were no cold runs.
  double still_median_s = std::numeric_limits<double>::quiet_NaN();
  int still_frames = 0;
  int settle_frames = 0;        ///< warm-up frames before the warm ones, completed at once where the back end can (RenderSession::Settle::complete)
  ImageError error;             ///< of the warm frame, against the reference frame
  /// The first cold frame's RMSE and SSIM against the reference (NaN when there was no cold run).
  double first_rmse = std::numeric_limits<double>::quiet_NaN(), first_ssim = std::numeric_limits<double>::quiet_NaN();
  bool is_reference = false;    ///< the truth itself: error 0 by definition
  /// Another program's renderer (bench --peers): its times are its own, measured by the
  /// script that ran it; its error is computed here, from its colour image, like every row's.
  bool is_peer = false;
  std::string description;      ///< what a peer row is (program, version, settings); "" for back ends
  uint64_t peak_rss_bytes = 0;  ///< a peer's peak resident memory, as its script measured it (0: not measured)
  double rays_per_second_per_core = 0;
  uint64_t samples = 0, bricks = 0, bytes_read = 0;  ///< per warm frame
  std::string image;            ///< this row's colour PNG, relative to the report directory ("" for none)
};

struct BenchReport {
  std::string title;            ///< e.g. scene file name, dataset, image size, mode
  std::vector<BenchRow> rows;
};

/// @brief Which time of a row equal_error_rows() compares.
enum class BenchTime {
  warm,       ///< warm_median_s: the steady frame
  converged,  ///< from empty caches to the converged image: still_median_s where measured, else converged_median_s
};
double time_of(const BenchRow& r, BenchTime which);

/// @brief One back end's warm frame time at the error another back end reached in one of its
/// rows: the two back ends compared at equal error.
struct EqualErrorRow {
  /// How backend_time_s was found on the back end's curve (its own Pareto front: more time,
  /// less error).
  enum class Bound {
    interpolated,  ///< between its two rows around the error, log-log (or at one row of that error)
    at_most,       ///< its fastest row is already more accurate: that row's time, an upper bound
    at_least,      ///< no row of it is this accurate: its most accurate row's time, a lower bound
  };
  std::string backend;          ///< the back end timed at `against`'s error
  std::string against;          ///< the back end whose row sets the error
  std::string against_quality;  ///< that row's quality label
  double rmse = 0;              ///< that row's colour RMSE
  double against_time_s = 0;    ///< that row's warm median
  double backend_time_s = 0;    ///< backend's warm median at rmse, or its bound
  Bound bound = Bound::interpolated;
  BenchTime time = BenchTime::warm;  ///< which time both sides are
  /// against_time_s / backend_time_s: above 1 where `backend` is faster (a lower bound when
  /// bound is at_most, an upper one when it is at_least).
  double speedup() const { return against_time_s / backend_time_s; }
};

/// @brief Every ordered pair of back ends (in the order of their first comparable rows),
/// each compared at the error of every row of the second: the first's warm time there,
/// interpolated log-log along its own Pareto front (a power law of time in error is matched
/// exactly), or bounded by its fastest or most accurate row outside the errors it reached.
/// Rows without a positive, finite time and RMSE take no part.
/// `which` picks the time compared: the warm frame (the default) or the time from empty caches
/// to the converged image; the error is the warm frame's in both (the converged image's).
std::vector<EqualErrorRow> equal_error_rows(const std::vector<BenchRow>& rows, BenchTime which = BenchTime::warm);

/// @brief The files write_bench_report() wrote; an entry is empty when that file was not
/// written (contact_sheet when no row's image exists).
struct BenchReportPaths {
  std::string csv;              ///< DIR/bench.csv
  std::string equal_error_csv;  ///< DIR/equal-error.csv (equal_error_rows(); a header alone when there are none)
  std::string markdown;         ///< DIR/bench.md
  std::string error_plot;       ///< DIR/error-vs-time.png
  std::string contact_sheet;    ///< DIR/contact-sheet.png
};

/// @brief Indices (ascending) of the rows on the Pareto front of (warm_median_s, error.rmse):
/// no other row is at least as fast and at least as accurate and strictly better in one.
/// Rows with identical time and error do not dominate each other, so both stay. Reference
/// rows are neither candidates nor competitors (their error is zero by definition), and nor
/// are rows whose time or RMSE is NaN (not measured).
std::vector<size_t> pareto_front(const std::vector<BenchRow>& rows);

/// @brief Writes, creating `dir` if needed:
/// - DIR/bench.csv: a header line and one line per row with every field (doubles in
///   shortest round-trip form, so full precision; infinity as "inf"), RFC 4180 quoting;
/// - DIR/error-vs-time.png: colour RMSE against warm median time (ms), both axes logarithmic,
///   one curve per back end in quality_value order with points labelled by quality, the
///   Pareto front as a highlighted staircase, and each reference row as a labelled dashed
///   vertical line at its time (zero error has no place on a log axis); a non-reference row
///   with zero error sits on the bottom edge, labelled "(RMSE 0)";
/// - DIR/contact-sheet.png: the rows' images in a grid, each titled "backend quality, time,
///   RMSE" (rows whose image is empty or missing are left out; not written when none is left);
/// - DIR/equal-error.csv: equal_error_rows(), one line each (backend, against,
///   against_quality, rmse, against_time_s, backend_time_s, time_bound, speedup, time; time_bound
///   bounds backend_time_s, so at_most makes the speed-up a lower bound and at_least an upper one;
///   time is "warm" for the steady frames and "converged" for the times from empty caches to
///   the converged image, both sets written);
/// - DIR/bench.md: title, a summary, the chart, a table (backend, quality, first cold frame
///   median ms and RMSE, cold-to-converged median ms and frames, warm median/p95 ms,
///   rays/s/core, bytes read, RMSE, PSNR, SSIM, depth mean/p99 voxels, normal mean degrees,
///   coverage mismatch %, Pareto mark, image link), the equal-error tables (warm, and cold to
///   converged) when there are two back ends to compare, the peers' descriptions, a legend and
///   the contact sheet.
/// The charts need gnuplot (package gnuplot-nox).
/// A chart not drawn this time is removed if an earlier run left one, so the directory never
/// mixes two runs.
/// @throws Error(io) naming the file that cannot be written. When a chart fails (gnuplot
/// missing or failing), bench.csv and bench.md (without that chart) are still written, no
/// partial chart is left, and then the chart's Error(unsupported) naming it is thrown.
BenchReportPaths write_bench_report(const std::string& dir, const BenchReport& report);

}  // namespace brickyard
