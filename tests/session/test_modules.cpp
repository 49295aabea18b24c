// Back ends from outside the tree: modules loaded by `brickyard --module` (and BRICKYARD_MODULES)
// render through the same path as the built-in back ends; bad modules are refused by name.

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <set>

#include "core/image.h"
#include "core/error.h"
#include "renderers/common/module.h"
#include "session/modules.h"
#include "tet_fixture.h"
#include "test_util.h"

namespace brickyard {
namespace {

using ::testing::HasSubstr;

class Modules : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new testing::TempDir();
    testing::write_tet_store(dir_->file("row.store"), 4);
    std::ofstream(dir_->file("mesh.json")) << R"({"dataset": "row.store", "backend": "tet-probe", "mode": "mip",
        "image": {"width": 64, "height": 16},
        "camera": {"eye": [0.5, -6, 0.5], "target": [0.5, 0.5, 0.5], "up": [0, 0, 1], "fov_degrees": 30}})";
  }
  static void TearDownTestSuite() { delete dir_; }
  static testing::CommandResult brickyard(const std::string& args, const std::string& env = "") {
    return testing::run_command(env + " " + BRICKYARD_EXE + " " + args);
  }
  static testing::TempDir* dir_;
};
testing::TempDir* Modules::dir_ = nullptr;

TEST_F(Modules, RenderOpensAMeshAndReachesAModulesBackEnd) {
  const std::string out = dir_->file("mesh.png");
  const auto r = brickyard(std::string("-q --module ") + BRICKYARD_TET_MODULE + " render " + dir_->file("mesh.json") + " -o " + out);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("frame 0: tet-probe 64x16"));
  const Image<Rgba8> image = read_png(out);
  ASSERT_EQ(image.width(), 64);
  // The middle row, left to right: clusters 0 to 3, grey 1/4 to 1 (64, 128, 191, 255) over
  // the black background.
  std::set<int> greys;
  for (int x = 0; x < 64; ++x)
    if (image(x, 8).r > 0) greys.insert(image(x, 8).r);
  EXPECT_EQ(greys, (std::set<int>{64, 128, 191, 255}));
}

TEST_F(Modules, TheEnvironmentNamesModulesToo) {
  const auto r = brickyard("render --list-backends", std::string("BRICKYARD_MODULES=/nonexistent-first:") + BRICKYARD_TET_MODULE);
  EXPECT_EQ(r.exit_code, 1) << r.output;  // every module named must load
  EXPECT_THAT(r.output, HasSubstr("/nonexistent-first: no such module file"));
  const auto ok = brickyard("render --list-backends", std::string("BRICKYARD_MODULES=") + BRICKYARD_TET_MODULE);
  ASSERT_EQ(ok.exit_code, 0) << ok.output;
  EXPECT_THAT(ok.output, HasSubstr("tet-probe  (mip; tetrahedral)"));
  EXPECT_THAT(ok.output, HasSubstr("gigavoxels  (iso,dvr; structured)"));
}

TEST_F(Modules, AGridBackEndOnAMeshIsRefusedByName) {
  const auto r = brickyard("render " + dir_->file("mesh.json") + " --backend raymarch -o " + dir_->file("no.png"));
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_THAT(r.output, HasSubstr("back end 'raymarch' does not render tetrahedral datasets"));
  EXPECT_FALSE(std::filesystem::exists(dir_->file("no.png")));
}

TEST_F(Modules, BadModulesAreRefusedNamingTheFile) {
  BackendRegistry registry;
  auto expect_refused = [&](const std::string& path, Errc code, const std::string& text) {
    try {
      load_module(path, registry);
      FAIL() << path;
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), code) << e.what();
      EXPECT_EQ(e.file(), path);
      EXPECT_THAT(e.message(), HasSubstr(text));
    }
  };
  expect_refused(dir_->file("absent.so"), Errc::not_found, "no such module file");
  std::ofstream(dir_->file("text.so")) << "not a shared library";
  expect_refused(dir_->file("text.so"), Errc::format, "cannot load the module");
  expect_refused(BRICKYARD_WRONG_API_MODULE, Errc::unsupported,
                 "built for module API version " + std::to_string(kModuleApiVersion + 98));
  EXPECT_TRUE(registry.entries().empty());
  const auto r = brickyard(std::string("--module ") + BRICKYARD_WRONG_API_MODULE + " render --list-backends");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_THAT(r.output, HasSubstr("rebuild it against this brickyard"));
}

TEST_F(Modules, InfoAndVerifyReadAMeshStore) {
  const auto info = brickyard("info " + dir_->file("row.store"));
  ASSERT_EQ(info.exit_code, 0) << info.output;
  EXPECT_THAT(info.output, HasSubstr("tetrahedral mesh"));
  EXPECT_THAT(info.output, HasSubstr("24 tetrahedra, 32 vertices in 4 clusters"));
  const auto verify = brickyard("verify " + dir_->file("row.store"));
  EXPECT_EQ(verify.exit_code, 0) << verify.output;
  EXPECT_THAT(verify.output, HasSubstr("4 clusters, 24 tets decoded, 0 problems"));
  const auto exported = brickyard("export " + dir_->file("row.store") + " --out " + dir_->file("x.raw"));
  EXPECT_EQ(exported.exit_code, 2) << exported.output;
  EXPECT_THAT(exported.output, HasSubstr("a tetrahedral store exports to a .vtu file"));
}

}  // namespace
}  // namespace brickyard
