#include "report/bench_report.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <optional>

#include <fmt/format.h>

#include "core/atomic_file.h"
#include "core/error.h"
#include "core/plot.h"
#include "core/units.h"

namespace brickyard {
namespace {

namespace fs = std::filesystem;

// --- formatting helpers ---------------------------------------------------------------------

/// Line breaks and tabs become spaces: labels go into one-line contexts (table cells, gnuplot strings).
std::string one_line(std::string_view text) {
  std::string out(text);
  for (char& c : out)
    if (c == '\n' || c == '\r' || c == '\t' || c == '\0') c = ' ';
  return out;
}

/// "backend quality" or "backend" when there is no quality label.
std::string row_label(const BenchRow& r) { return one_line(r.quality.empty() ? r.backend : r.backend + " " + r.quality); }

/// Three significant digits without an exponent for ordinary magnitudes: 0.0123, 1.23, 123, 12345.
std::string sig3(double v) {
  if (!std::isfinite(v)) return v > 0 ? "∞" : v < 0 ? "-∞" : "n/a";
  const double a = std::fabs(v);
  if (a == 0) return "0";
  if (a >= 1e6 || a < 1e-3) return fmt::format("{:.2e}", v);
  const int digits = std::max(0, 2 - int(std::floor(std::log10(a))));
  return fmt::format("{:.{}f}", v, digits);
}

std::string ms(double seconds) { return sig3(seconds * 1e3); }

/// Shortest round-trip text of a double: full precision, "inf"/"-inf"/"nan" for the others.
std::string csv_number(double v) {
  if (std::isnan(v)) return "nan";
  if (std::isinf(v)) return v > 0 ? "inf" : "-inf";
  return fmt::format("{}", v);
}

/// RFC 4180: a field holding a comma, a double quote or a line break is quoted, quotes doubled.
std::string csv_field(std::string_view text) {
  if (text.find_first_of(",\"\r\n") == std::string_view::npos) return std::string(text);
  std::string out = "\"";
  for (char c : text) {
    if (c == '"') out += '"';
    out += c;
  }
  return out + "\"";
}

/// Text for a Markdown table cell: characters with a meaning in Markdown are backslash-escaped.
std::string md_cell(std::string_view text) {
  std::string out;
  for (char c : one_line(text)) {
    if (std::string_view("\\|*_`[]<>#~").find(c) != std::string_view::npos) out += '\\';
    out += c;
  }
  return out;
}

/// A relative path as a link target: everything but unreserved characters and '/' is
/// percent-encoded (spaces, parentheses, quotes, non-ASCII bytes), so any file name links.
std::string md_link_target(std::string_view path) {
  std::string out;
  for (unsigned char c : path) {
    if (std::isalnum(c) || std::string_view("-._~/=,+@").find(char(c)) != std::string_view::npos)
      out += char(c);
    else
      out += fmt::format("%{:02X}", c);
  }
  return out;
}

/// A number for a gnuplot script or datablock.
std::string gp_number(double v) { return fmt::format("{:.17g}", v); }

/// Over less than three decades gnuplot labels a log axis too sparsely (one or two powers of
/// ten): label it at 1, 2, 5 times each power instead.
std::string log_tics(const char* axis, double lo, double hi) {
  if (!(lo > 0) || hi / lo >= 1e3) return {};
  std::string list;
  for (int e = int(std::floor(std::log10(lo))); e <= int(std::ceil(std::log10(hi))); ++e)
    for (double m : {1.0, 2.0, 5.0}) {
      const double v = m * std::pow(10.0, e);
      if (v >= lo && v <= hi) list += fmt::format("{}{:g}", list.empty() ? "" : ", ", v);
    }
  return fmt::format("set {}tics ({})\nset m{}tics 10\n", axis, list, axis);
}

bool plottable_time(const BenchRow& r) { return std::isfinite(r.warm_median_s) && r.warm_median_s > 0; }

void write_text(const std::string& path, const std::string& text) {
  AtomicFile file(path);
  file.write(text.data(), text.size());
  file.commit();
}

// --- CSV ------------------------------------------------------------------------------------

std::string csv_text(const BenchReport& report, const std::vector<bool>& on_front) {
  std::string out =
      "backend,quality,quality_value,width,height,threads,cold_median_s,cold_p95_s,warm_median_s,warm_p95_s,"
      "cold_runs,warm_runs,settle_frames,is_reference,pareto,rays_per_second_per_core,samples,bricks,bytes_read,rmse,psnr_db,ssim,"
      "depth_mean,depth_p99,depth_max,normal_mean_deg,normal_p99_deg,depth_pixels,normal_pixels,coverage_mismatch,"
      "coverage_mismatch_fraction,nonfinite_color_pixels,first_rmse,first_ssim,converged_median_s,converged_frames,"
      "still_median_s,still_frames,is_peer,peak_rss_bytes,description,image\n";
  for (size_t i = 0; i < report.rows.size(); ++i) {
    const BenchRow& r = report.rows[i];
    const ImageError& e = r.error;
    out += fmt::format("{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},", csv_field(r.backend),
                       csv_field(r.quality), csv_number(r.quality_value), r.width, r.height, r.threads,
                       csv_number(r.cold_median_s), csv_number(r.cold_p95_s), csv_number(r.warm_median_s),
                       csv_number(r.warm_p95_s), r.cold_runs, r.warm_runs, r.settle_frames, int(r.is_reference), int(on_front[i]),
                       csv_number(r.rays_per_second_per_core), r.samples, r.bricks, r.bytes_read);
    out += fmt::format("{},{},{},{},{},{},{},{},{},{},{},{},{},", csv_number(e.rmse), csv_number(e.psnr_db),
                       csv_number(e.ssim), csv_number(e.depth_mean), csv_number(e.depth_p99), csv_number(e.depth_max),
                       csv_number(e.normal_mean_deg), csv_number(e.normal_p99_deg), e.depth_pixels, e.normal_pixels,
                       e.coverage_mismatch, csv_number(e.coverage_mismatch_fraction), e.nonfinite_color_pixels);
    // The image stays last, where it always was; it is never empty for rendered rows.
    out += fmt::format("{},{},{},{},{},{},{},{},{},{}\n", csv_number(r.first_rmse), csv_number(r.first_ssim),
                       csv_number(r.converged_median_s), r.converged_frames, csv_number(r.still_median_s),
                       r.still_frames, int(r.is_peer), r.peak_rss_bytes,
                       csv_field(r.description), csv_field(r.image));
  }
  return out;
}

const char* bound_name(EqualErrorRow::Bound b) {
  switch (b) {
    case EqualErrorRow::Bound::interpolated: return "interpolated";
    case EqualErrorRow::Bound::at_most: return "at_most";
    case EqualErrorRow::Bound::at_least: return "at_least";
  }
  return "?";
}

std::string equal_error_csv_text(const std::vector<EqualErrorRow>& rows) {
  std::string out = "backend,against,against_quality,rmse,against_time_s,backend_time_s,time_bound,speedup,time\n";
  for (const EqualErrorRow& e : rows)
    out += fmt::format("{},{},{},{},{},{},{},{},{}\n", csv_field(e.backend), csv_field(e.against), csv_field(e.against_quality),
                       csv_number(e.rmse), csv_number(e.against_time_s), csv_number(e.backend_time_s), bound_name(e.bound),
                       csv_number(e.speedup()), e.time == BenchTime::warm ? "warm" : "converged");
  return out;
}

// --- error against time -----------------------------------------------------------------------

std::string error_plot_script(const BenchReport& report, const std::vector<size_t>& front) {
  const auto& rows = report.rows;
  // Step 1: ranges. Both axes are logarithmic, so only positive values count; rows with zero
  // error sit at `floor`, below every measured error.
  double t_min = INFINITY, t_max = 0, e_min = INFINITY, e_max = 0;
  for (const BenchRow& r : rows) {
    if (!plottable_time(r)) continue;
    t_min = std::min(t_min, r.warm_median_s * 1e3);
    t_max = std::max(t_max, r.warm_median_s * 1e3);
    if (!r.is_reference && std::isfinite(r.error.rmse) && r.error.rmse > 0) {
      e_min = std::min(e_min, r.error.rmse);
      e_max = std::max(e_max, r.error.rmse);
    }
  }
  if (t_max == 0) t_min = 1, t_max = 100;
  if (e_max == 0) e_min = 1e-3, e_max = 1e-1;
  auto on_plot = [&](const BenchRow& r) {
    return !r.is_reference && plottable_time(r) && std::isfinite(r.error.rmse) && r.error.rmse >= 0;
  };
  const bool any_exact = std::any_of(rows.begin(), rows.end(), [&](const BenchRow& r) { return on_plot(r) && r.error.rmse == 0; });
  const double floor = e_min / 4;
  const double x_lo = t_min / 1.6, x_hi = t_max * 1.6, y_lo = any_exact ? floor / 1.6 : e_min / 2, y_hi = e_max * 2.5;
  auto plotted_error = [&](const BenchRow& r) { return r.error.rmse > 0 ? r.error.rmse : floor; };

  std::string s = "set termoption noenhanced\n";
  s += fmt::format("set title {}\n", gnuplot_quote(one_line(report.title.empty() ? "bench" : report.title)));
  s += "set logscale xy\nset format x '%g'\nset format y '%g'\n"
       "set xlabel 'warm frame time, median (ms)'\nset ylabel 'colour RMSE against the reference'\n"
       "set grid xtics ytics mxtics mytics lc rgb '#dddddd'\nset key outside right top\n";
  s += fmt::format("set xrange [{}:{}]\nset yrange [{}:{}]\n", gp_number(x_lo), gp_number(x_hi), gp_number(y_lo),
                   gp_number(y_hi));
  s += log_tics("x", x_lo, x_hi) + log_tics("y", y_lo, y_hi);

  // Step 2: one datablock per back end, in quality order, and the front as a staircase that
  // runs on to the right edge (beyond its slowest point nothing is more accurate).
  std::vector<std::string> backends;
  for (const BenchRow& r : rows)
    if (on_plot(r) && std::find(backends.begin(), backends.end(), r.backend) == backends.end())
      backends.push_back(r.backend);
  std::vector<std::string> clauses;
  std::vector<size_t> sorted_front = front;
  std::erase_if(sorted_front, [&](size_t i) { return !on_plot(rows[i]); });
  std::sort(sorted_front.begin(), sorted_front.end(), [&](size_t a, size_t b) {
    return std::pair(rows[a].warm_median_s, rows[a].error.rmse) < std::pair(rows[b].warm_median_s, rows[b].error.rmse);
  });
  if (!sorted_front.empty()) {
    s += "$front << EOD\n";
    for (size_t i : sorted_front)
      s += fmt::format("{} {}\n", gp_number(rows[i].warm_median_s * 1e3), gp_number(plotted_error(rows[i])));
    s += fmt::format("{} {}\nEOD\n", gp_number(x_hi), gp_number(plotted_error(rows[sorted_front.back()])));
    clauses.push_back("$front using 1:2 with steps lw 10 lc rgb '#b0e69f00' title 'Pareto front'");
  }
  int label_id = 1;
  for (size_t b = 0; b < backends.size(); ++b) {
    std::vector<size_t> mine;
    for (size_t i = 0; i < rows.size(); ++i)
      if (on_plot(rows[i]) && rows[i].backend == backends[b]) mine.push_back(i);
    std::stable_sort(mine.begin(), mine.end(), [&](size_t x, size_t y) { return rows[x].quality_value < rows[y].quality_value; });
    s += fmt::format("$b{} << EOD\n", b);
    std::string labels;
    for (size_t i : mine) {
      const BenchRow& r = rows[i];
      s += fmt::format("{} {}\n", gp_number(r.warm_median_s * 1e3), gp_number(plotted_error(r)));
      std::string text = one_line(r.quality);
      if (r.error.rmse == 0) text += text.empty() ? "(RMSE 0)" : " (RMSE 0)";
      if (!text.empty())
        labels += fmt::format("set label {} {} at {},{} offset char 0.7,0.7 font ',8' tc lt {} front\n", label_id++,
                         gnuplot_quote(text), gp_number(r.warm_median_s * 1e3), gp_number(plotted_error(r)), b + 1);
    }
    s += "EOD\n" + labels;
    clauses.push_back(fmt::format("$b{} using 1:2 with linespoints lt {} lw 2 pt 7 ps 1.2 title {}", b, b + 1,
                                  gnuplot_quote(one_line(backends[b]))));
  }
  if (!sorted_front.empty())
    clauses.push_back("$front using 1:2 every ::0::" + std::to_string(sorted_front.size() - 1) +
                      " with points pt 6 ps 2.4 lw 2 lc rgb '#e69f00' notitle");

  // Step 3: the reference's time as a dashed vertical line with its label.
  int arrow_id = 1;
  for (const BenchRow& r : rows) {
    if (!r.is_reference || !plottable_time(r)) continue;
    const double t = r.warm_median_s * 1e3;
    const std::string text = fmt::format("{}, {} ms", row_label(r), ms(r.warm_median_s));
    s += fmt::format("set arrow {} from {}, graph 0 to {}, graph 1 nohead dt 2 lw 2 lc rgb '#555555' front\n",
                     arrow_id++, gp_number(t), gp_number(t));
    s += fmt::format("set label {} {} at {}, graph 0.97 rotate by 90 right offset char -0.9,0 font ',9' front\n",
                     label_id++, gnuplot_quote(text), gp_number(t));
  }
  // An empty chart still needs one plot clause; NaN draws nothing.
  if (clauses.empty()) clauses.push_back("NaN notitle");
  s += "plot ";
  for (size_t i = 0; i < clauses.size(); ++i) s += (i ? ", \\\n     " : "") + clauses[i];
  s += "\n";
  return s;
}

// --- contact sheet -----------------------------------------------------------------------------

struct SheetCell {
  std::string path, title;
  int width, height;  // of the image, for its aspect
};

constexpr int kCellWidth = 360, kTitleHeight = 22, kSheetTitleHeight = 34, kGap = 6;

/// The multiplot script of the contact sheet, and the canvas size it needs.
std::string contact_sheet_script(const std::string& title, const std::vector<SheetCell>& cells, int& width, int& height) {
  const int n = int(cells.size());
  const int cols = std::min(n, std::max(1, int(std::ceil(std::sqrt(double(n))))));
  const int rows = (n + cols - 1) / cols;
  double aspect = 0;  // the tallest image's height / width sets the cell height
  for (const SheetCell& c : cells) aspect = std::max(aspect, c.width > 0 && c.height > 0 ? double(c.height) / c.width : 0.75);
  const int image_h = int(std::lround((kCellWidth - 2 * kGap) * std::min(aspect, 2.0)));
  const int cell_h = image_h + kTitleHeight + kGap;
  width = cols * kCellWidth;
  height = kSheetTitleHeight + rows * cell_h;

  std::string s = "set termoption noenhanced\n";
  s += fmt::format("set multiplot title {} font ',12'\n", gnuplot_quote(one_line(title.empty() ? "bench" : title)));
  s += "unset border\nunset tics\nunset key\nunset colorbox\nset autoscale fix\n";
  for (int i = 0; i < n; ++i) {
    const SheetCell& c = cells[size_t(i)];
    // The image area of this cell in pixels from the top-left, fitted to the image's aspect.
    const int col = i % cols, row = i / cols;
    const double a = c.width > 0 && c.height > 0 ? double(c.height) / c.width : 0.75;
    double w = kCellWidth - 2 * kGap, h = w * a;
    if (h > image_h) h = image_h, w = h / a;
    const double left = col * kCellWidth + (kCellWidth - w) / 2;
    const double top = kSheetTitleHeight + row * cell_h + kTitleHeight + (image_h - h) / 2;
    auto sx = [&](double px) { return gp_number(px / width); };
    auto sy = [&](double px) { return gp_number(1 - px / height); };
    s += fmt::format("set lmargin at screen {}\nset rmargin at screen {}\nset tmargin at screen {}\nset bmargin at screen {}\n",
                     sx(left), sx(left + w), sy(top), sy(top + h));
    s += fmt::format("set title {} font ',9' offset 0,-0.6\n", gnuplot_quote(c.title));
    s += fmt::format("plot {} binary filetype=png with rgbimage\n", gnuplot_quote(c.path));
  }
  s += "unset multiplot\n";
  return s;
}

// --- Markdown ------------------------------------------------------------------------------------

/// "640×480 px" when every row agrees, else the distinct values.
template <typename F>
std::string distinct(const std::vector<BenchRow>& rows, F&& f) {
  std::vector<std::string> seen;
  for (const BenchRow& r : rows) {
    std::string v = f(r);
    if (std::find(seen.begin(), seen.end(), v) == seen.end()) seen.push_back(std::move(v));
  }
  std::string out;
  for (const std::string& v : seen) out += (out.empty() ? "" : ", ") + v;
  return out;
}

/// The equal-error table: a back end's time as "≤ 12.3" / "≥ 12.3" / "12.3" ms, and the speed-up likewise.
std::string equal_error_markdown(const std::vector<EqualErrorRow>& rows, BenchTime which) {
  if (std::none_of(rows.begin(), rows.end(), [&](const EqualErrorRow& e) { return e.time == which; })) return "";
  std::string s =
      which == BenchTime::warm
          ? "## At equal error: steady frames\n\n"
            "Each back end's warm time at the RMSE of every row of another, interpolated log-log along its own Pareto "
            "front; ≤ where its fastest row is already more accurate (that row's time), ≥ where none is that accurate "
            "(its most accurate row's time). Speed-up: the other's time over this one's (above 1: faster).\n\n"
          : "## At equal error: from empty caches to the converged image\n\n"
            "The same comparison with the time from empty caches to a still camera's converged image (Still; "
            "Converged where Still was not measured; for a peer, its first frame) in place of the warm frame's.\n\n";
  s += "| Backend | Against | At RMSE of | RMSE | Against ms | Backend ms | Speed-up |\n"
       "|---|---|---|--:|--:|--:|--:|\n";
  for (const EqualErrorRow& e : rows) {
    if (e.time != which) continue;
    const char* time_mark = e.bound == EqualErrorRow::Bound::at_most ? "≤ " : e.bound == EqualErrorRow::Bound::at_least ? "≥ " : "";
    const char* speed_mark = e.bound == EqualErrorRow::Bound::at_most ? "≥ " : e.bound == EqualErrorRow::Bound::at_least ? "≤ " : "";
    s += fmt::format("| {} | {} | {} | {:.4g} | {} | {}{} | {}{:.2f}× |\n", md_cell(e.backend), md_cell(e.against),
                     md_cell(e.against_quality.empty() ? e.against : e.against_quality), e.rmse, ms(e.against_time_s),
                     time_mark, ms(e.backend_time_s), speed_mark, e.speedup());
  }
  return s + "\n";
}

std::string markdown_text(const std::string& dir, const BenchReport& report, const std::vector<bool>& on_front,
                          const std::vector<EqualErrorRow>& equal_error, const BenchReportPaths& written) {
  const auto& rows = report.rows;
  std::string s = fmt::format("# Bench: {}\n\n", md_cell(report.title.empty() ? "bench" : report.title));
  if (!rows.empty()) {
    s += fmt::format("{} rows; frames of {} px; {} threads; runs per row: {} cold, {} warm.\n\n", rows.size(),
                     distinct(rows, [](const BenchRow& r) { return fmt::format("{}×{}", r.width, r.height); }),
                     distinct(rows, [](const BenchRow& r) { return std::to_string(r.threads); }),
                     distinct(rows, [](const BenchRow& r) { return std::to_string(r.cold_runs); }),
                     distinct(rows, [](const BenchRow& r) { return std::to_string(r.warm_runs); }));
  }
  if (!written.error_plot.empty()) s += "![Colour RMSE against warm frame time](error-vs-time.png)\n\n";

  s += "| Backend | Quality | First frame ms | First RMSE | Converged ms | Frames | Still ms | Still frames "
       "| Warm median ms | Warm p95 ms | Rays/s/core | Read/frame | RMSE | PSNR dB | SSIM | Depth mean vox "
       "| Depth p99 vox | Normal mean ° | Coverage mismatch % | Pareto | Image |\n";
  s += "|---|---|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|:-:|---|\n";
  std::vector<std::string> nonfinite;
  for (size_t i = 0; i < rows.size(); ++i) {
    const BenchRow& r = rows[i];
    const ImageError& e = r.error;
    std::string image = "";
    if (!r.image.empty())
      image = fs::exists(fs::path(dir) / r.image) ? fmt::format("[png]({})", md_link_target(r.image)) : "missing";
    std::string errors;
    if (r.is_reference) {
      errors = "truth | — | — | — | — | — | —";
    } else {
      errors = fmt::format("{:.4g} | {} | {:.4f} | {} | {} | {} | {}", e.rmse,
                           std::isinf(e.psnr_db) ? std::string("∞") : fmt::format("{:.1f}", e.psnr_db), e.ssim,
                           e.depth_pixels ? sig3(e.depth_mean) : "—", e.depth_pixels ? sig3(e.depth_p99) : "—",
                           e.normal_pixels ? fmt::format("{:.2f}", e.normal_mean_deg) : "—",
                           sig3(e.coverage_mismatch_fraction * 100));
      if (e.nonfinite_color_pixels) nonfinite.push_back(fmt::format("{} ({})", row_label(r), e.nonfinite_color_pixels));
    }
    const bool cold = r.cold_runs > 0;
    s += fmt::format("| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |\n", md_cell(r.backend),
                     md_cell(r.quality), cold ? ms(r.cold_median_s) : "—",
                     cold && std::isfinite(r.first_rmse) ? fmt::format("{:.4g}", r.first_rmse) : "—",
                     std::isfinite(r.converged_median_s) ? ms(r.converged_median_s) : "—",
                     std::isfinite(r.converged_median_s) ? std::to_string(r.converged_frames) : "—",
                     std::isfinite(r.still_median_s) ? ms(r.still_median_s) : "—",
                     std::isfinite(r.still_median_s) ? std::to_string(r.still_frames) : "—", ms(r.warm_median_s),
                     ms(r.warm_p95_s), r.is_peer ? "—" : format_count(r.rays_per_second_per_core),
                     r.is_peer ? "—" : format_bytes(double(r.bytes_read)), errors, on_front[i] ? "★" : "", image);
  }
  s += "\n";
  if (!nonfinite.empty()) {
    s += "**Warning**: non-finite colour (NaN or infinity) in";
    for (size_t i = 0; i < nonfinite.size(); ++i) s += (i ? ", " : " ") + md_cell(nonfinite[i]);
    s += " pixels; each counts as the largest error.\n\n";
  }
  s += equal_error_markdown(equal_error, BenchTime::warm);
  s += equal_error_markdown(equal_error, BenchTime::converged);
  std::string peers;
  for (const BenchRow& r : rows)
    if (r.is_peer)
      peers += fmt::format("- **{}** {}: {}{}\n", md_cell(r.backend), md_cell(r.quality), md_cell(r.description),
                           r.peak_rss_bytes ? fmt::format("; peak resident memory {}", format_bytes(double(r.peak_rss_bytes))) : "");
  if (!peers.empty())
    s += "## Peers\n\nOther programs' renderers on the same view, timed by the script that ran them (bench/peers); their "
         "error is computed here from their colour images, against the same reference.\n\n" + peers + "\n";
  s += "Legend:\n\n"
       "- **First frame**: the first frame from empty caches, and its RMSE: a back end that refines as its data "
       "arrives shows a coarse or incomplete image first. **Converged**: the wall time from empty caches to the "
       "converged image, the frames rendered one after another as they would be shown, each followed by the loads "
       "it asked for; **Frames**: how many that took. **Still**: the same wait for a still camera's image asked "
       "for at once (`brickyard render`): no frame before it is shown, so a back end may complete each one where "
       "it would refine it over frames shown; **Still frames**: how many that took. **Warm**: the same frame "
       "again with the caches filled and the image converged. Medians (and 95th percentile) over the runs; a peer's times are its first frame and "
       "its steady frames.\n"
       "- **Rays/s/core**: primary rays per second per thread on a warm frame; **Read/frame**: bytes read from "
       "the store during a warm frame.\n"
       "- **RMSE**: root mean square difference of the R, G, B values (0 to 1) from the reference image; "
       "**PSNR** = 20 log10(1 / RMSE) (∞ for identical images); **SSIM**: structural similarity of luminance "
       "(1 for identical images).\n"
       "- **Depth**: |depth difference| in voxels where both images hit something (mean, 99th percentile); "
       "**Normal**: mean angle between surface normals in degrees; — where not measured.\n"
       "- **Coverage mismatch**: pixels hit in exactly one of the two images.\n"
       "- **Pareto** ★: no other row is at least as fast (warm median) and at least as accurate (RMSE) and "
       "strictly better in one. The reference is the truth (error 0 by definition) and is not ranked.\n"
       "- Every figure is in bench.csv at full precision.\n\n";
  if (!written.contact_sheet.empty()) s += "## Images\n\n![Contact sheet](contact-sheet.png)\n";
  return s;
}

}  // namespace

std::vector<size_t> pareto_front(const std::vector<BenchRow>& rows) {
  auto candidate = [](const BenchRow& r) {
    return !r.is_reference && !std::isnan(r.warm_median_s) && !std::isnan(r.error.rmse);
  };
  // O(n^2): a bench has tens of rows, and the definition reads off the code.
  std::vector<size_t> front;
  for (size_t i = 0; i < rows.size(); ++i) {
    if (!candidate(rows[i])) continue;
    const double t = rows[i].warm_median_s, e = rows[i].error.rmse;
    bool dominated = false;
    for (size_t j = 0; j < rows.size() && !dominated; ++j) {
      if (j == i || !candidate(rows[j])) continue;
      const double tj = rows[j].warm_median_s, ej = rows[j].error.rmse;
      dominated = tj <= t && ej <= e && (tj < t || ej < e);
    }
    if (!dominated) front.push_back(i);
  }
  return front;
}

double time_of(const BenchRow& r, BenchTime which) {
  if (which == BenchTime::warm) return r.warm_median_s;
  return std::isfinite(r.still_median_s) ? r.still_median_s : r.converged_median_s;
}

std::vector<EqualErrorRow> equal_error_rows(const std::vector<BenchRow>& rows, BenchTime which) {
  auto t = [which](const BenchRow& r) { return time_of(r, which); };
  auto comparable = [&](const BenchRow& r) {
    return !r.is_reference && std::isfinite(t(r)) && t(r) > 0 && std::isfinite(r.error.rmse) && r.error.rmse > 0;
  };
  std::vector<std::string> backends;
  for (const BenchRow& r : rows)
    if (comparable(r) && std::find(backends.begin(), backends.end(), r.backend) == backends.end()) backends.push_back(r.backend);

  std::vector<EqualErrorRow> out;
  for (const std::string& backend : backends) {
    // Its curve: its own Pareto front, fastest first (error never rises along it; equal times
    // only for identical rows).
    std::vector<BenchRow> own;
    for (const BenchRow& r : rows)
      if (comparable(r) && r.backend == backend) {
        own.push_back(r);
        own.back().warm_median_s = t(r);  // pareto_front() ranks by warm time
      }
    std::vector<const BenchRow*> curve;
    for (size_t i : pareto_front(own)) curve.push_back(&own[i]);
    std::sort(curve.begin(), curve.end(), [](const BenchRow* a, const BenchRow* b) {
      return a->warm_median_s < b->warm_median_s || (a->warm_median_s == b->warm_median_s && a->error.rmse > b->error.rmse);
    });
    for (const std::string& against : backends) {
      if (against == backend) continue;
      for (const BenchRow& r : rows) {
        if (!comparable(r) || r.backend != against) continue;
        EqualErrorRow e;
        e.backend = backend, e.against = against, e.against_quality = r.quality;
        e.rmse = r.error.rmse, e.against_time_s = t(r);
        e.time = which;
        if (e.rmse >= curve.front()->error.rmse) {
          e.backend_time_s = curve.front()->warm_median_s;
          e.bound = e.rmse == curve.front()->error.rmse ? EqualErrorRow::Bound::interpolated : EqualErrorRow::Bound::at_most;
        } else if (e.rmse < curve.back()->error.rmse) {
          e.backend_time_s = curve.back()->warm_median_s;
          e.bound = EqualErrorRow::Bound::at_least;
        } else {
          size_t i = 0;  // curve[i] less accurate than rmse, curve[i + 1] at least as accurate
          while (curve[i + 1]->error.rmse > e.rmse) ++i;
          const BenchRow& a = *curve[i];
          const BenchRow& b = *curve[i + 1];
          const double f = std::log(a.error.rmse / e.rmse) / std::log(a.error.rmse / b.error.rmse);
          // At b's own error, b's own time, not pow's rounding of it.
          e.backend_time_s = f == 1 ? b.warm_median_s : a.warm_median_s * std::pow(b.warm_median_s / a.warm_median_s, f);
          e.bound = EqualErrorRow::Bound::interpolated;
        }
        out.push_back(std::move(e));
      }
    }
  }
  return out;
}

BenchReportPaths write_bench_report(const std::string& dir, const BenchReport& report) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) throw Error(Errc::io, fmt::format("cannot create the report directory: {}", ec.message())).with_file(dir);

  const std::vector<size_t> front = pareto_front(report.rows);
  std::vector<bool> on_front(report.rows.size(), false);
  for (size_t i : front) on_front[i] = true;
  auto in_dir = [&](const char* name) { return (fs::path(dir) / name).string(); };

  BenchReportPaths paths;
  paths.csv = in_dir("bench.csv");
  write_text(paths.csv, csv_text(report, on_front));
  std::vector<EqualErrorRow> equal_error = equal_error_rows(report.rows);
  for (EqualErrorRow& e : equal_error_rows(report.rows, BenchTime::converged)) equal_error.push_back(std::move(e));
  paths.equal_error_csv = in_dir("equal-error.csv");
  write_text(paths.equal_error_csv, equal_error_csv_text(equal_error));

  // The charts: a failure is remembered, bench.md is written without that chart, then it is
  // thrown. A chart not drawn this time is removed, so the directory never mixes two runs.
  std::optional<Error> chart_error;
  auto chart = [&](const std::string& path, auto&& draw) {
    try {
      draw(path);
      return path;
    } catch (const Error& e) {
      if (!chart_error) chart_error = e;
      fs::remove(path, ec);
      return std::string();
    }
  };
  paths.error_plot = chart(in_dir("error-vs-time.png"), [&](const std::string& png) {
    run_gnuplot(error_plot_script(report, front), png, 1000, 650);
  });
  std::vector<SheetCell> cells;
  for (const BenchRow& r : report.rows) {
    if (r.image.empty()) continue;
    const std::string path = (fs::path(dir) / r.image).string();
    if (!fs::exists(path)) continue;
    std::string title = fmt::format("{}, {} ms", row_label(r), ms(r.warm_median_s));
    title += r.is_reference ? ", reference" : fmt::format(", RMSE {:.3g}", r.error.rmse);
    cells.push_back({path, title, r.width, r.height});
  }
  if (!cells.empty())
    paths.contact_sheet = chart(in_dir("contact-sheet.png"), [&](const std::string& png) {
      int width = 0, height = 0;
      const std::string script = contact_sheet_script(report.title, cells, width, height);
      run_gnuplot(script, png, width, height);
    });
  else
    fs::remove(in_dir("contact-sheet.png"), ec);

  paths.markdown = in_dir("bench.md");
  write_text(paths.markdown, markdown_text(dir, report, on_front, equal_error, paths));
  if (chart_error) throw *chart_error;
  return paths;
}

}  // namespace brickyard
