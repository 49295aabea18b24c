// End-to-end tests of cachebench and flight.

#include <gtest/gtest.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <string>
#include <utility>
#include <vector>

#include "cache/trace.h"
#include "core/image.h"
#include "core/error.h"
#include "test_util.h"

namespace brickyard {
namespace {

const std::string kExe = BRICKYARD_EXE;
testing::CommandResult brickyard(const std::string& args) { return testing::run_command(kExe + " " + args); }
bool contains(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

TEST(CliCache, CachebenchShowsLrusCollapseOnALoopNextToOpt) {
  testing::TempDir dir;
  auto r = brickyard("cachebench --synthetic loop:objects=1000,passes=5 --policies lru,sieve,opt --sizes 50% --csv " +
                     dir.file("r.csv"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(contains(r.output, "lru            1.0000")) << r.output;
  EXPECT_TRUE(contains(r.output, "best online policy against OPT")) << r.output;
  const std::string csv = testing::read_file(dir.file("r.csv"));
  EXPECT_TRUE(contains(csv, "policy,size_fraction,capacity_bytes,requests,misses,miss_ratio")) << csv;
  EXPECT_TRUE(contains(csv, "lru,0.5,500,5000,5000,1.000000")) << csv;
  EXPECT_TRUE(contains(csv, "opt,0.5,500,5000,")) << csv;
}

TEST(CliCache, CachebenchDrawsTheMissRatioCurve) {
  testing::TempDir dir;
  auto r = brickyard("cachebench --synthetic zipf:objects=2000,requests=20000 --policies lru,s3fifo,opt --plot " +
                     dir.file("mrc.png"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const ImageRGBA8 png = read_png(dir.file("mrc.png"));
  EXPECT_EQ(png.width(), 900);
  EXPECT_EQ(png.height(), 600);
  EXPECT_TRUE(std::filesystem::exists(dir.file("mrc.png.csv")));
}

TEST(CliCache, TracesConvertBetweenFormatsAndReplayTheSame) {
  testing::TempDir dir;
  ASSERT_EQ(brickyard("cachebench --synthetic zipf:objects=500,requests=5000,size=4096 --convert " + dir.file("t.bytrace")).exit_code, 0);
  ASSERT_EQ(brickyard("cachebench " + dir.file("t.bytrace") + " --convert " + dir.file("t.oracleGeneral") + " --to oracleGeneral").exit_code, 0);
  ASSERT_EQ(brickyard("cachebench " + dir.file("t.oracleGeneral") + " --convert " + dir.file("t.txt") + " --to text").exit_code, 0);
  const std::string args = " --policies lru,arc --sizes 10%,30%";
  auto a = brickyard("cachebench " + dir.file("t.bytrace") + args);
  auto b = brickyard("cachebench " + dir.file("t.oracleGeneral") + args);
  auto c = brickyard("cachebench " + dir.file("t.txt") + args);
  ASSERT_EQ(a.exit_code, 0) << a.output;
  auto table = [](const std::string& out) { return out.substr(out.find("miss ratio"), out.find("per policy") - out.find("miss ratio")); };
  EXPECT_EQ(table(a.output), table(b.output));
  EXPECT_EQ(table(a.output), table(c.output));
  EXPECT_EQ(read_trace(dir.file("t.txt")).records.size(), 5000u);
}

TEST(CliCache, CachebenchRejectsBadInput) {
  testing::TempDir dir;
  std::ofstream(dir.file("bad.txt")) << "1 2\nxyz\n";
  auto r = brickyard("cachebench " + dir.file("bad.txt"));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_TRUE(contains(r.output, "bad.txt: line 2")) << r.output;
  r = brickyard("cachebench --synthetic zipf --policies lru,mru");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_TRUE(contains(r.output, "unknown cache policy 'mru'")) << r.output;
  r = brickyard("cachebench --synthetic zipf --sizes 0%");
  EXPECT_EQ(r.exit_code, 2);
  r = brickyard("cachebench");
  EXPECT_TRUE(contains(r.output, "give a TRACE file or --synthetic")) << r.output;
  r = brickyard("cachebench --synthetic spiral");
  EXPECT_TRUE(contains(r.output, "unknown synthetic trace 'spiral'")) << r.output;
}

TEST(CliCache, FlightRecordsATraceThatCachebenchReplays) {
  testing::TempDir dir;
  ASSERT_EQ(brickyard("-q import field:fbm --size 96 --type u8 --brick-size 16 --out " + dir.file("s")).exit_code, 0);
  std::ofstream(dir.file("path.json")) << R"({ "frames": 12, "image": {"width": 160, "height": 120},
    "camera_path": { "keyframes": [ {"eye": [0.5, -1.5, 0.5], "target": [0.5, 0.5, 0.5]},
                                    {"eye": [0.5, 0.2, 0.5], "target": [0.5, 0.9, 0.5]} ] } })";
  auto r = brickyard("flight " + dir.file("s") + " --path " + dir.file("path.json") + " --l1 1MiB --l2 2MiB --trace " +
                     dir.file("f.bytrace") + " --stats " + dir.file("stats.json"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(contains(r.output, "12 frames at 160x120")) << r.output;
  EXPECT_TRUE(contains(r.output, "wrote " + dir.file("f.bytrace"))) << r.output;
  EXPECT_TRUE(contains(testing::read_file(dir.file("stats.json")), "\"l2_peak_bytes\"")) << r.output;
  const Trace t = read_trace(dir.file("f.bytrace"));
  EXPECT_EQ(t.frames(), 13u);  // frames 1..12 (frame 0 is before the first frame_begin)
  r = brickyard("cachebench " + dir.file("f.bytrace") + " --policies lru,opt --sizes 10%,50%");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(contains(r.output, "prefetch fills")) << r.output;
  r = brickyard("flight " + dir.file("s") + " --path " + dir.file("nothing.json"));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_TRUE(contains(r.output, "nothing.json: cannot open")) << r.output;
}

/// A grid store and a two-frame path for flights that are meant to fail before they fly.
struct SmallFlight {
  testing::TempDir dir;
  SmallFlight() {
    EXPECT_EQ(brickyard("-q import field:fbm --size 32 --type u8 --brick-size 16 --out " + dir.file("s")).exit_code, 0);
    std::ofstream(dir.file("path.json")) << R"({ "frames": 2, "image": {"width": 64, "height": 48},
      "camera_path": { "keyframes": [ {"eye": [0.5, -1.5, 0.5], "target": [0.5, 0.5, 0.5]},
                                      {"eye": [0.5, 0.2, 0.5], "target": [0.5, 0.9, 0.5]} ] } })";
  }
  testing::CommandResult fly(const std::string& args) const {
    return brickyard("flight " + dir.file("s") + " --path " + dir.file("path.json") + " --l1 1MiB --l2 2MiB " + args);
  }
};

TEST(CliCache, FlightRefusesATraceOrStatsItCannotWriteBeforeFlying) {
  const SmallFlight f;
  std::ofstream(f.dir.file("file")) << "x";
  std::vector<std::pair<std::string, std::string>> cases = {
      {"--trace " + f.dir.file("missing_dir/fl.bytrace"), f.dir.file("missing_dir/fl.bytrace")},
      {"--trace " + f.dir.file("file/fl.bytrace"), f.dir.file("file/fl.bytrace")},
      {"--trace " + f.dir.path().string(), f.dir.path().string()},
      {"--stats " + f.dir.file("missing_dir/s.json"), f.dir.file("missing_dir/s.json")},
  };
  if (std::filesystem::is_directory("/proc")) cases.push_back({"--trace /proc/fl.bytrace", "/proc/fl.bytrace"});
  for (const auto& [args, path] : cases) {
    const auto r = f.fly(args);
    EXPECT_EQ(r.exit_code, 1) << args << "\n" << r.output;
    EXPECT_TRUE(contains(r.output, path + ":")) << args << "\n" << r.output;
    EXPECT_FALSE(contains(r.output, "wrote")) << args << "\n" << r.output;
    EXPECT_FALSE(contains(r.output, "flight over")) << "flew before refusing: " << args << "\n" << r.output;
  }
  EXPECT_FALSE(std::filesystem::exists(f.dir.file("missing_dir")));
  EXPECT_FALSE(std::filesystem::exists("/proc/fl.bytrace"));
}

TEST(CliCache, FlightRefusesALodOrFrameCountThatMeansNothing) {
  const SmallFlight f;
  for (const std::string args : {"--lod 0", "--lod -1", "--lod nan", "--frames 0", "--frames -1"}) {
    const auto r = f.fly(args + " --trace " + f.dir.file("t.bytrace"));
    const std::string option = args.substr(0, args.find(' '));
    EXPECT_EQ(r.exit_code, 2) << args << "\n" << r.output;
    EXPECT_TRUE(contains(r.output, "'" + option + "'")) << args << "\n" << r.output;
    EXPECT_FALSE(contains(r.output, "wrote")) << args << "\n" << r.output;
    EXPECT_FALSE(contains(r.output, "flight over")) << args << "\n" << r.output;
  }
  EXPECT_FALSE(std::filesystem::exists(f.dir.file("t.bytrace")));
  // Given and valid, or left out, --frames still flies.
  const auto r = f.fly("--frames 1 --lod 2");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(contains(r.output, "1 frames at 64x48")) << r.output;
}

TEST(CliCache, CachebenchRefusesAnOutputItCannotWriteBeforeReplaying) {
  testing::TempDir dir;
  for (const std::string option : {"--csv", "--plot", "--convert"}) {
    const std::string path = dir.file("missing_dir/out");
    const auto r = brickyard("cachebench --synthetic loop:objects=100,passes=2 --policies lru " + option + " " + path);
    EXPECT_EQ(r.exit_code, 1) << option << "\n" << r.output;
    EXPECT_TRUE(contains(r.output, path)) << option << "\n" << r.output;
    EXPECT_FALSE(contains(r.output, "wrote")) << option << "\n" << r.output;
    EXPECT_FALSE(contains(r.output, "miss ratio")) << "replayed before refusing: " << option << "\n" << r.output;
  }
}

TEST(CliCache, CachebenchReplaysTracesOfSeveralRecordKindsOrOneOfThem) {
  testing::TempDir dir;
  // Keys 1-3 of two kinds: six objects, each read twice.
  std::ofstream(dir.file("mixed.txt")) << "1 64\n2 64\n3 64\n1 256 octree_page\n2 256 octree_page\n3 256 octree_page\n"
                                          "1 64\n2 64\n3 64\n1 256 octree_page\n2 256 octree_page\n3 256 octree_page\n";
  const auto all = brickyard("cachebench " + dir.file("mixed.txt") + " --policies lru --sizes 100%");
  ASSERT_EQ(all.exit_code, 0) << all.output;
  EXPECT_TRUE(contains(all.output, "12 requests, 0 prefetch fills, 6 objects")) << all.output;
  EXPECT_TRUE(contains(all.output, "record kinds: brick 3 objects")) << all.output;
  EXPECT_TRUE(contains(all.output, "octree_page 3 objects")) << all.output;
  const auto one = brickyard("cachebench " + dir.file("mixed.txt") + " --kind octree_page --policies lru --sizes 100%");
  ASSERT_EQ(one.exit_code, 0) << one.output;
  EXPECT_TRUE(contains(one.output, "6 requests, 0 prefetch fills, 3 objects")) << one.output;
  const auto bad = brickyard("cachebench " + dir.file("mixed.txt") + " --kind voxel");
  EXPECT_EQ(bad.exit_code, 2) << bad.output;
  EXPECT_TRUE(contains(bad.output, "unknown record kind 'voxel'")) << bad.output;
}

TEST(CliCache, ASyntheticTraceThatCannotFitInMemoryIsRefusedBeforeItIsMade) {
  // Each needs terabytes: refused on any machine, before a record is generated.
  for (const std::string spec : {"zipf:objects=1000,requests=1e12", "scan:objects=1e9,passes=1e6",
                                 "zipf:objects=1e13,requests=10"}) {
    const auto start = std::chrono::steady_clock::now();
    auto r = brickyard("cachebench --synthetic " + spec);
    EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(), 20.0) << spec;
    EXPECT_EQ(r.exit_code, kExitOutOfResources) << r.output;
    EXPECT_TRUE(contains(r.output, "cachebench --synthetic " + spec + " needs about")) << r.output;
    EXPECT_TRUE(contains(r.output, "of memory")) << r.output;
    EXPECT_TRUE(contains(r.output, "fewer requests, objects or passes in --synthetic")) << r.output;
  }
  // What fits is not refused.
  EXPECT_EQ(brickyard("cachebench --synthetic zipf:objects=100,requests=1000 --policies lru --sizes 50%").exit_code, 0);
}

}  // namespace
}  // namespace brickyard
