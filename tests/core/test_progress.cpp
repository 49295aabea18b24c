#include <gtest/gtest.h>

#include <sstream>
#include <thread>
#include <vector>

#include "core/progress.h"

namespace brickyard {
namespace {

TEST(Progress, LinesReportPercentRateAndEta) {
  std::ostringstream out;
  {
    Progress p("generate test", 1000, "voxels", {ProgressStyle::lines, &out, 0.0, 0.0});
    p.advance(250);
    p.advance(250);
  }
  const std::string s = out.str();
  EXPECT_NE(s.find("generate test: 25% (250 voxels of 1k voxels)"), std::string::npos) << s;
  EXPECT_NE(s.find("voxels/s"), std::string::npos) << s;
  EXPECT_NE(s.find("ETA"), std::string::npos) << s;
  // The closing line reports the total, once, even though the destructor also finishes.
  EXPECT_NE(s.find("generate test: 500 voxels in"), std::string::npos) << s;
  EXPECT_EQ(s.find("500 voxels in"), s.rfind("500 voxels in"));
}

TEST(Progress, AResumedTaskCountsEarlierWorkAsDoneButNotInItsRate) {
  std::ostringstream out;
  {
    Progress p("import", 1000, "B", {ProgressStyle::lines, &out, 0.0, 0.0});
    p.start_at(900);
    p.advance(50);
  }
  const std::string s = out.str();
  EXPECT_NE(s.find("import: 95% (950 B of 1000 B)"), std::string::npos) << s;
  // The closing line is this run's work, and its rate is of that alone.
  EXPECT_NE(s.find("import: 50 B in"), std::string::npos) << s;
}

TEST(Progress, BarRedrawsInPlace) {
  std::ostringstream out;
  Progress p("import", 10, "bricks", {ProgressStyle::bar, &out, 0.0, 0.0});
  p.advance(5);
  EXPECT_NE(out.str().find("\r"), std::string::npos);
  EXPECT_NE(out.str().find("[=============="), std::string::npos) << out.str();
  EXPECT_NE(out.str().find(" 50%"), std::string::npos) << out.str();
  p.finish();
  EXPECT_EQ(out.str().back(), '\n');
}

TEST(Progress, QuietPrintsNothing) {
  std::ostringstream out;
  {
    Progress p("x", 10, "", {ProgressStyle::quiet, &out, 0.0, 0.0});
    p.advance(10);
  }
  EXPECT_TRUE(out.str().empty());
}

TEST(Progress, DefaultStyleFollowsGlobalQuiet) {
  std::ostringstream out;
  set_default_progress_style(ProgressStyle::quiet);
  {
    Progress p("x", 10, "", {ProgressStyle::automatic, &out, 0.0, 0.0});
    p.advance(10);
  }
  set_default_progress_style(ProgressStyle::automatic);
  EXPECT_TRUE(out.str().empty());
}

TEST(Progress, CountsEveryAdvanceFromManyThreads) {
  std::ostringstream out;
  Progress p("threads", 4 * 100000, "items", {ProgressStyle::lines, &out, 0.0, 0.0});
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t)
    threads.emplace_back([&] {
      for (int i = 0; i < 100000; ++i) p.advance(1);
    });
  for (auto& t : threads) t.join();
  EXPECT_EQ(p.done(), 400000u);
}

}  // namespace
}  // namespace brickyard
