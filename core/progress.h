#pragma once
/// @file progress.h
/// @brief Progress reporting for long work: a live bar with rate and ETA on a terminal,
/// periodic plain lines otherwise (logs, CI), nothing at all when quiet.
///
/// Concurrency: advance() may be called from many threads at once. It costs one atomic add
/// and a clock read; whichever thread finds a report due and wins a try-lock prints it, the
/// others never wait.

#include <atomic>
#include <cstdint>
#include <iosfwd>
#include <mutex>
#include <string>

#include "core/timing.h"

namespace brickyard {

enum class ProgressStyle {
  automatic,  ///< bar when the stream is a terminal, lines otherwise
  bar,        ///< redraw one line in place
  lines,      ///< a plain line every line_interval seconds
  quiet,      ///< print nothing
};

struct ProgressOptions {
  ProgressStyle style = ProgressStyle::automatic;
  std::ostream* out = nullptr;     ///< default: std::cerr
  double bar_interval = 0.1;       ///< seconds between redraws of the bar
  double line_interval = 5.0;      ///< seconds between plain lines
};

/// @brief Process-wide default style; the CLI sets quiet for --quiet.
void set_default_progress_style(ProgressStyle style);
ProgressStyle default_progress_style();

class Progress {
 public:
  /// @param label  what is being done ("generate fbm")
  /// @param total  amount of work in `unit`s (0 if unknown: no percentage or ETA)
  /// @param unit   what is counted ("voxels", "bricks", "B" for bytes)
  Progress(std::string label, uint64_t total, std::string unit, ProgressOptions options = {});
  ~Progress();
  Progress(const Progress&) = delete;
  Progress& operator=(const Progress&) = delete;

  /// @brief Records n more units done; thread-safe.
  void advance(uint64_t n);
  /// @brief Work done before this run (a resumed build): counted as done, not in the rate or
  /// the time left. Call before advance().
  void start_at(uint64_t n);
  /// @brief Prints the closing line (total, time, mean rate). Idempotent; the destructor calls it.
  void finish();

  uint64_t done() const { return done_.load(std::memory_order_relaxed); }
  double elapsed_seconds() const { return watch_.seconds(); }

 private:
  void report(bool final_line);
  std::string amount(double n) const;

  std::string label_, unit_;
  uint64_t total_;
  ProgressStyle style_;
  std::ostream* out_;
  double interval_;
  Stopwatch watch_;
  std::atomic<uint64_t> done_{0};
  uint64_t already_done_ = 0;
  std::atomic<int64_t> next_report_ns_;
  std::mutex print_mutex_;  // guards printing and finished_
  bool finished_ = false;
};

}  // namespace brickyard
