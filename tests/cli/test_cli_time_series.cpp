// Grids of several time steps from the command line, as a user runs them: numbered raw files,
// and every volume of a 4D NIfTI file or netCDF variable, imported as one store; info, verify,
// export and render of one step; what is refused.

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>

#include <fmt/format.h>

#include "preprocess/volume_source.h"
#include "test_util.h"

namespace brickyard {
namespace {

const std::string kExe = BRICKYARD_EXE;
const std::string kData = BRICKYARD_SOURCE_DIR "/tests/data/";

testing::CommandResult brickyard(const std::string& args) { return testing::run_command(kExe + " " + args); }
bool contains(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

std::string scene_for(const testing::TempDir& dir, const std::string& store) {
  const std::string path = dir.file("scene-" + std::to_string(std::hash<std::string>{}(store)) + ".json");
  std::ofstream(path) << fmt::format(R"({{"dataset": "{}", "backend": "raymarch", "image": {{"width": 48, "height": 40}},
    "camera": {{"eye": [1.7, -1.2, 1.4], "target": [0.5, 0.5, 0.5], "up": [0, 0, 1], "fov_degrees": 35}},
    "mode": "iso", "values": "stored", "isosurfaces": [{{"value": 128}}], "shading": {{"light": "headlight"}}}})",
                                     store);
  return path;
}

TEST(CliTimeSeries, NumberedRawFilesBecomeOneStoreWhoseStepsExportAndRenderAsTheFilesAlone) {
  testing::TempDir dir;
  const char* const fields[] = {"sphere", "torus", "gyroid"};
  std::string files;
  for (int k = 0; k < 3; ++k) {
    const std::string raw = dir.file(fmt::format("t_{:03d}.raw", k));
    ASSERT_EQ(brickyard(fmt::format("-q generate {} --size 30,26,22 --type u8 --out {}", fields[k], raw)).exit_code, 0);
    files += " " + raw;
  }
  auto r = brickyard("import" + files + " --out " + dir.file("s") + " --brick-size 8");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(contains(r.output, "import 3 time steps")) << r.output;

  r = brickyard("info " + dir.file("s"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  for (const char* part : {"format version 3", "time steps 3 (0 to 2)", "time step 0: values [", "time step 2: values [",
                           "\"kind\":\"time_series\""})
    EXPECT_TRUE(contains(r.output, part)) << part << " missing from\n" << r.output;
  r = brickyard("verify " + dir.file("s"));
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(contains(r.output, "(3 time steps)")) << r.output;
  EXPECT_TRUE(contains(r.output, " 0 problems")) << r.output;

  for (int k = 0; k < 3; ++k) {
    SCOPED_TRACE(fields[k]);
    const std::string raw = dir.file(fmt::format("t_{:03d}.raw", k)), back = dir.file(fmt::format("back{}.raw", k));
    r = brickyard(fmt::format("-q export {} --time-step {} --out {}", dir.file("s"), k, back));
    ASSERT_EQ(r.exit_code, 0) << r.output;
    EXPECT_EQ(testing::read_file(back), testing::read_file(raw)) << "step " << k << " is not its file";
    // Rendered: the step of the series, and the file imported alone, are the same image.
    const std::string alone = dir.file(fmt::format("alone{}", k));
    ASSERT_EQ(brickyard("-q import " + raw + " --out " + alone + " --brick-size 8").exit_code, 0);
    const std::string a = dir.file(fmt::format("a{}.png", k)), b = dir.file(fmt::format("b{}.png", k));
    const std::string how = k == 1 ? "--set time_step=1" : fmt::format("--time-step {}", k);
    r = brickyard("-q render " + scene_for(dir, dir.file("s")) + " " + how + " -o " + a);
    ASSERT_EQ(r.exit_code, 0) << r.output;
    ASSERT_EQ(brickyard("-q render " + scene_for(dir, alone) + " -o " + b).exit_code, 0);
    EXPECT_EQ(testing::read_file(a), testing::read_file(b));
  }
  EXPECT_NE(testing::read_file(dir.file("a0.png")), testing::read_file(dir.file("a2.png"))) << "the steps differ";

  r = brickyard("-q export " + dir.file("s") + " --time-step 3 --out " + dir.file("x.raw"));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_TRUE(contains(r.output, "time step 3 of a store with 3 (0 to 2)")) << r.output;
  r = brickyard("-q render " + scene_for(dir, dir.file("s")) + " --time-step 3 -o " + dir.file("x.png"));
  EXPECT_NE(r.exit_code, 0);
  EXPECT_TRUE(contains(r.output, "time step 3 of a dataset with 3 (0 to 2)")) << r.output;
  r = brickyard("build-octree " + dir.file("s"));
  EXPECT_NE(r.exit_code, 0);
  EXPECT_TRUE(contains(r.output, "one time step")) << r.output;
}

TEST(CliTimeSeries, StepsThatAreNotOneGridAreRefusedNamingTheFile) {
  testing::TempDir dir;
  ASSERT_EQ(brickyard("-q generate sphere --size 20 --type u8 --out " + dir.file("a.raw")).exit_code, 0);
  ASSERT_EQ(brickyard("-q generate sphere --size 20,20,21 --type u8 --out " + dir.file("b.raw")).exit_code, 0);
  ASSERT_EQ(brickyard("-q generate sphere --size 20 --type u16 --out " + dir.file("c.raw")).exit_code, 0);
  for (const auto& [other, what] : {std::pair{"b.raw", "time step 1 is 20x20x21 voxels"}, {"c.raw", "time step 1 holds u16 values"}}) {
    const auto r = brickyard("import " + dir.file("a.raw") + " " + dir.file(other) + " --out " + dir.file("s"));
    EXPECT_NE(r.exit_code, 0) << r.output;
    EXPECT_TRUE(contains(r.output, what)) << r.output;
    EXPECT_TRUE(contains(r.output, other)) << r.output;
  }
  EXPECT_FALSE(std::filesystem::exists(dir.file("s")));
  const auto r = brickyard("import field:sphere field:torus --out " + dir.file("s"));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_TRUE(contains(r.output, "volume files only")) << r.output;
}

TEST(CliTimeSeries, EveryVolumeOfA4dNiftiFileOrNetcdfVariableWithTimeStepAll) {
  testing::TempDir dir;
  struct Case {
    bool supported;
    std::string file;
    int steps;
  };
  for (const Case& c : {Case{nifti_support(), kData + "nifti/4d.nii", 3}, Case{netcdf_support(), kData + "netcdf/ocean.nc", 2}}) {
    if (!c.supported) continue;
    SCOPED_TRACE(c.file);
    const std::string s = dir.file("all");
    auto r = brickyard("import " + c.file + " --time-step all --out " + s + " --brick-size 8 --force");
    ASSERT_EQ(r.exit_code, 0) << r.output;
    EXPECT_TRUE(contains(r.output, fmt::format("import {} time steps", c.steps))) << r.output;
    for (int k = 0; k < c.steps; ++k) {
      const std::string one = dir.file("one"), a = dir.file("a.raw"), b = dir.file("b.raw");
      ASSERT_EQ(brickyard(fmt::format("-q import {} --time-step {} --out {} --brick-size 8 --force", c.file, k, one)).exit_code, 0);
      ASSERT_EQ(brickyard(fmt::format("-q export {} --time-step {} --out {}", s, k, a)).exit_code, 0);
      ASSERT_EQ(brickyard(fmt::format("-q export {} --out {}", one, b)).exit_code, 0);
      EXPECT_EQ(testing::read_file(a), testing::read_file(b)) << "step " << k;
    }
  }
}

}  // namespace
}  // namespace brickyard
