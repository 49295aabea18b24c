// End-to-end tests of `brickyard render` and `brickyard bench`, as a user runs them, on a small
// store imported by the test.

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <sys/stat.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/brick_key.h"
#include "core/image.h"
#include "store_damage.h"
#include "core/error.h"
#include "test_util.h"

namespace brickyard {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

const std::string kExe = BRICKYARD_EXE;
testing::CommandResult brickyard(const std::string& args) { return testing::run_command(kExe + " " + args); }

const std::string kCamera = R"("camera": {"eye": [1.8, -1.2, 1.4], "target": [0.5, 0.5, 0.5], "fov_degrees": 40})";
const std::string kIso = R"("mode": "iso", "isosurfaces": [{"value": 0.0, "color": [0.9, 0.6, 0.3]}])";

std::vector<std::string> split_on(const std::string& text, char separator) {
  std::vector<std::string> out;
  std::istringstream in(text);
  for (std::string part; std::getline(in, part, separator);) out.push_back(part);
  return out;
}
std::vector<std::string> lines_of(const std::string& text) { return split_on(text, '\n'); }
std::vector<std::string> fields_of(const std::string& csv_line) { return split_on(csv_line, ','); }

/// A sphere's signed distance, 32^3 f32 in 16^3 bricks, imported once for the whole suite;
/// scenes are written next to it and name it relatively.
class CliRender : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new testing::TempDir();
    const auto r = brickyard("-q import field:sphere --size 32 --type f32 --brick-size 16 --out " + dir_->file("sphere.store"));
    ASSERT_EQ(r.exit_code, 0) << r.output;
  }
  static void TearDownTestSuite() { delete dir_; }

  /// Writes a scene file into the suite's directory; returns its path.
  static std::string write_scene(const std::string& name, const std::string& members) {
    const std::string path = dir_->file(name);
    std::ofstream(path) << "// written by the test\n{\"dataset\": \"sphere.store\", " << members << "}\n";
    return path;
  }

  static testing::TempDir* dir_;
};
testing::TempDir* CliRender::dir_ = nullptr;

TEST_F(CliRender, WritesColourDepthNormalsAndStats) {
  testing::TempDir out;
  const std::string scene = write_scene("still.json", R"("image": {"width": 48, "height": 32}, )" + kCamera + ", " + kIso);
  const auto r = brickyard("render " + scene + " -o " + out.file("c.png") + " --depth " + out.file("d.png") + " --normals " +
                           out.file("n.png") + " --stats " + out.file("stats.json"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("frame 0: raymarch 48x32"));

  const ImageRGBA8 colour = read_png(out.file("c.png"));
  EXPECT_EQ(colour.width(), 48);
  EXPECT_EQ(colour.height(), 32);
  int lit = 0;  // the sphere covers part of the image: some pixels are not the black background
  for (int y = 0; y < 32; ++y)
    for (int x = 0; x < 48; ++x) lit += colour(x, y).r > 0;
  EXPECT_GT(lit, 100);
  EXPECT_LT(lit, 48 * 32);
  for (const char* name : {"d.png", "n.png"}) {
    const ImageRGBA8 img = read_png(out.file(name));
    EXPECT_EQ(img.width(), 48) << name;
    EXPECT_EQ(img.height(), 32) << name;
  }

  const nlohmann::json stats = nlohmann::json::parse(testing::read_file(out.file("stats.json")));
  for (const char* key : {"scene", "backend", "params", "frames", "cache"}) EXPECT_TRUE(stats.contains(key)) << key;
  EXPECT_EQ(stats["scene"], scene);
  EXPECT_EQ(stats["backend"], "raymarch");
  EXPECT_EQ(stats["params"]["step"], 0.5);
  ASSERT_EQ(stats["frames"].size(), 1u);
  const nlohmann::json& f = stats["frames"][0];
  for (const char* key : {"frame", "width", "height", "threads", "seconds", "phases", "rays", "samples", "cells", "nodes",
                          "bricks", "gradients", "shadow_rays", "rays_per_second", "cache"})
    EXPECT_TRUE(f.contains(key)) << key;
  EXPECT_EQ(f["frame"], 0);
  EXPECT_EQ(f["width"], 48);
  EXPECT_EQ(f["rays"], 48 * 32);
  EXPECT_GT(f["gradients"].get<int64_t>(), 0);  // headlight shading by default
  for (const char* key : {"l1", "l2", "l3", "stalls"}) EXPECT_TRUE(stats["cache"].contains(key)) << key;
}

TEST_F(CliRender, AnOutputThatIsNotARegularFileIsRefusedAndLeftAsItIs) {
  // Every output goes to a temporary file renamed over its path, which would replace a device
  // (run as root, -o /dev/null became a regular file), a FIFO or a directory's link: such a
  // path is refused, naming it, with a non-zero exit, and is still what it was.
  testing::TempDir out;
  const std::string scene = write_scene("refuse.json", R"("image": {"width": 16, "height": 16}, )" + kCamera + ", " + kIso);
  const std::string fifo = out.file("pipe"), folder = out.file("folder");
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  fs::create_directory(folder);
  for (const std::string& args : {"-o " + fifo, "-o " + folder, "-o " + out.file("c.png") + " --stats " + fifo}) {
    const auto r = brickyard("render " + scene + " " + args);
    EXPECT_NE(r.exit_code, 0) << args << r.output;
    EXPECT_THAT(r.output, HasSubstr("outputs replace only regular files")) << args;
    EXPECT_TRUE(fs::is_fifo(fifo)) << args;
    EXPECT_TRUE(fs::is_directory(folder)) << args;
    EXPECT_FALSE(fs::exists(fifo + ".partial")) << args;
  }
  const auto r = brickyard("render " + scene + " -o " + fifo);
  EXPECT_THAT(r.output, HasSubstr(fifo + ": exists and is a FIFO"));
}

TEST(CliDamaged, RenderAndFlightNameUnreadableBricksAndExit3UnlessAllowed) {
  testing::TempDir dir;
  const std::string store = dir.file("s.store");
  ASSERT_EQ(brickyard("-q import field:sphere --size 32 --type f32 --brick-size 16 --out " + store).exit_code, 0);
  // The finest brick facing the camera.
  const BrickKey key{1, 1, 0, 1};
  testing::damage_record(store, "bricks", key.code());
  std::ofstream(dir.file("scene.json")) << "{\"dataset\": \"s.store\", \"image\": {\"width\": 32, \"height\": 32}, " << kCamera
                                       << ", " << kIso << R"(, "quality": {"lod_ratio": 0.01}})" << "\n";
  for (const std::string backend : {"raymarch", "reference", "gobbetti", "gigavoxels"}) {
    const std::string png = dir.file(backend + ".png");
    const auto r = brickyard("render " + dir.file("scene.json") + " --backend " + backend + " -o " + png + " --stats " +
                             dir.file(backend + ".json"));
    EXPECT_EQ(r.exit_code, kExitDamaged) << backend << "\n" << r.output;
    EXPECT_THAT(r.output, HasSubstr("error: 1 record of the store could not be read")) << backend;
    EXPECT_THAT(r.output, HasSubstr(store + ": key " + key.to_string() + ": checksum mismatch")) << backend;
    EXPECT_THAT(r.output, HasSubstr("--allow-damaged")) << backend;
    EXPECT_TRUE(fs::exists(png)) << backend << ": the image is still written";
    const nlohmann::json stats = nlohmann::json::parse(testing::read_file(dir.file(backend + ".json")));
    ASSERT_EQ(stats["unreadable"].size(), 1u) << backend;
    EXPECT_EQ(stats["frames"][0]["cache"]["unreadable"].get<int>(), 1) << backend;
  }
  auto r = brickyard("render " + dir.file("scene.json") + " --allow-damaged -o " + dir.file("allowed.png"));
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("warning: 1 record of the store could not be read"));
  // flight asks for every brick it would draw: the same report, the same exit status.
  r = brickyard("flight " + store + " --path " + std::string(BRICKYARD_SOURCE_DIR) + "/scenes/flight-orbit.json --frames 2 --lod 0.01");
  EXPECT_EQ(r.exit_code, kExitDamaged) << r.output;
  EXPECT_THAT(r.output, HasSubstr(store + ": key " + key.to_string() + ": checksum mismatch"));
  r = brickyard("flight " + store + " --path " + std::string(BRICKYARD_SOURCE_DIR) + "/scenes/flight-orbit.json --frames 2 --lod 0.01 --allow-damaged");
  EXPECT_EQ(r.exit_code, 0) << r.output;
}

TEST_F(CliRender, CameraPathFramesAreNumbered) {
  testing::TempDir out;
  const std::string scene = write_scene("path.json", R"("image": {"width": 24, "height": 16}, "camera_path": {"frames": 3,
      "keyframes": [{"eye": [1.8, -1.2, 1.4], "target": [0.5, 0.5, 0.5]}, {"eye": [-0.8, 1.8, 1.2], "target": [0.5, 0.5, 0.5]}]}, )" +
                                                        kIso);
  auto r = brickyard("-q render " + scene + " --frames all -o " + out.file("f.png") + " --depth " + out.file("d.png") + " --stats " +
                     out.file("s.json"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  for (const char* name : {"f_0000.png", "f_0001.png", "f_0002.png", "d_0000.png", "d_0002.png"}) {
    ASSERT_TRUE(fs::exists(out.file(name))) << name;
    EXPECT_EQ(read_png(out.file(name)).width(), 24) << name;
  }
  EXPECT_FALSE(fs::exists(out.file("f.png")));
  EXPECT_FALSE(fs::exists(out.file("f_0003.png")));
  EXPECT_EQ(nlohmann::json::parse(testing::read_file(out.file("s.json")))["frames"].size(), 3u);

  r = brickyard("-q render " + scene + " --frames 1-2 -o " + out.file("g.png"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_FALSE(fs::exists(out.file("g_0000.png")));
  EXPECT_TRUE(fs::exists(out.file("g_0001.png")));
  EXPECT_TRUE(fs::exists(out.file("g_0002.png")));

  r = brickyard("-q render " + scene + " --frames 3 -o " + out.file("h.png"));
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.output, HasSubstr("--frames"));
  EXPECT_THAT(r.output, HasSubstr("0-2"));
}

TEST_F(CliRender, FramesBelowTheQualityAskedAreSaidOnceAndCounted) {
  // gobbetti over an L1 of one brick (16^3 f32 with its apron: 23328 bytes): the cut stays at
  // the root on every frame. The run still succeeds; the terminal says so once, the summary
  // counts the frames, and --stats gives each frame's reason.
  testing::TempDir out;
  const std::string scene = write_scene("starved.json", R"("image": {"width": 48, "height": 32}, "quality": {"lod_ratio": 0.25},
      "cache": {"l1": "23328"}, "camera_path": {"frames": 3, "keyframes": [{"eye": [1.8, -1.2, 1.4], "target": [0.5, 0.5, 0.5]},
      {"eye": [-0.8, 1.8, 1.2], "target": [0.5, 0.5, 0.5]}]}, )" + kIso);
  const auto r = brickyard("-q render " + scene + " --backend gobbetti --frames all --settle -o " + out.file("f.png") + " --stats " +
                           out.file("s.json"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  size_t warnings = 0;
  for (size_t at = r.output.find("is below the quality asked"); at != std::string::npos;
       at = r.output.find("is below the quality asked", at + 1))
    ++warnings;
  EXPECT_EQ(warnings, 1u) << r.output;
  EXPECT_THAT(r.output, HasSubstr("brickyard: warning: frame 0 is below the quality asked: gobbetti's cut was held back by the L1 pool"));
  EXPECT_THAT(r.output, HasSubstr("3 frames: "));
  EXPECT_THAT(r.output, HasSubstr(", 3 of them below the quality asked"));
  const nlohmann::json stats = nlohmann::json::parse(testing::read_file(out.file("s.json")));
  EXPECT_EQ(stats["frames_below_quality"].get<int>(), 3);
  for (const auto& f : stats["frames"]) EXPECT_TRUE(f["below_quality"].is_string()) << f.dump();
}

TEST_F(CliRender, MalformedScenesExitNonZeroNamingTheFileAndKeyAndWriteNothing) {
  testing::TempDir out;
  struct Bad {
    const char* file;
    std::string members;
    std::vector<std::string> mentions;
  };
  const Bad bad[] = {
      {"typo.json", kCamera + ", " + kIso + R"(, "shading": {"ligth": "point"})", {"typo.json", "'shading.ligth'", "unknown key"}},
      {"range.json", kCamera + ", " + kIso + R"(, "image": {"width": 0})", {"range.json", "'image.width'"}},
      {"syntax.json", kCamera + ", " + kIso + ", \"mode\": ", {"syntax.json", "not valid JSON"}},
      {"noiso.json", kCamera + R"(, "mode": "iso")", {"noiso.json", "'isosurfaces'"}},
  };
  for (const Bad& b : bad) {
    const std::string scene = write_scene(b.file, b.members);
    const auto r = brickyard("render " + scene + " -o " + out.file("x.png"));
    EXPECT_EQ(r.exit_code, 1) << r.output;  // Errc::format
    EXPECT_THAT(r.output, HasSubstr("brickyard: error:"));
    for (const std::string& m : b.mentions) EXPECT_THAT(r.output, HasSubstr(m)) << b.file;
    EXPECT_FALSE(fs::exists(out.file("x.png"))) << b.file;
  }
  auto r = brickyard("render " + dir_->file("absent.json") + " -o " + out.file("x.png"));
  EXPECT_NE(r.exit_code, 0);
  EXPECT_THAT(r.output, HasSubstr("absent.json"));

  // A scene whose store does not exist names the store.
  std::ofstream(dir_->file("nostore.json")) << R"({"dataset": "no-such.store", )" << kCamera << ", " << kIso << "}";
  r = brickyard("render " + dir_->file("nostore.json") + " -o " + out.file("x.png"));
  EXPECT_NE(r.exit_code, 0);
  EXPECT_THAT(r.output, HasSubstr("no-such.store"));
  EXPECT_FALSE(fs::exists(out.file("x.png")));
}

TEST_F(CliRender, UnknownBackEndOrParameterIsAUsageErrorListingTheKnownOnes) {
  testing::TempDir out;
  const std::string scene = write_scene("small.json", R"("image": {"width": 16, "height": 16}, )" + kCamera + ", " + kIso);
  auto r = brickyard("render " + scene + " --backend raytrace -o " + out.file("x.png"));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_THAT(r.output, HasSubstr("'raytrace'"));
  EXPECT_THAT(r.output, HasSubstr("'reference'"));
  EXPECT_THAT(r.output, HasSubstr("'raymarch'"));
  EXPECT_FALSE(fs::exists(out.file("x.png")));

  r = brickyard("render " + scene + " --set stride=2 -o " + out.file("x.png"));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_THAT(r.output, HasSubstr("backend.params.stride"));
  EXPECT_THAT(r.output, HasSubstr("'step'"));
  EXPECT_FALSE(fs::exists(out.file("x.png")));

  r = brickyard("render " + scene + " --backend reference --set step=0.25 -o " + out.file("x.png"));
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("reference 16x16"));
}

TEST_F(CliRender, ListBackendsNamesEveryBackEndWithItsParameters) {
  const auto r = brickyard("render --list-backends");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("reference  (iso,dvr,mip; structured,tetrahedral)"));
  EXPECT_THAT(r.output, HasSubstr("raymarch  (iso,dvr,mip; structured)"));
  EXPECT_THAT(r.output, HasSubstr("bench sweeps step = "));
}

TEST_F(CliRender, BenchReportsFirstFrameConvergenceAndPeersBesideTheBackEnds) {
  testing::TempDir out;
  const std::string scene = write_scene("bench-peers.json", R"("image": {"width": 32, "height": 24}, )" + kCamera + ", " + kIso);
  // A peer whose image is a flat colour, and one that is the reference's own image (error 0).
  ImageRGBA8 flat(32, 24, Rgba8{10, 20, 30, 255});
  write_png(out.file("flat.png"), flat);
  std::ofstream(out.file("peers.json")) << R"({"peers": [
      {"name": "flat", "quality": "q=1", "threads": 2, "first_frame_s": 0.5, "steady_s": [0.2, 0.3, 0.25],
       "image": "flat.png", "description": "a flat colour", "peak_rss_bytes": 1048576}]})";
  const std::string report = out.file("report");
  auto r = brickyard("-q bench " + scene + " --backends raymarch,gigavoxels --quality step=1 --quality lod_ratio=1 "
                     "--warm 1 --cold 1 --peers " + out.file("peers.json") + " --out " + report);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const std::vector<std::string> csv = lines_of(testing::read_file(report + "/bench.csv"));
  ASSERT_EQ(csv.size(), 5u) << testing::read_file(report + "/bench.csv");  // header, reference, 2 back ends, the peer
  const std::vector<std::string> header = fields_of(csv[0]);
  auto cell = [&](size_t line, const std::string& name) {
    const auto at = std::find(header.begin(), header.end(), name);
    EXPECT_NE(at, header.end()) << name;
    return fields_of(csv[line]).at(size_t(at - header.begin()));
  };
  EXPECT_EQ(cell(2, "backend"), "raymarch");
  EXPECT_EQ(cell(2, "converged_frames"), "1");  // complete at once
  EXPECT_EQ(cell(3, "backend"), "gigavoxels");
  EXPECT_GT(std::stoi(cell(3, "converged_frames")), 1);  // refines from empty caches
  EXPECT_GE(std::stod(cell(3, "converged_median_s")), std::stod(cell(3, "cold_median_s")));
  EXPECT_GT(std::stod(cell(3, "first_rmse")), std::stod(cell(3, "rmse")));  // the first image is coarser
  // A still camera's image asked for at once: raymarch's first frame; gigavoxels completes its
  // first frame where the frames shown refine over several.
  EXPECT_EQ(cell(2, "still_frames"), "1");
  EXPECT_GT(std::stod(cell(2, "still_median_s")), 0);
  EXPECT_EQ(cell(3, "still_frames"), "1");
  EXPECT_GT(std::stod(cell(3, "still_median_s")), 0);
  EXPECT_EQ(cell(4, "backend"), "flat");
  EXPECT_EQ(cell(4, "is_peer"), "1");
  EXPECT_EQ(cell(4, "warm_median_s"), "0.25");
  EXPECT_EQ(cell(4, "converged_median_s"), "0.5");
  EXPECT_EQ(cell(4, "still_median_s"), "0.5");  // a peer's first frame is its finished image
  EXPECT_GT(std::stod(cell(4, "rmse")), 0.01);
  EXPECT_TRUE(fs::exists(report + "/images/peer-flat-q_1.png"));
  const std::string md = testing::read_file(report + "/bench.md");
  EXPECT_THAT(md, HasSubstr("**flat** q=1: a flat colour; peak resident memory 1 MiB"));
  EXPECT_THAT(md, HasSubstr("## At equal error: from empty caches to the converged image"));

  // A peer file with a bad key fails before anything is rendered, naming it.
  std::ofstream(out.file("bad.json")) << R"({"peers": [{"name": "flat", "first_frame_s": 0.5, "steady_s": [], "image": "flat.png"}]})";
  r = brickyard("-q bench " + scene + " --backends raymarch --peers " + out.file("bad.json") + " --out " + out.file("bad"));
  EXPECT_NE(r.exit_code, 0);
  EXPECT_THAT(r.output, HasSubstr("peers[0].steady_s"));
  EXPECT_FALSE(fs::exists(out.file("bad") + "/bench.csv"));
  // A peer named like a back end would mix two rows' meanings.
  std::ofstream(out.file("clash.json")) << R"({"peers": [{"name": "raymarch", "first_frame_s": 0.5, "steady_s": [0.1], "image": "flat.png"}]})";
  r = brickyard("-q bench " + scene + " --backends raymarch --peers " + out.file("clash.json") + " --out " + out.file("clash"));
  EXPECT_NE(r.exit_code, 0);
  EXPECT_THAT(r.output, HasSubstr("back end's name"));
}

TEST_F(CliRender, BenchWritesTableReportImagesAndCharts) {
  testing::TempDir out;
  const std::string scene = write_scene("bench.json", R"("image": {"width": 64, "height": 64}, )" + kCamera + ", " + kIso);
  const std::string report = out.file("report");
  const auto r = brickyard("-q bench " + scene + " --backends raymarch --warm 1 --cold 1 --quality step=1,0.5 --out " + report);
  ASSERT_EQ(r.exit_code, 0) << r.output;

  const std::vector<std::string> csv = lines_of(testing::read_file(report + "/bench.csv"));
  ASSERT_EQ(csv.size(), 4u) << testing::read_file(report + "/bench.csv");  // header, reference, 2 raymarch
  EXPECT_THAT(csv[0], ::testing::StartsWith("backend,quality,"));
  EXPECT_THAT(csv[1], ::testing::StartsWith("reference,"));
  EXPECT_THAT(csv[2], ::testing::StartsWith("raymarch,step=1,"));
  EXPECT_THAT(csv[3], ::testing::StartsWith("raymarch,step=0.5,"));
  for (size_t i = 1; i < csv.size(); ++i) EXPECT_THAT(csv[i], HasSubstr(",64,64,")) << csv[i];

  const std::string md = testing::read_file(report + "/bench.md");
  EXPECT_THAT(md, HasSubstr("step=0.5"));
  EXPECT_THAT(md, HasSubstr("reference"));
  std::vector<std::string> images;
  for (const auto& e : fs::directory_iterator(report + "/images")) images.push_back(e.path().filename().string());
  EXPECT_THAT(images, ::testing::UnorderedElementsAre("reference.png", "raymarch-step_1.png", "raymarch-step_0.5.png"));
  for (const std::string& img : images) EXPECT_EQ(read_png(report + "/images/" + img).width(), 64) << img;

  // A misspelt knob is an error before anything is rendered, not the default sweep.
  const auto typo = brickyard("-q bench " + scene + " --warm 1 --cold 0 --quality stepp=1,0.5 --out " + out.file("typo"));
  EXPECT_EQ(typo.exit_code, 2) << typo.output;
  EXPECT_THAT(typo.output, HasSubstr("--quality"));
  EXPECT_THAT(typo.output, HasSubstr("'stepp'"));
  EXPECT_FALSE(fs::exists(out.file("typo")));

  if (!fs::exists("/usr/bin/gnuplot")) GTEST_SKIP() << "gnuplot is not installed: no charts to check";
  for (const char* chart : {"error-vs-time.png", "contact-sheet.png"}) {
    ASSERT_TRUE(fs::exists(report + "/" + chart)) << chart;
    EXPECT_GT(read_png(report + "/" + chart).width(), 0) << chart;
  }
}

TEST_F(CliRender, BenchOfEveryBackEndSkipsOneWhoseDataTheStoreLacksAndSaysHowToAddIt) {
  testing::TempDir out;
  const std::string scene = write_scene("bench.json", R"("image": {"width": 32, "height": 32}, )" + kCamera + ", " + kIso);
  const auto r = brickyard("-q bench " + scene + " --warm 1 --cold 0 --quality step=1 --quality lod_ratio=1 --out " + out.file("all"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("octree_cgt reads the octree volume"));
  EXPECT_THAT(r.output, HasSubstr("skipped (brickyard build-octree "));
  EXPECT_THAT(testing::read_file(out.file("all") + "/bench.csv"), HasSubstr("\ngobbetti,"));
  // Named explicitly, it is refused as a render would be: the user asked for it.
  const auto named = brickyard("-q bench " + scene + " --backends octree_cgt --warm 1 --cold 0 --out " + out.file("named"));
  EXPECT_NE(named.exit_code, 0) << named.output;
  EXPECT_THAT(named.output, HasSubstr("build-octree"));
}

TEST_F(CliRender, BenchAgainstASupersampledReferenceFiltersColourAndKeepsCentreDepths) {
  testing::TempDir out;
  const std::string scene = write_scene("bench_ss.json", R"("image": {"width": 24, "height": 24}, )" + kCamera + ", " + kIso);
  using Row = std::map<std::string, std::string>;  // a CSV row by its header's names
  const auto bench = [&](int factor, Row& reference, Row& row) {
    const std::string report = out.file("ss" + std::to_string(factor));
    const auto r = brickyard("-q bench " + scene + " --backends raymarch --warm 1 --cold 0 --quality step=0.5 " +
                             "--reference-supersample " + std::to_string(factor) + " --out " + report);
    ASSERT_EQ(r.exit_code, 0) << r.output;
    const std::vector<std::string> csv = lines_of(testing::read_file(report + "/bench.csv"));
    ASSERT_EQ(csv.size(), 3u);
    const std::vector<std::string> header = fields_of(csv[0]);
    for (const auto& [line, into] : {std::pair{csv[1], &reference}, std::pair{csv[2], &row}}) {
      const std::vector<std::string> fields = fields_of(line);
      ASSERT_EQ(fields.size(), header.size()) << line;
      for (size_t i = 0; i < header.size(); ++i) (*into)[header[i]] = fields[i];
    }
    if (factor > 1) {
      EXPECT_THAT(testing::read_file(report + "/bench.md"), HasSubstr("reference supersampled 3x3"));
      EXPECT_EQ(reference["quality"], "supersample=3");
    }
  };
  Row ref1, row1, ref3, row3;
  ASSERT_NO_FATAL_FAILURE(bench(1, ref1, row1));
  ASSERT_NO_FATAL_FAILURE(bench(3, ref3, row3));
  EXPECT_EQ(ref1["width"], "24");
  EXPECT_EQ(ref3["width"], "72");  // the reference renders 3x3 rays a pixel
  EXPECT_EQ(row3["width"], "24");
  // raymarch's surface matches the centre rays' to rounding (about 2e-8), but the sphere's
  // silhouette pixels are part covered: their mean differs from their centre ray (measured
  // 0.0107). Depth comes from the centre rays in both: the same depth error.
  EXPECT_LT(std::stod(row1["rmse"]), 1e-4) << row1["rmse"];
  EXPECT_GT(std::stod(row3["rmse"]), 3e-3) << row3["rmse"];
  EXPECT_EQ(row3["depth_mean"], row1["depth_mean"]);

  // An even factor has no centre sub-pixel, and a reference over 16384 pixels a side is
  // refused: both by name, before anything is written.
  for (const auto& [factor, why] : {std::pair{"2", "must be odd"}, std::pair{"683", "exceeds 16384 pixels a side"}}) {
    const std::string dir = out.file(std::string("bad") + factor);
    const auto bad = brickyard("-q bench " + scene + " --warm 1 --cold 0 --reference-supersample " + factor + " --out " + dir);
    EXPECT_EQ(bad.exit_code, 2) << bad.output;
    EXPECT_THAT(bad.output, HasSubstr("--reference-supersample"));
    EXPECT_THAT(bad.output, HasSubstr(why));
    EXPECT_FALSE(fs::exists(dir));
  }
}

TEST_F(CliRender, AStillOfAnAsynchronousBackEndIsTheConvergedImageWithoutShowingTheFramesBefore) {
  // gigavoxels refines over frames as bricks arrive (4 a frame of the 9 here: 7 frames to
  // converge, measured on a one-frame path with --settle): a still's warm-up frames are
  // completed at once, one exact frame and one to check, and the image is exact mode's.
  testing::TempDir out;
  const std::string scene = write_scene("still_gv.json", R"("image": {"width": 48, "height": 48}, )" + kCamera + ", " + kIso);
  const std::string stats = out.file("still.json");
  const auto still = brickyard("-q render " + scene + " --backend gigavoxels --set upload_budget=4 --set lod_ratio=0.25 -o " +
                               out.file("still.png") + " --stats " + stats);
  ASSERT_EQ(still.exit_code, 0) << still.output;
  const nlohmann::json j = nlohmann::json::parse(testing::read_file(stats));
  const nlohmann::json& frame = j.is_array() ? j[0] : j["frames"][0];
  EXPECT_EQ(frame["settle_frames"].get<int>(), 2) << frame.dump();
  const auto exact = brickyard("-q render " + scene + " --backend gigavoxels --set exact=1 --set lod_ratio=0.25 -o " +
                               out.file("exact.png"));
  ASSERT_EQ(exact.exit_code, 0) << exact.output;
  EXPECT_EQ(read_png(out.file("still.png")), read_png(out.file("exact.png")));
}

TEST_F(CliRender, AnImageThatCannotFitInMemoryIsRefusedBeforeAnythingOpens) {
  // Scenes of a store that does not exist: a check that lets the render through ends at once,
  // with "no such store". What is free is capped by the environment, never raised.
  auto scene = [&](const std::string& name, int side) {
    const std::string path = dir_->file(name);
    std::ofstream(path) << "{\"dataset\": \"no-such.store\", \"image\": {\"width\": " << side << ", \"height\": " << side
                        << "}, " << kCamera << ", " << kIso << "}\n";
    return path;
  };
  auto render = [&](const std::string& memory, const std::string& args) {
    return testing::run_command("BRICKYARD_AVAILABLE_MEMORY=" + memory + " " + kExe + " render " + args + " -o " +
                                dir_->file("huge.png"));
  };
  auto r = render("1GiB", scene("huge.json", 16384));
  EXPECT_EQ(r.exit_code, kExitOutOfResources) << r.output;
  EXPECT_THAT(r.output, HasSubstr("render of 16384x16384 pixels needs about 9.25 GiB of memory"));
  EXPECT_THAT(r.output, HasSubstr("but 1 GiB is available; a smaller image (the scene's image.width and image.height)"));
  EXPECT_THAT(r.output, ::testing::Not(HasSubstr("no such store")));

  // The back end's own state per pixel counts: GigaVoxels keeps a ray state for each.
  const std::string medium = scene("medium.json", 4096);
  r = render("2GiB", medium);
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_THAT(r.output, HasSubstr("no such store"));
  r = render("2GiB", medium + " --backend gigavoxels");
  EXPECT_EQ(r.exit_code, kExitOutOfResources) << r.output;
  EXPECT_THAT(r.output, HasSubstr("render of 4096x4096 pixels needs about"));

  // bench renders the reference beside each back end, at --size.
  const std::string small = write_scene("bench-huge.json", R"("image": {"width": 16, "height": 16}, )" + kCamera + ", " + kIso);
  r = testing::run_command("BRICKYARD_AVAILABLE_MEMORY=1GiB " + kExe + " bench " + small + " --backends raymarch --size 16384,16384 --out " +
                           dir_->file("bench-huge"));
  EXPECT_EQ(r.exit_code, kExitOutOfResources) << r.output;
  EXPECT_THAT(r.output, HasSubstr("bench at 16384x16384 pixels needs about"));
  EXPECT_THAT(r.output, HasSubstr("--size"));
  EXPECT_FALSE(fs::exists(dir_->file("bench-huge")));
}

}  // namespace
}  // namespace brickyard
