#include "core/progress.h"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iostream>

#include <fmt/format.h>

#include "core/units.h"

namespace brickyard {
namespace {
std::atomic<ProgressStyle> g_default_style{ProgressStyle::automatic};
}

void set_default_progress_style(ProgressStyle style) { g_default_style.store(style); }
ProgressStyle default_progress_style() { return g_default_style.load(); }

Progress::Progress(std::string label, uint64_t total, std::string unit, ProgressOptions options)
    : label_(std::move(label)), unit_(std::move(unit)), total_(total), out_(options.out ? options.out : &std::cerr) {
  style_ = options.style;
  if (style_ == ProgressStyle::automatic) style_ = default_progress_style();
  if (style_ == ProgressStyle::automatic)
    style_ = (out_ == &std::cerr && ::isatty(STDERR_FILENO)) ? ProgressStyle::bar : ProgressStyle::lines;
  interval_ = style_ == ProgressStyle::bar ? options.bar_interval : options.line_interval;
  next_report_ns_.store(static_cast<int64_t>(interval_ * 1e9));
}

Progress::~Progress() {
  // A task abandoned before any work (an error, nothing to do) ends without a closing line.
  if (done_.load(std::memory_order_relaxed) == 0) {
    std::lock_guard lock(print_mutex_);
    if (style_ == ProgressStyle::bar && !finished_) *out_ << "\r\033[K" << std::flush;
    finished_ = true;
  }
  finish();
}

std::string Progress::amount(double n) const {
  if (unit_ == "B") return format_bytes(n);
  return unit_.empty() ? format_count(n) : format_count(n) + " " + unit_;
}

void Progress::advance(uint64_t n) {
  done_.fetch_add(n, std::memory_order_relaxed);
  if (style_ == ProgressStyle::quiet) return;
  const int64_t now = watch_.nanoseconds();
  if (now < next_report_ns_.load(std::memory_order_relaxed)) return;
  std::unique_lock lock(print_mutex_, std::try_to_lock);
  if (!lock.owns_lock() || finished_) return;
  if (now < next_report_ns_.load(std::memory_order_relaxed)) return;  // another thread just printed
  next_report_ns_.store(now + static_cast<int64_t>(interval_ * 1e9), std::memory_order_relaxed);
  report(false);
}

void Progress::start_at(uint64_t n) {
  already_done_ = n;
  done_.store(n, std::memory_order_relaxed);
}

void Progress::finish() {
  std::lock_guard lock(print_mutex_);
  if (finished_) return;
  finished_ = true;
  if (style_ != ProgressStyle::quiet) report(true);
}

void Progress::report(bool final_line) {
  const double t = watch_.seconds();
  const double done = static_cast<double>(done_.load(std::memory_order_relaxed));
  const double rate = t > 0 ? (done - static_cast<double>(already_done_)) / t : 0.0;
  const std::string rate_text = (unit_ == "B" ? format_bytes(rate) : amount(rate)) + "/s";

  if (final_line) {
    std::string line = fmt::format("{}: {} in {} ({})", label_, amount(done - static_cast<double>(already_done_)),
                                   format_duration(t), rate_text);
    if (style_ == ProgressStyle::bar) *out_ << "\r\033[K";
    *out_ << line << '\n' << std::flush;
    return;
  }

  const bool known = total_ > 0;
  const double fraction = known ? std::min(1.0, done / static_cast<double>(total_)) : 0.0;
  std::string eta = "?";
  if (known && rate > 0) {
    const double remaining = (static_cast<double>(total_) - done) / rate;
    eta = remaining < 1.0 ? "<1 s" : format_duration(std::round(remaining));
  }
  if (style_ == ProgressStyle::bar) {
    constexpr int width = 30;
    std::string bar;
    if (known) {
      const int filled = static_cast<int>(fraction * width);
      bar = fmt::format("[{:=<{}}{:<{}}] ", "", filled, filled < width ? ">" : "", width - filled);
    }
    *out_ << "\r\033[K"
          << fmt::format("{} {}{:3.0f}%  {}  {}  ETA {}", label_, bar, fraction * 100, amount(done), rate_text, eta)
          << std::flush;
  } else if (known) {
    *out_ << fmt::format("{}: {:.0f}% ({} of {}), {}, ETA {}\n", label_, fraction * 100, amount(done),
                         amount(static_cast<double>(total_)), rate_text, eta)
          << std::flush;
  } else {
    *out_ << fmt::format("{}: {}, {}\n", label_, amount(done), rate_text) << std::flush;
  }
}

}  // namespace brickyard
