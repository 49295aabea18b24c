// Tetrahedral meshes end to end, as a user runs them: import (procedural and files), info,
// verify, export to .vtu and back, render through the reference, and bad input that names
// the file and leaves no store behind.

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "storage/store.h"
#include "test_util.h"

namespace brickyard {
namespace {

const std::string kExe = BRICKYARD_EXE;
const std::string kData = std::string(BRICKYARD_SOURCE_DIR) + "/tests/data/mesh/";

testing::CommandResult brickyard(const std::string& args) { return testing::run_command(kExe + " " + args); }
bool contains(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

TEST(CliMesh, ProceduralImportInfoVerifyExportAndBack) {
  testing::TempDir dir;
  auto r = brickyard("-q import mesh:sphere --cells 12 --jitter 0.15 --cluster-tets 1000 --steps 2 -o " + dir.file("m.store"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(contains(r.output, "10368 tets")) << r.output;
  r = brickyard("info " + dir.file("m.store"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  for (const char* part : {"tetrahedral mesh", "10368 tetrahedra", "2 time steps", "\"field\":\"sphere\"", "\"jitter\":0.15",
                           "steps  [\"sphere_0\",\"sphere_1\"]"})
    EXPECT_TRUE(contains(r.output, part)) << part << " missing from\n" << r.output;
  r = brickyard("-q verify " + dir.file("m.store"));
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(contains(r.output, "0 problems")) << r.output;
  // Again: up to date, nothing done.
  r = brickyard("-q import mesh:sphere --cells 12 --jitter 0.15 --cluster-tets 1000 --steps 2 -o " + dir.file("m.store"));
  EXPECT_TRUE(contains(r.output, "up to date")) << r.output;

  for (const char* encoding : {"ascii", "binary", "appended", "base64", "zlib"}) {
    const std::string vtu = dir.file(std::string("m_") + encoding + ".vtu");
    r = brickyard(std::string("-q export ") + dir.file("m.store") + " --encoding " + encoding + " -o " + vtu);
    ASSERT_EQ(r.exit_code, 0) << r.output;
    EXPECT_TRUE(contains(r.output, "10368 tets, 2197 vertices, 2 time steps")) << r.output;
    const std::string back = dir.file(std::string("back_") + encoding + ".store");
    r = brickyard("-q import " + vtu + " --cluster-tets 1000 -o " + back);
    ASSERT_EQ(r.exit_code, 0) << r.output;
    EXPECT_TRUE(contains(r.output, "10368 valid tets")) << r.output;
    Store a(dir.file("m.store")), b(back);
    EXPECT_EQ(b.manifest().time_steps, 2) << encoding;
    EXPECT_EQ(b.manifest().mesh.tets, a.manifest().mesh.tets);
    EXPECT_EQ(b.manifest().mesh.vertices, 2197u);
    EXPECT_EQ(b.manifest().min_value, a.manifest().min_value);
    EXPECT_EQ(b.manifest().max_value, a.manifest().max_value);
    EXPECT_EQ(b.manifest().mesh.bounds.lo, a.manifest().mesh.bounds.lo);
    EXPECT_EQ(b.manifest().mesh.bounds.hi, a.manifest().mesh.bounds.hi);
  }
}

TEST(CliMesh, ImportWithBvhStoresThemAndInfoVerifyAndExportReadTheStore) {
  testing::TempDir dir;
  auto r = brickyard("-q import mesh:sphere --cells 10 --cluster-tets 1000 --bvh -o " + dir.file("b.store"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  r = brickyard("info " + dir.file("b.store"));
  EXPECT_TRUE(contains(r.output, "BVHs stored with the clusters (bih, leaves of at most 12 tets, step 0)")) << r.output;
  r = brickyard("-q verify " + dir.file("b.store"));
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(contains(r.output, "0 problems")) << r.output;
  r = brickyard("-q export " + dir.file("b.store") + " -o " + dir.file("b.vtu"));
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(contains(r.output, "6000 tets")) << r.output;
  // The same mesh without: a different build, refused unless --force.
  r = brickyard("-q import mesh:sphere --cells 10 --cluster-tets 1000 -o " + dir.file("b.store"));
  EXPECT_NE(r.exit_code, 0) << r.output;
  EXPECT_TRUE(contains(r.output, "--force")) << r.output;
  r = brickyard("-q import mesh:sphere --cells 10 --cluster-tets 1000 --force -o " + dir.file("b.store"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  r = brickyard("info " + dir.file("b.store"));
  EXPECT_FALSE(contains(r.output, "BVHs stored")) << r.output;
}

TEST(CliMesh, ImportsFilesWrittenByVtkGmshAndTetgen) {
  testing::TempDir dir;
  struct Case {
    const char* file;
    const char* expect;
  };
  for (const Case& c : {Case{"hex_appended_raw_zlib_u64.vtu", "8 hexahedron -> 96 tets"},
                        Case{"mixed_legacy_binary.vtk", "triangle cells rejected"}, Case{"box_msh41_bin.msh", "valid tets"},
                        Case{"cube.1.node", "68 valid tets"}, Case{"steps.pvd", "3 time steps"}}) {
    const std::string out = dir.file(std::string(c.file) + ".store");
    auto r = brickyard("-q import " + kData + c.file + " -o " + out);
    ASSERT_EQ(r.exit_code, 0) << c.file << "\n" << r.output;
    EXPECT_TRUE(contains(r.output, c.expect)) << c.file << "\n" << r.output;
    r = brickyard("-q verify " + out);
    EXPECT_EQ(r.exit_code, 0) << c.file << "\n" << r.output;
  }
}

TEST(CliMesh, BadMeshesNameTheFileAndLeaveNoStore) {
  testing::TempDir dir;
  const std::string good = testing::read_file(kData + "hex_ascii.vtu");
  struct Case {
    std::string name, text, expect;
  };
  std::vector<Case> cases = {
      {"truncated.vtu", good.substr(0, good.size() / 2), "truncated.vtu"},
      {"empty.vtu", "", "empty.vtu"},
      {"flat.node", "4 3 0 0\n0 0 0 0\n1 0 0 0\n2 0 0 0\n3 0 0 0\n", "flat"},
  };
  std::ofstream(dir.file("flat.ele")) << "1 4 0\n0 0 1 2 3\n";
  for (const Case& c : cases) {
    std::ofstream(dir.file(c.name), std::ios::binary) << c.text;
    const std::string out = dir.file(c.name + ".store");
    auto r = brickyard("-q import " + dir.file(c.name) + " -o " + out);
    EXPECT_NE(r.exit_code, 0) << c.name << "\n" << r.output;
    EXPECT_TRUE(contains(r.output, c.expect)) << c.name << "\n" << r.output;
    EXPECT_FALSE(std::filesystem::exists(out + "/data.mdb")) << c.name;
  }
  auto r = brickyard("-q import " + dir.file("flat.node") + " -o " + dir.file("x.store"));
  EXPECT_TRUE(contains(r.output, "no valid tetrahedron is left")) << r.output;
  r = brickyard("-q import mesh:sphere --jitter 0.5 -o " + dir.file("j.store"));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_TRUE(contains(r.output, "--jitter")) << r.output;
  r = brickyard("-q import " + kData + "hex_ascii.vtu --array nope -o " + dir.file("a.store"));
  EXPECT_NE(r.exit_code, 0) << r.output;
  EXPECT_TRUE(contains(r.output, "no point array 'nope'")) << r.output;
}

TEST(CliMesh, AFlightOverAMeshRecordsClusterAccessesThatCachebenchReplays) {
  testing::TempDir dir;
  ASSERT_EQ(brickyard("-q import mesh:sphere --cells 24 --cluster-tets 1000 -o " + dir.file("m.store")).exit_code, 0);
  auto r = brickyard("-q flight " + dir.file("m.store") + " --path " + std::string(BRICKYARD_SOURCE_DIR) +
                     "/scenes/flight-orbit.json --frames 20 --l1 1MiB --l2 2MiB --values 0,0 --trace " + dir.file("f.trace") +
                     " --stats " + dir.file("stats.json"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(contains(r.output, "clusters looked up")) << r.output;
  // The trace in text: every access is a cluster's.
  r = brickyard("-q cachebench " + dir.file("f.trace") + " --convert " + dir.file("f.txt") + " --to text");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const std::string trace = testing::read_file(dir.file("f.txt"));
  EXPECT_TRUE(contains(trace, " tet_cluster\n")) << trace.substr(0, 200);
  EXPECT_FALSE(contains(trace, "brick")) << trace.substr(0, 200);
  // The L2 never held more than its budget.
  const std::string stats = testing::read_file(dir.file("stats.json"));
  const size_t at = stats.find("\"l2_peak_bytes\":");
  ASSERT_NE(at, std::string::npos) << stats;
  EXPECT_LE(std::stoull(stats.substr(at + 16)), 2u << 20) << stats;
  r = brickyard("-q cachebench " + dir.file("f.trace"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(contains(r.output, "opt")) << r.output;
  r = brickyard("-q flight " + dir.file("m.store") + " --path " + std::string(BRICKYARD_SOURCE_DIR) +
                "/scenes/flight-orbit.json --time-step 1");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_TRUE(contains(r.output, "--time-step")) << r.output;
}

TEST(CliMesh, RendersAMeshSceneThroughTheReference) {
  testing::TempDir dir;
  ASSERT_EQ(brickyard("-q import mesh:sphere --cells 8 -o " + dir.file("m.store")).exit_code, 0);
  std::ofstream(dir.file("s.json")) << R"({"dataset": "m.store", "backend": "reference", "image": {"width": 64, "height": 64},
      "mode": "iso", "isosurfaces": [{"value": 0.0}], "clip": {"lo": [0, 0, 0], "hi": [1, 0.5, 1]},
      "camera": {"eye": [1.8, -1.2, 1.4], "target": [0.5, 0.5, 0.5]}})";
  auto r = brickyard("-q render " + dir.file("s.json") + " -o " + dir.file("s.png"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(std::filesystem::exists(dir.file("s.png")));
}

}  // namespace
}  // namespace brickyard
