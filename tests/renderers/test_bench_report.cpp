// The bench report (CSV, Markdown, charts) and the gnuplot runner it draws with.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string>
#include <vector>

#include "core/error.h"
#include "core/image.h"
#include "core/plot.h"
#include "report/bench_report.h"
#include "test_util.h"

namespace brickyard {
namespace {

namespace fs = std::filesystem;

BenchRow row(std::string backend, std::string quality, double quality_value, double warm_s, double rmse) {
  BenchRow r;
  r.backend = std::move(backend);
  r.quality = std::move(quality);
  r.quality_value = quality_value;
  r.width = 64;
  r.height = 48;
  r.threads = 2;
  r.cold_median_s = warm_s * 3;
  r.cold_p95_s = warm_s * 3.5;
  r.warm_median_s = warm_s;
  r.warm_p95_s = warm_s * 1.2;
  r.cold_runs = 3;
  r.warm_runs = 5;
  r.error.rmse = rmse;
  r.error.psnr_db = rmse > 0 ? 20 * std::log10(1 / rmse) : std::numeric_limits<double>::infinity();
  r.error.ssim = 1 - rmse;
  r.rays_per_second_per_core = 1.5e6;
  r.samples = 123456;
  r.bricks = 789;
  r.bytes_read = 1 << 20;
  return r;
}

BenchRow reference_row(double warm_s) {
  BenchRow r = row("reference", "", 0, warm_s, 0);
  r.is_reference = true;
  return r;
}

/// RFC 4180 records of `text` (quoted fields may hold commas, quotes and line breaks).
std::vector<std::vector<std::string>> parse_csv(const std::string& text) {
  std::vector<std::vector<std::string>> records(1, std::vector<std::string>(1));
  bool quoted = false;
  for (size_t i = 0; i < text.size(); ++i) {
    const char c = text[i];
    auto& field = records.back().back();
    if (quoted) {
      if (c == '"' && i + 1 < text.size() && text[i + 1] == '"') field += '"', ++i;
      else if (c == '"') quoted = false;
      else field += c;
    } else if (c == '"') {
      quoted = true;
    } else if (c == ',') {
      records.back().emplace_back();
    } else if (c == '\n') {
      records.emplace_back(1);
    } else if (c != '\r') {
      field += c;
    }
  }
  if (records.back().size() == 1 && records.back()[0].empty()) records.pop_back();
  return records;
}

std::vector<std::string> lines_starting_with(const std::string& text, const std::string& prefix) {
  std::vector<std::string> out;
  size_t start = 0;
  while (start < text.size()) {
    size_t end = text.find('\n', start);
    if (end == std::string::npos) end = text.size();
    const std::string line = text.substr(start, end - start);
    if (line.rfind(prefix, 0) == 0) out.push_back(line);
    start = end + 1;
  }
  return out;
}

bool has_partial_files(const fs::path& dir) {
  for (const auto& entry : fs::recursive_directory_iterator(dir))
    if (entry.path().string().find(".partial") != std::string::npos) return true;
  return false;
}

/// A report of two back ends over a quality sweep, with small images on disk.
BenchReport sample_report(const testing::TempDir& dir) {
  BenchReport report;
  report.title = "sample scene, fbm 96^3, 64x48, iso";
  report.rows = {reference_row(0.200),
                 row("raymarch", "step=1, lod=1", 1, 0.010, 0.05),  // comma: must be quoted in the CSV
                 row("raymarch", "step=0.5, lod=1", 0.5, 0.020, 0.02),
                 row("raymarch", "step=0.25, lod=1", 0.25, 0.040, 0.015),
                 row("dda", "\"exact\" cells", 1, 0.030, 0.03),  // dominated by step=0.5
                 row("dda", "it's | odd", 2, 0.060, 0.0)};       // zero error, not the reference
  for (size_t i = 0; i < report.rows.size(); ++i) {
    ImageRGBA8 image(64, 48, Rgba8{uint8_t(40 * i), 90, uint8_t(255 - 40 * i), 255});
    for (int y = 10; y < 30; ++y)
      for (int x = 20; x < 44; ++x) image(x, y) = Rgba8{250, 250, 250, 255};
    report.rows[i].image = "images/row " + std::to_string(i) + " (it's).png";  // spaces, parentheses, a quote
    fs::create_directories(dir.path() / "images");
    write_png(dir.file(report.rows[i].image), image);
  }
  return report;
}

TEST(ParetoFront, ExcludesDominatedRowsAndTheReference) {
  const std::vector<BenchRow> rows = {reference_row(1.0),        // 0: fastest of all, but the truth
                                      row("a", "", 0, 0.010, 0.10),   // 1: fastest candidate
                                      row("a", "", 0, 0.020, 0.05),   // 2
                                      row("b", "", 0, 0.030, 0.07),   // 3: dominated by 2
                                      row("b", "", 0, 0.040, 0.01),   // 4: most accurate
                                      row("c", "", 0, 0.050, 0.01)};  // 5: as accurate as 4, slower
  EXPECT_EQ(pareto_front(rows), (std::vector<size_t>{1, 2, 4}));
}

TEST(ParetoFront, KeepsExactTiesAndDropsRowsEqualInOneAndWorseInTheOther) {
  const std::vector<BenchRow> rows = {row("a", "", 0, 0.010, 0.05), row("b", "", 0, 0.010, 0.05),  // identical: both
                                      row("c", "", 0, 0.010, 0.06),                                 // same time, worse
                                      row("d", "", 0, 0.005, 0.20), row("e", "", 0, 0.007, 0.20)};  // same error, slower
  EXPECT_EQ(pareto_front(rows), (std::vector<size_t>{0, 1, 3}));
}

TEST(ParetoFront, IgnoresUnmeasuredRowsAndMayBeEmpty) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  std::vector<BenchRow> rows = {row("a", "", 0, nan, 0.0), row("b", "", 0, 0.02, nan), row("c", "", 0, 0.03, 0.1)};
  EXPECT_EQ(pareto_front(rows), (std::vector<size_t>{2}));
  EXPECT_TRUE(pareto_front({reference_row(1.0)}).empty());
  EXPECT_TRUE(pareto_front({}).empty());
}

const EqualErrorRow* find_equal_error(const std::vector<EqualErrorRow>& rows, const std::string& backend,
                                      const std::string& against, const std::string& quality) {
  for (const EqualErrorRow& e : rows)
    if (e.backend == backend && e.against == against && e.against_quality == quality) return &e;
  return nullptr;
}

/// `backend` at the error of `against`'s row `quality`: found, with this bound and time.
void expect_equal_error(const std::vector<EqualErrorRow>& rows, const std::string& backend, const std::string& against,
                        const std::string& quality, EqualErrorRow::Bound bound, double time_s) {
  const EqualErrorRow* e = find_equal_error(rows, backend, against, quality);
  ASSERT_NE(e, nullptr) << backend << " at " << against << " " << quality;
  EXPECT_EQ(e->bound, bound) << backend << " at " << against << " " << quality;
  EXPECT_NEAR(e->backend_time_s, time_s, 1e-12) << backend << " at " << against << " " << quality;
}

TEST(EqualError, MatchesAPowerLawExactlyAndBoundsOutsideTheSweep) {
  // fast: time = 1e-4 / rmse at 0.01, 0.004, 0.002; a dominated row and unmeasured rows take no part.
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const std::vector<BenchRow> rows = {reference_row(5.0),
                                      row("fast", "q=1", 1, 0.010, 0.010),
                                      row("fast", "q=2", 2, 0.025, 0.004),
                                      row("fast", "q=3", 3, 0.050, 0.002),
                                      row("fast", "q=slow", 4, 0.060, 0.005),  // dominated by q=2
                                      row("fast", "q=nan", 5, nan, 0.001),
                                      row("slow", "s=1", 1, 0.100, 0.020),     // less accurate than all of fast
                                      row("slow", "s=2", 2, 0.200, 0.008),
                                      row("slow", "s=3", 3, 0.400, 0.004),     // exactly fast's q=2
                                      row("slow", "s=4", 4, 0.800, 0.001),     // more accurate than all of fast
                                      row("slow", "s=0", 5, 0.900, 0.0)};      // zero error: no log
  const std::vector<EqualErrorRow> eq = equal_error_rows(rows);
  ASSERT_EQ(eq.size(), 4u + 4u);  // fast at slow's 4 measured rows, slow at fast's 4
  using Bound = EqualErrorRow::Bound;
  expect_equal_error(eq, "fast", "slow", "s=2", Bound::interpolated, 1e-4 / 0.008);
  EXPECT_NEAR(find_equal_error(eq, "fast", "slow", "s=2")->speedup(), 0.200 / (1e-4 / 0.008), 1e-9);
  expect_equal_error(eq, "fast", "slow", "s=3", Bound::interpolated, 0.025);
  expect_equal_error(eq, "fast", "slow", "s=1", Bound::at_most, 0.010);  // its fastest row is already more accurate
  EXPECT_DOUBLE_EQ(find_equal_error(eq, "fast", "slow", "s=1")->speedup(), 10.0);
  expect_equal_error(eq, "fast", "slow", "s=4", Bound::at_least, 0.050);  // never that accurate
  EXPECT_EQ(find_equal_error(eq, "fast", "slow", "s=0"), nullptr);
  EXPECT_EQ(find_equal_error(eq, "slow", "fast", "q=nan"), nullptr);
  // The other way: slow at fast's errors, along slow's own curve (0.020 -> 0.008 -> 0.004 -> 0.001).
  expect_equal_error(eq, "slow", "fast", "q=1", Bound::interpolated,
                     0.100 * std::pow(2.0, std::log(0.020 / 0.010) / std::log(0.020 / 0.008)));
  // A dominated row is still compared against: 0.005 lies where slow's time is 0.0016 / rmse.
  expect_equal_error(eq, "slow", "fast", "q=slow", Bound::interpolated, 0.0016 / 0.005);
  // A back end of one row, at exactly its error; duplicate rows (both on its front) change nothing.
  const std::vector<EqualErrorRow> single = equal_error_rows(
      {row("one", "", 0, 0.3, 0.004), row("two", "t=1", 1, 0.1, 0.01), row("two", "t=2", 2, 0.2, 0.004),
       row("two", "t=2 again", 2, 0.2, 0.004), row("two", "t=3", 3, 0.4, 0.002),
       row("two", "t=inf", 4, std::numeric_limits<double>::infinity(), 0.001)});
  expect_equal_error(single, "one", "two", "t=2", Bound::interpolated, 0.3);
  expect_equal_error(single, "two", "one", "", Bound::interpolated, 0.2);
  EXPECT_EQ(find_equal_error(single, "one", "two", "t=inf"), nullptr);
  EXPECT_EQ(single.size(), 4u + 1u);
  // One back end, or none measured: nothing to compare.
  EXPECT_TRUE(equal_error_rows({reference_row(1.0), row("fast", "q=1", 1, 0.01, 0.01), row("fast", "q=2", 2, 0.02, 0.005)}).empty());
  EXPECT_TRUE(equal_error_rows({}).empty());
}

TEST(EqualError, TheGigaVoxelsDvrBenchmarkOfStop21) {
  // The figures the issue-7 note quotes (fBm 1024^3 u16, 512x512, warm medians): gigavoxels
  // 1.50x, 2.17x and 3.02x raymarch at raymarch's steps 1, 0.5 and 0.3.
  const std::vector<BenchRow> rows = {
      row("gigavoxels", "step=1", 1, 0.930, 0.003435), row("gigavoxels", "step=0.5", 0.5, 1.25, 0.002108),
      row("gigavoxels", "step=0.3", 0.3, 1.72, 0.00188), row("raymarch", "step=1", 1, 1.54, 0.002921),
      row("raymarch", "step=0.5", 0.5, 2.62, 0.002237), row("raymarch", "step=0.3", 0.3, 3.95, 0.002075)};
  const std::vector<EqualErrorRow> eq = equal_error_rows(rows);
  const double expected[] = {1.50, 2.17, 3.02};
  const char* steps[] = {"step=1", "step=0.5", "step=0.3"};
  for (int i = 0; i < 3; ++i) {
    const EqualErrorRow* e = find_equal_error(eq, "gigavoxels", "raymarch", steps[i]);
    ASSERT_NE(e, nullptr) << steps[i];
    EXPECT_EQ(e->bound, EqualErrorRow::Bound::interpolated) << steps[i];
    EXPECT_NEAR(e->speedup(), expected[i], 0.01) << steps[i];
  }
  // raymarch at gigavoxels' step=1 error: every raymarch row is more accurate.
  const EqualErrorRow* e = find_equal_error(eq, "raymarch", "gigavoxels", "step=1");
  ASSERT_NE(e, nullptr);
  EXPECT_EQ(e->bound, EqualErrorRow::Bound::at_most);
  EXPECT_DOUBLE_EQ(e->backend_time_s, 1.54);
}

TEST(BenchReport, EqualErrorIsWrittenAsCsvAndAMarkdownTable) {
  testing::TempDir dir;
  const BenchReport report = sample_report(dir);
  BenchReportPaths paths;
  try {
    paths = write_bench_report(dir.path().string(), report);
  } catch (const Error& e) {
    ASSERT_EQ(e.code(), Errc::unsupported) << e.what();
  }
  const auto eq = equal_error_rows(report.rows);
  // raymarch at dda's one measured row; dda (one row of 0.03) at raymarch's three.
  ASSERT_EQ(eq.size(), 4u);
  const auto records = parse_csv(testing::read_file(dir.file("equal-error.csv")));
  ASSERT_EQ(records.size(), eq.size() + 1);
  EXPECT_EQ(records[0], (std::vector<std::string>{"backend", "against", "against_quality", "rmse", "against_time_s",
                                                   "backend_time_s", "time_bound", "speedup", "time"}));
  for (size_t i = 1; i < records.size(); ++i) {
    ASSERT_EQ(records[i].size(), 9u);
    EXPECT_EQ(records[i][8], "warm");  // the sample's rows have no cold runs: no converged times
    EXPECT_EQ(records[i][6], i == 1 ? "interpolated" : i == 2 ? "at_most" : "at_least") << i;
    EXPECT_DOUBLE_EQ(std::stod(records[i][7]), eq[i - 1].speedup());
  }
  EXPECT_EQ(records[2][2], "step=1, lod=1");  // the comma survives quoting
  const std::string md = testing::read_file(dir.file("bench.md"));
  const size_t section = md.find("## At equal error");
  ASSERT_NE(section, std::string::npos) << md;
  const auto table = lines_starting_with(md.substr(section), "|");
  ASSERT_EQ(table.size(), eq.size() + 2);
  EXPECT_NE(table[3].find("| ≤ 30.0 | ≥ "), std::string::npos) << table[3];  // dda at raymarch step=1
  EXPECT_NE(table[4].find("| ≥ 30.0 | ≤ "), std::string::npos) << table[4];  // dda at raymarch step=0.5

  // One back end: a header-only CSV and no section.
  testing::TempDir one;
  BenchReport single;
  single.rows = {reference_row(1.0), row("raymarch", "step=1", 1, 0.01, 0.02)};
  try {
    write_bench_report(one.path().string(), single);
  } catch (const Error& e) {
    ASSERT_EQ(e.code(), Errc::unsupported) << e.what();
  }
  EXPECT_EQ(parse_csv(testing::read_file(one.file("equal-error.csv"))).size(), 1u);
  EXPECT_EQ(testing::read_file(one.file("bench.md")).find("At equal error"), std::string::npos);
}

TEST(GnuplotQuote, DoublesSingleQuotesAndRejectsLineBreaks) {
  EXPECT_EQ(gnuplot_quote("plain"), "'plain'");
  EXPECT_EQ(gnuplot_quote("it's \"x\" \\n"), "'it''s \"x\" \\n'");
  EXPECT_THROW(gnuplot_quote("two\nlines"), Error);
}

TEST(BenchReport, CsvHasEveryColumnOnEveryLineAndQuotesLabels) {
  testing::TempDir dir;
  const BenchReport report = sample_report(dir);
  BenchReportPaths paths;
  try {
    paths = write_bench_report(dir.file("out"), report);
  } catch (const Error& e) {
    ASSERT_EQ(e.code(), Errc::unsupported) << e.what();  // only the charts may fail (no gnuplot)
  }
  const auto records = parse_csv(testing::read_file(dir.file("out/bench.csv")));
  ASSERT_EQ(records.size(), report.rows.size() + 1);
  const size_t columns = records[0].size();
  EXPECT_EQ(columns, 42u);
  for (const auto& r : records) EXPECT_EQ(r.size(), columns);
  auto column = [&](const std::string& name) {
    return size_t(std::find(records[0].begin(), records[0].end(), name) - records[0].begin());
  };
  EXPECT_EQ(records[2][column("quality")], "step=1, lod=1");
  EXPECT_EQ(records[5][column("quality")], "\"exact\" cells");
  EXPECT_EQ(records[6][column("image")], "images/row 5 (it's).png");
  EXPECT_EQ(records[1][column("is_reference")], "1");
  EXPECT_EQ(records[1][column("pareto")], "0");
  EXPECT_EQ(records[2][column("pareto")], "1");
  EXPECT_EQ(records[5][column("pareto")], "0");
  EXPECT_EQ(records[6][column("psnr_db")], "inf");
  // Full precision: the numbers read back exactly.
  for (size_t i = 0; i < report.rows.size(); ++i) {
    EXPECT_EQ(std::stod(records[i + 1][column("warm_median_s")]), report.rows[i].warm_median_s);
    EXPECT_EQ(std::stod(records[i + 1][column("rmse")]), report.rows[i].error.rmse);
    EXPECT_EQ(std::stod(records[i + 1][column("cold_p95_s")]), report.rows[i].cold_p95_s);
  }
}

TEST(BenchReport, MarkdownHasOneTableLinePerRow) {
  testing::TempDir dir;
  const BenchReport report = sample_report(dir);
  try {
    write_bench_report(dir.path().string(), report);
  } catch (const Error& e) {
    ASSERT_EQ(e.code(), Errc::unsupported) << e.what();
  }
  const std::string md = testing::read_file(dir.file("bench.md"));
  const auto table = lines_starting_with(md.substr(0, md.find("## At equal error")), "|");
  ASSERT_EQ(table.size(), report.rows.size() + 2) << md;  // header, alignment, rows
  EXPECT_NE(md.find("sample scene"), std::string::npos);
  EXPECT_NE(md.find("Legend"), std::string::npos);
  EXPECT_NE(table[2].find("truth"), std::string::npos) << table[2];
  EXPECT_NE(table[3].find("★"), std::string::npos) << table[3];   // raymarch step=1: on the front
  EXPECT_EQ(table[6].find("★"), std::string::npos) << table[6];   // dda "exact": dominated
  EXPECT_NE(table[7].find("it's \\| odd"), std::string::npos) << table[7];  // the pipe is escaped
  EXPECT_NE(table[3].find("[png](images/row%201%20%28it%27s%29.png)"), std::string::npos) << table[3];
  // Every row has as many cells as the header.
  auto cells = [](const std::string& line) {
    size_t n = 0;
    for (size_t i = 0; i < line.size(); ++i) n += line[i] == '|' && (i == 0 || line[i - 1] != '\\');
    return n;
  };
  for (const auto& line : table) EXPECT_EQ(cells(line), cells(table[0])) << line;
}

TEST(BenchReport, ChartsAreReadablePngs) {
  if (!gnuplot_available()) GTEST_SKIP() << "gnuplot is not installed (apt-get install gnuplot-nox)";
  testing::TempDir dir;
  const BenchReport report = sample_report(dir);
  const BenchReportPaths paths = write_bench_report(dir.path().string(), report);
  EXPECT_EQ(paths.csv, dir.file("bench.csv"));
  EXPECT_EQ(paths.markdown, dir.file("bench.md"));
  ASSERT_EQ(paths.error_plot, dir.file("error-vs-time.png"));
  ASSERT_EQ(paths.contact_sheet, dir.file("contact-sheet.png"));
  const ImageRGBA8 plot = read_png(paths.error_plot);
  EXPECT_EQ(plot.width(), 1000);
  EXPECT_EQ(plot.height(), 650);
  const ImageRGBA8 sheet = read_png(paths.contact_sheet);
  EXPECT_EQ(sheet.width(), 3 * 360);  // six images: three columns of 360 pixels
  EXPECT_GT(sheet.height(), 2 * 200);
  // The sheet shows the images: their white squares are there, not just an empty canvas.
  size_t white = 0;
  for (int y = 0; y < sheet.height(); ++y)
    for (int x = 0; x < sheet.width(); ++x) white += sheet(x, y) == Rgba8{250, 250, 250, 255};
  EXPECT_GT(white, 6u * 100u);
  const std::string md = testing::read_file(paths.markdown);
  EXPECT_NE(md.find("](error-vs-time.png)"), std::string::npos);
  EXPECT_NE(md.find("](contact-sheet.png)"), std::string::npos);
  EXPECT_FALSE(has_partial_files(dir.path()));
}

TEST(BenchReport, WithoutImagesThereIsNoContactSheet) {
  if (!gnuplot_available()) GTEST_SKIP() << "gnuplot is not installed (apt-get install gnuplot-nox)";
  testing::TempDir dir;
  BenchReport report;
  report.rows = {reference_row(0.1), row("a", "", 1, 0.01, 0.1)};
  report.rows[1].image = "never-written.png";
  const BenchReportPaths paths = write_bench_report(dir.path().string(), report);
  EXPECT_TRUE(paths.contact_sheet.empty());
  EXPECT_FALSE(fs::exists(dir.file("contact-sheet.png")));
  EXPECT_NO_THROW(read_png(paths.error_plot));
  EXPECT_NE(testing::read_file(paths.markdown).find("| missing |"), std::string::npos);
  // Nothing plottable at all (only the reference) still gives a chart.
  report.rows = {reference_row(0.1)};
  EXPECT_NO_THROW(read_png(write_bench_report(dir.path().string(), report).error_plot));
}

TEST(BenchReport, AFailedChartRemovesTheOneAnEarlierRunLeft) {
  testing::TempDir dir;
  const BenchReport report = sample_report(dir);
  try {
    write_bench_report(dir.path().string(), report);
  } catch (const Error&) {
  }
  std::ofstream(dir.file("error-vs-time.png")) << "an earlier run's chart";
  fs::create_directories(dir.path() / "error-vs-time.png.partial" / "blocker");
  EXPECT_THROW(write_bench_report(dir.path().string(), report), Error);
  EXPECT_FALSE(fs::exists(dir.file("error-vs-time.png")));
}

TEST(BenchReport, FailingChartNamesItsFileAndLeavesNoPartialFile) {
  testing::TempDir dir;
  const BenchReport report = sample_report(dir);
  // A directory where gnuplot's output should go: it cannot open it, even as root.
  fs::create_directories(dir.path() / "error-vs-time.png.partial" / "blocker");
  try {
    write_bench_report(dir.path().string(), report);
    FAIL() << "expected an Error";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), Errc::unsupported);
    EXPECT_EQ(e.file(), dir.file("error-vs-time.png"));
    EXPECT_NE(std::string(e.what()).find("gnuplot"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(dir.file("error-vs-time.png")));
  // The data is still there, and the page does not link the missing chart.
  EXPECT_EQ(parse_csv(testing::read_file(dir.file("bench.csv"))).size(), report.rows.size() + 1);
  EXPECT_EQ(testing::read_file(dir.file("bench.md")).find("error-vs-time.png"), std::string::npos);
  // The blocker is ours, not a partial file of the report; remove it and check the rest.
  fs::remove_all(dir.path() / "error-vs-time.png.partial");
  EXPECT_FALSE(has_partial_files(dir.path()));
}

TEST(BenchReport, UnwritableDirectoryGivesAnErrorNamingIt) {
  testing::TempDir dir;
  std::ofstream(dir.file("a-file")) << "not a directory";
  try {
    write_bench_report(dir.file("a-file/report"), BenchReport{});
    FAIL() << "expected an Error";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), Errc::io);
    EXPECT_EQ(e.file(), dir.file("a-file/report"));
  }
  EXPECT_FALSE(has_partial_files(dir.path()));
}

TEST(RunGnuplot, FailureNamesThePngAndLeavesNoTemporaryFile) {
  testing::TempDir dir;
  // Keep the temporary script where this test can see it.
  const char* old_tmpdir = std::getenv("TMPDIR");
  const std::string saved = old_tmpdir ? old_tmpdir : "";
  fs::create_directories(dir.path() / "tmp");
  ::setenv("TMPDIR", dir.file("tmp").c_str(), 1);

  const std::string missing_dir_png = dir.file("no such dir/x.png");
  try {
    run_gnuplot("plot x\n", missing_dir_png);
    ADD_FAILURE() << "expected an Error";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), Errc::unsupported);
    EXPECT_EQ(e.file(), missing_dir_png);
    EXPECT_NE(std::string(e.what()).find("gnuplot failed or is missing (apt-get install gnuplot-nox)"), std::string::npos);
  }
  const std::string bad_script_png = dir.file("bad.png");
  try {
    run_gnuplot("plot sin(\n", bad_script_png);
    ADD_FAILURE() << "expected an Error";
  } catch (const Error& e) {
    EXPECT_EQ(e.file(), bad_script_png);
  }
  EXPECT_FALSE(fs::exists(bad_script_png));
  EXPECT_FALSE(has_partial_files(dir.path()));
  EXPECT_TRUE(fs::is_empty(dir.path() / "tmp"));

  if (old_tmpdir) ::setenv("TMPDIR", saved.c_str(), 1);
  else ::unsetenv("TMPDIR");
}

TEST(RunGnuplot, MissingGnuplotSaysHowToInstallIt) {
  testing::TempDir dir;
  const char* old_path = std::getenv("PATH");
  const std::string saved = old_path ? old_path : "";
  ::setenv("PATH", dir.path().c_str(), 1);  // an empty directory: no gnuplot on PATH
  EXPECT_FALSE(gnuplot_available());
  try {
    run_gnuplot("plot x\n", dir.file("x.png"));
    ADD_FAILURE() << "expected an Error";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), Errc::unsupported);
    EXPECT_EQ(e.file(), dir.file("x.png"));
    EXPECT_NE(std::string(e.what()).find("apt-get install gnuplot-nox"), std::string::npos) << e.what();
  }
  EXPECT_TRUE(fs::is_empty(dir.path()));
  ::setenv("PATH", saved.c_str(), 1);
}

TEST(RunGnuplot, WritesToPathsWithSpacesAndQuotes) {
  if (!gnuplot_available()) GTEST_SKIP() << "gnuplot is not installed (apt-get install gnuplot-nox)";
  testing::TempDir dir;
  fs::create_directories(dir.path() / "it's a \"dir\" $(x)");
  const std::string png = dir.file("it's a \"dir\" $(x)/plot; rm -rf x.png");
  run_gnuplot("plot sin(x) title " + gnuplot_quote("it's sin") + "\n", png, 320, 200);
  const ImageRGBA8 image = read_png(png);
  EXPECT_EQ(image.width(), 320);
  EXPECT_EQ(image.height(), 200);
  EXPECT_FALSE(has_partial_files(dir.path()));
}

}  // namespace
}  // namespace brickyard

namespace brickyard {
namespace {

TEST(BenchReport, ComparesTimesFromEmptyCachesToTheConvergedImage) {
  // "lod" converges in several frames (slow from cold) but is fast warm; "march" converges at
  // once. At equal error the warm comparison favours lod, the converged one march.
  std::vector<BenchRow> rows = {row("lod", "q=1", 1, 0.010, 0.02), row("march", "q=1", 1, 0.030, 0.02)};
  rows[0].converged_median_s = 0.300, rows[0].converged_frames = 9;
  rows[1].converged_median_s = 0.040, rows[1].converged_frames = 1;
  const std::vector<EqualErrorRow> warm = equal_error_rows(rows);
  const std::vector<EqualErrorRow> cold = equal_error_rows(rows, BenchTime::converged);
  ASSERT_EQ(warm.size(), 2u);
  ASSERT_EQ(cold.size(), 2u);
  EXPECT_EQ(warm[0].backend, "lod");
  EXPECT_DOUBLE_EQ(warm[0].speedup(), 3.0);
  EXPECT_EQ(warm[0].time, BenchTime::warm);
  EXPECT_EQ(cold[0].backend, "lod");
  EXPECT_DOUBLE_EQ(cold[0].backend_time_s, 0.300);
  EXPECT_DOUBLE_EQ(cold[0].speedup(), 0.040 / 0.300);
  EXPECT_EQ(cold[0].time, BenchTime::converged);
  // Where a still camera's wait was measured, that is the time compared: "lod" completes its
  // first frame in 0.06 s where the frames shown take 0.3.
  rows[0].still_median_s = 0.060, rows[0].still_frames = 1;
  const std::vector<EqualErrorRow> still = equal_error_rows(rows, BenchTime::converged);
  ASSERT_EQ(still.size(), 2u);
  EXPECT_DOUBLE_EQ(still[0].backend_time_s, 0.060);
  EXPECT_DOUBLE_EQ(still[0].speedup(), 0.040 / 0.060);
  rows[0].still_median_s = std::numeric_limits<double>::quiet_NaN();
  // A row without cold runs (NaN) takes no part in the converged comparison.
  rows[1].converged_median_s = std::numeric_limits<double>::quiet_NaN();
  EXPECT_TRUE(equal_error_rows(rows, BenchTime::converged).empty());
  EXPECT_EQ(equal_error_rows(rows).size(), 2u);
}

TEST(BenchReport, WritesFirstFrameConvergedAndPeerColumns) {
  testing::TempDir dir;
  BenchReport report = sample_report(dir);
  report.rows[1].cold_runs = 3, report.rows[1].cold_median_s = 0.004;
  report.rows[1].first_rmse = 0.21, report.rows[1].first_ssim = 0.5;
  report.rows[1].converged_median_s = 0.25, report.rows[1].converged_frames = 7;
  report.rows[1].still_median_s = 0.1, report.rows[1].still_frames = 2;
  report.rows[2].converged_median_s = 0.03, report.rows[2].converged_frames = 1;
  BenchRow peer = row("vtk-fixed-point", "sample=1", 1, 0.15, 0.03);
  peer.is_peer = true, peer.description = "VTK 9.1 vtkFixedPointVolumeRayCastMapper, 2 threads";
  peer.peak_rss_bytes = uint64_t(3) << 30;
  peer.cold_runs = 1, peer.cold_median_s = peer.converged_median_s = 0.5, peer.converged_frames = 1;
  report.rows.push_back(peer);
  try {
    write_bench_report(dir.path().string(), report);
  } catch (const Error& e) {
    ASSERT_EQ(e.code(), Errc::unsupported) << e.what();
  }
  const auto records = parse_csv(testing::read_file(dir.file("bench.csv")));
  ASSERT_EQ(records.size(), report.rows.size() + 1);
  auto column = [&](const std::string& name) {
    const auto at = std::find(records[0].begin(), records[0].end(), name);
    EXPECT_NE(at, records[0].end()) << name;
    return size_t(at - records[0].begin());
  };
  EXPECT_EQ(records[2][column("first_rmse")], "0.21");
  EXPECT_EQ(records[2][column("converged_median_s")], "0.25");
  EXPECT_EQ(records[2][column("converged_frames")], "7");
  EXPECT_EQ(records[2][column("still_median_s")], "0.1");
  EXPECT_EQ(records[2][column("still_frames")], "2");
  EXPECT_EQ(records[4][column("still_median_s")], "nan");
  EXPECT_EQ(records[2][column("is_peer")], "0");
  EXPECT_EQ(records[4][column("converged_median_s")], "nan");  // no cold runs: not measured
  const auto& p = records.back();
  EXPECT_EQ(p[column("backend")], "vtk-fixed-point");
  EXPECT_EQ(p[column("is_peer")], "1");
  EXPECT_EQ(p[column("peak_rss_bytes")], std::to_string(uint64_t(3) << 30));
  EXPECT_EQ(p[column("description")], "VTK 9.1 vtkFixedPointVolumeRayCastMapper, 2 threads");
  for (const auto& r : records) EXPECT_EQ(r.size(), records[0].size());

  const std::string md = testing::read_file(dir.file("bench.md"));
  EXPECT_NE(md.find("| raymarch | step=1, lod=1 | 4.00 | 0.21 | 250 | 7 | 100 | 2 |"), std::string::npos) << md;
  EXPECT_NE(md.find("## At equal error: from empty caches to the converged image"), std::string::npos) << md;
  EXPECT_NE(md.find("## Peers"), std::string::npos) << md;
  EXPECT_NE(md.find("**vtk-fixed-point** sample=1: VTK 9.1 vtkFixedPointVolumeRayCastMapper, 2 threads; peak resident "
                    "memory 3 GiB"),
            std::string::npos)
      << md;
  const auto eq = parse_csv(testing::read_file(dir.file("equal-error.csv")));
  EXPECT_TRUE(std::any_of(eq.begin(), eq.end(), [](const std::vector<std::string>& r) { return r.back() == "converged"; }));
}

}  // namespace
}  // namespace brickyard
