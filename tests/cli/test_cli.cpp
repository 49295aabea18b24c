// End-to-end tests of the `brickyard` binary: exit codes and messages as a user sees them.

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <string>

#include "core/raw_volume.h"
#include "fields/field.h"
#include "test_util.h"

namespace brickyard {
namespace {

const std::string kExe = BRICKYARD_EXE;

testing::CommandResult brickyard(const std::string& args) { return testing::run_command(kExe + " " + args); }

bool contains(const std::string& haystack, const std::string& needle) {
  return haystack.find(needle) != std::string::npos;
}

TEST(Cli, GenerateWritesGridSidecarAndProgress) {
  testing::TempDir dir;
  const std::string out = dir.file("ml.raw");
  auto r = brickyard("generate marschner-lobb --size 32 --type f32 --out " + out);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(contains(r.output, "generate marschner-lobb: 32.8k voxels in")) << r.output;
  EXPECT_TRUE(contains(r.output, "wrote " + out)) << r.output;
  const std::string data = testing::read_file(out);
  ASSERT_EQ(data.size(), size_t(32 * 32 * 32 * 4));
  const RawVolumeInfo info = read_raw_sidecar(out + ".json");
  EXPECT_EQ(info.dims, Vec3s(32));
  // Spot-check voxels against the analytic formula.
  auto f = make_field("marschner-lobb");
  for (int64_t n : {0, 1, 1000, 12345, 32767}) {
    const int64_t i = n % 32, j = (n / 32) % 32, k = n / 1024;
    float v;
    std::memcpy(&v, data.data() + n * 4, 4);
    const Vec3d p = Vec3d(-1.0) + Vec3d(double(i), double(j), double(k)) * (2.0 / 31.0);
    EXPECT_NEAR(v, f->value(p), 1e-6);
  }
}

TEST(Cli, QuietSuppressesProgress) {
  testing::TempDir dir;
  auto r = brickyard("--quiet generate sphere --size 8,9,10 --type u8 --out " + dir.file("s.raw"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_FALSE(contains(r.output, "voxels in")) << r.output;
  EXPECT_EQ(std::filesystem::file_size(dir.file("s.raw")), 8u * 9 * 10);
}

TEST(Cli, FieldParametersAndThreads) {
  testing::TempDir dir;
  auto a = brickyard("-j 1 -q generate fbm --size 16 --set seed=5 --set octaves=3 --out " + dir.file("a.raw"));
  auto b = brickyard("-j 2 -q generate fbm --size 16 --set seed=5 --set octaves=3 --out " + dir.file("b.raw"));
  ASSERT_EQ(a.exit_code, 0) << a.output;
  ASSERT_EQ(b.exit_code, 0) << b.output;
  EXPECT_EQ(testing::read_file(dir.file("a.raw")), testing::read_file(dir.file("b.raw")));
  const RawVolumeInfo info = read_raw_sidecar(dir.file("a.raw.json"));
  bool seed = false;
  for (const auto& [k, v] : info.source_params) seed = seed || (k == "seed" && v == 5);
  EXPECT_TRUE(seed);
}

TEST(Cli, GenerateWaveletIsVtksDefaultWaveletBitForBit) {
  // VTK's untouched vtkRTAnalyticSource is 21^3 (WholeExtent -10..10); see docs/fields.md.
  testing::TempDir dir;
  auto r = brickyard("-q generate wavelet --size 21 --type f32 --out " + dir.file("w.raw"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(testing::read_file(dir.file("w.raw")) ==
              testing::read_file(std::string(BRICKYARD_SOURCE_DIR) + "/tests/data/wavelet/default_21x21x21.f32"));
  const RawVolumeInfo info = read_raw_sidecar(dir.file("w.raw.json"));
  EXPECT_NEAR(info.min_value, 37.3531, 1e-4);  // VTK's GetScalarRange() of the default source
  EXPECT_NEAR(info.max_value, 276.829, 1e-3);
  auto u8 = brickyard("-q generate wavelet --size 16,8,4 --type u8 --set xfreq=20 --out " + dir.file("w8.raw"));
  ASSERT_EQ(u8.exit_code, 0) << u8.output;
  EXPECT_EQ(std::filesystem::file_size(dir.file("w8.raw")), 16u * 8 * 4);
}

struct BadArgs {
  const char* name;
  const char* args;
  const char* message;
};

class CliRejects : public ::testing::TestWithParam<BadArgs> {};

TEST_P(CliRejects, WithAClearMessageAndNonZeroExit) {
  testing::TempDir dir;
  std::string args = GetParam().args;
  const std::string placeholder = "OUT";
  if (auto at = args.find(placeholder); at != std::string::npos) args.replace(at, placeholder.size(), dir.file("x.raw"));
  auto r = brickyard(args);
  EXPECT_NE(r.exit_code, 0) << r.output;
  EXPECT_TRUE(contains(r.output, GetParam().message)) << "expected '" << GetParam().message << "' in:\n" << r.output;
  EXPECT_FALSE(std::filesystem::exists(dir.file("x.raw")));
  EXPECT_FALSE(std::filesystem::exists(dir.file("x.raw.partial")));
}

INSTANTIATE_TEST_SUITE_P(
    Generate, CliRejects,
    ::testing::Values(
        BadArgs{"size_zero", "generate sphere --size 0 --out OUT", "field '--size': '0': every dimension must be at least 1"},
        BadArgs{"size_axis_zero", "generate sphere --size 16,0,16 --out OUT", "every dimension must be at least 1"},
        BadArgs{"size_negative", "generate sphere --size -4 --out OUT", "'-4': every dimension must be at least 1"},
        BadArgs{"size_text", "generate sphere --size abc --out OUT", "'abc' is not a size"},
        BadArgs{"size_two_dims", "generate sphere --size 12,13 --out OUT", "has 2 dimensions; give 1 or 3"},
        BadArgs{"size_exceeds_disk", "generate sphere --size 100000 --type f32 --out OUT", "needs up to 3.55 PiB of disk (the raw file), but"},
        BadArgs{"size_overflows", "generate sphere --size 10000000 --out OUT", "overflow a 64-bit byte count"},
        BadArgs{"size_missing_value", "generate sphere --out OUT --size", "--size"},
        BadArgs{"unknown_field", "generate perlin --out OUT", "unknown field 'perlin' (known fields: marschner-lobb"},
        BadArgs{"unknown_type", "generate sphere --type f64 --out OUT", "unknown value type 'f64'"},
        BadArgs{"unknown_param", "generate sphere --set radiu=0.2 --out OUT", "field 'sphere' has no parameter 'radiu'"},
        BadArgs{"param_without_value", "generate sphere --set radius --out OUT", "'radius' is not NAME=VALUE"},
        BadArgs{"param_not_number", "generate sphere --set radius=big --out OUT", "'big' is not a finite number"},
        BadArgs{"missing_out", "generate sphere --size 8", "missing output file"},
        BadArgs{"missing_field", "generate --size 8 --out OUT", "missing FIELD"},
        BadArgs{"missing_out_dir", "generate sphere --size 8 --out /nonexistent-dir/x.raw", "/nonexistent-dir: the output directory does not exist"},
        BadArgs{"unknown_subcommand", "frobnicate", "not expected: frobnicate"},
        BadArgs{"no_subcommand", "", "a subcommand is required (generate, version, import, info"},
        BadArgs{"zero_threads", "--threads 0 version", "--threads"}),
    [](const auto& param_info) { return std::string(param_info.param.name); });

TEST(Cli, UsageErrorsExitWithTwo) {
  EXPECT_EQ(brickyard("generate sphere --size 0 --out /tmp/x.raw").exit_code, 2);
  EXPECT_EQ(brickyard("generate sphere --bogus").exit_code, 2);
}

TEST(Cli, EverySubcommandHasHelp) {
  for (const char* cmd : {"", "generate ", "version "}) {
    auto r = brickyard(std::string(cmd) + "--help");
    EXPECT_EQ(r.exit_code, 0) << cmd;
    EXPECT_TRUE(contains(r.output, "Usage")) << r.output;
  }
  auto r = brickyard("generate --help");
  EXPECT_TRUE(contains(r.output, "marschner-lobb, sphere, torus, gyroid, fbm, menger, sparse-blobs")) << r.output;
}

TEST(Cli, GenerateListShowsFieldsAndParameters) {
  auto r = brickyard("generate --list");
  ASSERT_EQ(r.exit_code, 0);
  EXPECT_TRUE(contains(r.output, "fbm")) << r.output;
  EXPECT_TRUE(contains(r.output, "octaves=6")) << r.output;
  EXPECT_TRUE(contains(r.output, "radius=0.35")) << r.output;
}

TEST(Cli, VersionNamesBuildAndLibraries) {
  auto r = brickyard("version");
  ASSERT_EQ(r.exit_code, 0);
  EXPECT_TRUE(contains(r.output, "brickyard 0.")) << r.output;
  EXPECT_TRUE(contains(r.output, "oneTBB")) << r.output;
}

}  // namespace
}  // namespace brickyard
