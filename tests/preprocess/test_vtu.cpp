// The VTK XML readers (.vtu, .pvd) and the .vtu writer: round trips through every encoding,
// files written by VTK itself (tests/data/mesh/make_vtk_files.py, values by known formulas),
// and errors that name the file and the problem.

#include <gtest/gtest.h>
#include <sys/stat.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "core/error.h"
#include "preprocess/mesh_readers.h"
#include "test_util.h"

namespace brickyard {
namespace {

const std::string kData = BRICKYARD_SOURCE_DIR "/tests/data/mesh/";

void write_text(const std::string& path, const std::string& text) {
  std::ofstream(path, std::ios::binary | std::ios::trunc) << text;
}

// Expects `f` to throw Error of `code` whose what() names `file` and contains `needle`.
template <typename F>
void expect_error(F&& f, Errc code, const std::string& file, const std::string& needle) {
  try {
    f();
    ADD_FAILURE() << "no error; expected one containing '" << needle << "'";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), code) << e.what();
    EXPECT_NE(std::string(e.what()).find(file), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
  }
}

// A tet mesh of `n` vertices on a curve and n-3 tets over consecutive vertices, two steps.
TetMesh curve_mesh(size_t n) {
  TetMesh m;
  for (size_t i = 0; i < n; ++i) {
    const float t = float(i) * 0.37f;
    m.positions.insert(m.positions.end(), {std::cos(t), std::sin(t), t * 0.01f});
  }
  for (size_t i = 0; i + 3 < n; ++i)
    m.tets.insert(m.tets.end(), {uint32_t(i), uint32_t(i + 1), uint32_t(i + 2), uint32_t(i + 3)});
  m.scalars.resize(2);
  for (size_t i = 0; i < n; ++i) {
    m.scalars[0].push_back(float(i) * 0.5f - 3.25f);
    m.scalars[1].push_back(1.0f / float(i + 1));
  }
  m.array_name = "density";
  m.step_names = {"density_0", "density_1"};
  return m;
}

void expect_same_mesh(const TetMesh& m, const MeshData& d, const std::vector<std::string>& names) {
  ASSERT_EQ(d.point_count(), m.vertex_count());
  for (size_t i = 0; i < m.positions.size(); ++i) ASSERT_EQ(d.points[i], double(m.positions[i])) << i;
  ASSERT_EQ(d.cell_count(), m.tet_count());
  for (size_t c = 0; c < d.cell_count(); ++c) {
    ASSERT_EQ(d.cell_types[c], MeshCellType::tetra);
    ASSERT_EQ(d.cell_offsets[c + 1], 4 * (c + 1));
  }
  ASSERT_EQ(d.connectivity.size(), m.tets.size());
  for (size_t i = 0; i < m.tets.size(); ++i) ASSERT_EQ(d.connectivity[i], int64_t(m.tets[i])) << i;
  ASSERT_EQ(d.arrays.size(), m.scalars.size());
  for (size_t s = 0; s < d.arrays.size(); ++s) {
    EXPECT_EQ(d.arrays[s].name, names[s]);
    EXPECT_EQ(d.arrays[s].step, 0);
    ASSERT_EQ(d.arrays[s].values.size(), m.vertex_count());
    for (size_t i = 0; i < m.vertex_count(); ++i) ASSERT_EQ(d.arrays[s].values[i], double(m.scalars[s][i])) << i;
  }
  EXPECT_TRUE(d.rejected_cells.empty());
}

TEST(VtuWriter, RoundTripsEveryEncodingCompressionAndHeaderType) {
  testing::TempDir dir;
  using E = VtuWriteOptions::Encoding;
  // 3000 vertices: 36 KB of points and 96 KB of connectivity, so several zlib blocks.
  for (const size_t n : {size_t(6), size_t(3000)}) {
    const TetMesh mesh = curve_mesh(n);
    for (const E encoding : {E::ascii, E::binary, E::appended_raw, E::appended_base64})
      for (const bool compress : {false, true})
        for (const bool header64 : {false, true}) {
          SCOPED_TRACE(::testing::Message() << "n " << n << " encoding " << int(encoding) << " compress " << compress
                                            << " header64 " << header64);
          const std::string path = dir.file("m.vtu");
          write_vtu(path, mesh, {encoding, compress, header64});
          EXPECT_FALSE(std::filesystem::exists(path + ".partial"));
          const MeshData d = read_vtu(path);
          EXPECT_EQ(d.format, "vtu");
          EXPECT_EQ(d.source, path);
          expect_same_mesh(mesh, d, mesh.step_names);
        }
  }
}

TEST(VtuWriter, NamesArraysByStepNamesArrayNameOrNumber) {
  testing::TempDir dir;
  TetMesh one = curve_mesh(5);
  one.scalars.resize(1);
  one.step_names.clear();
  write_vtu(dir.file("one.vtu"), one);
  expect_same_mesh(one, read_vtu(dir.file("one.vtu")), {"density"});

  TetMesh two = curve_mesh(5);
  two.step_names = {"first"};
  write_vtu(dir.file("two.vtu"), two);
  expect_same_mesh(two, read_vtu(dir.file("two.vtu")), {"first", "scalar_1"});
}

TEST(VtuWriter, RefusesToReplaceWhatIsNotARegularFile) {
  const TetMesh mesh = curve_mesh(5);
  expect_error([&] { write_vtu("/dev/null", mesh); }, Errc::invalid_argument, "/dev/null", "not a regular file");
  struct stat st {};
  ASSERT_EQ(::stat("/dev/null", &st), 0);
  EXPECT_TRUE(S_ISCHR(st.st_mode));
  testing::TempDir dir;
  expect_error([&] { write_vtu(dir.path().string(), mesh); }, Errc::invalid_argument, dir.path().string(),
               "not a regular file");
}

// ---------------------------------------------------------------------------------------------
// Files written by VTK 9 (make_vtk_files.py)

void expect_hex_grid(const MeshData& d) {
  ASSERT_EQ(d.point_count(), 27u);
  for (uint64_t p = 0; p < 27; ++p) {
    ASSERT_EQ(d.points[3 * p + 0], 0.5 * double(p % 3));
    ASSERT_EQ(d.points[3 * p + 1], 0.5 * double(p / 3 % 3));
    ASSERT_EQ(d.points[3 * p + 2], 0.5 * double(p / 9));
  }
  ASSERT_EQ(d.cell_count(), 8u);
  for (uint64_t c = 0; c < 8; ++c) {
    EXPECT_EQ(d.cell_types[c], MeshCellType::hexahedron);
    EXPECT_EQ(d.cell_offsets[c + 1], 8 * (c + 1));
  }
  EXPECT_EQ(std::vector<int64_t>(d.connectivity.begin(), d.connectivity.begin() + 8),
            (std::vector<int64_t>{0, 1, 4, 3, 9, 10, 13, 12}));
  EXPECT_EQ(std::vector<int64_t>(d.connectivity.end() - 8, d.connectivity.end()),
            (std::vector<int64_t>{13, 14, 17, 16, 22, 23, 26, 25}));
  // The 3-component "velocity" is not a scalar: nothing is recorded for it.
  ASSERT_EQ(d.arrays.size(), 2u);
  EXPECT_EQ(d.arrays[0].name, "temperature");
  EXPECT_EQ(d.arrays[1].name, "id");
  for (uint64_t p = 0; p < 27; ++p) {
    EXPECT_EQ(d.arrays[0].values[p], d.points[3 * p] + 2 * d.points[3 * p + 1] + 3 * d.points[3 * p + 2]);
    EXPECT_EQ(d.arrays[1].values[p], 10.0 * double(p));
  }
  EXPECT_TRUE(d.rejected_cells.empty());
}

TEST(VtuReader, ReadsVtkWrittenHexGridInEveryEncoding) {
  std::vector<std::string> names = {"hex_ascii.vtu", "hex_binary_zlib_u32_bigendian.vtu",
                                    "hex_appended_raw_raw_u64_bigendian.vtu"};
  for (const char* mode : {"binary", "appended_raw", "appended_base64"})
    for (const char* compress : {"raw", "zlib"})
      for (const char* header : {"u32", "u64"}) names.push_back(std::string("hex_") + mode + "_" + compress + "_" + header + ".vtu");
  for (const std::string& name : names) {
    SCOPED_TRACE(name);
    const MeshData d = read_vtu(kData + name);
    expect_hex_grid(d);
  }
}

TEST(VtuReader, ReadsMixedCellsRejectsTriangleAndReordersVoxel) {
  for (const char* name : {"mixed_ascii.vtu", "mixed_appended_raw_zlib_u64.vtu"}) {
    SCOPED_TRACE(name);
    const MeshData d = read_vtu(kData + name);
    ASSERT_EQ(d.point_count(), 26u);
    EXPECT_EQ(d.points[3 * 14 + 0], 4.5);  // Float64 points
    EXPECT_EQ(d.points[3 * 14 + 1], 0.5);
    EXPECT_EQ(d.cell_types, (std::vector<MeshCellType>{MeshCellType::tetra, MeshCellType::wedge, MeshCellType::pyramid,
                                                       MeshCellType::hexahedron}));
    EXPECT_EQ(d.cell_offsets, (std::vector<uint64_t>{0, 4, 10, 15, 23}));
    EXPECT_EQ(d.connectivity, (std::vector<int64_t>{0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14,
                                                    18, 19, 21, 20, 22, 23, 25, 24}));
    EXPECT_EQ(d.rejected_cells, (std::map<std::string, uint64_t>{{"triangle", 1}}));
    ASSERT_EQ(d.arrays.size(), 2u);
    for (uint64_t p = 0; p < 26; ++p)
      EXPECT_EQ(d.arrays[0].values[p], d.points[3 * p] + 2 * d.points[3 * p + 1] + 3 * d.points[3 * p + 2]);
  }
}

TEST(PvdReader, ReadsStepsSortedByTimeWithMovingPoints) {
  const MeshData d = read_pvd(kData + "steps.pvd");
  EXPECT_EQ(d.format, "pvd");
  EXPECT_EQ(d.source, kData + "steps.pvd");
  EXPECT_EQ(d.steps, 3);
  EXPECT_EQ(d.step_times, (std::vector<double>{0.0, 0.5, 1.0}));
  ASSERT_EQ(d.point_count(), 12u);
  EXPECT_EQ(d.cell_count(), 2u);
  ASSERT_EQ(d.step_points.size(), 2u);
  EXPECT_EQ(d.step_points[0], d.points);
  for (uint64_t p = 0; p < 12; ++p) EXPECT_EQ(d.step_points[1][3 * p + 2], d.points[3 * p + 2] + 0.25);
  ASSERT_EQ(d.arrays.size(), 6u);
  for (int s = 0; s < 3; ++s) {
    const PointArray& t = d.arrays[size_t(2 * s)];
    EXPECT_EQ(t.name, "temperature");
    EXPECT_EQ(t.step, s);
    EXPECT_EQ(d.arrays[size_t(2 * s + 1)].name, "id");
    const std::vector<double>& xyz = s == 0 ? d.points : d.step_points[size_t(s - 1)];
    for (uint64_t p = 0; p < 12; ++p)
      EXPECT_DOUBLE_EQ(t.values[p], xyz[3 * p] + 2 * xyz[3 * p + 1] + 3 * xyz[3 * p + 2] + 10 * s) << s << " " << p;
  }
}

TEST(PvdReader, StaticPointsLeaveStepPointsEmptyAndRefusesOtherCells) {
  testing::TempDir dir;
  TetMesh a = curve_mesh(6);
  a.scalars.resize(1);
  write_vtu(dir.file("a.vtu"), a);
  write_vtu(dir.file("b.vtu"), a);
  TetMesh c = a;
  std::swap(c.tets[0], c.tets[1]);
  write_vtu(dir.file("c.vtu"), c);
  const std::string head = "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\">\n<Collection>\n";
  write_text(dir.file("ok.pvd"), head + "<DataSet timestep=\"2\" file=\"b.vtu\"/><DataSet timestep=\"1\" file=\"a.vtu\"/>"
                                        "</Collection></VTKFile>\n");
  const MeshData d = read_pvd(dir.file("ok.pvd"));
  EXPECT_EQ(d.steps, 2);
  EXPECT_TRUE(d.step_points.empty());
  EXPECT_EQ(d.step_times, (std::vector<double>{1, 2}));
  ASSERT_EQ(d.arrays.size(), 2u);
  EXPECT_EQ(d.arrays[1].step, 1);

  write_text(dir.file("bad.pvd"), head + "<DataSet file=\"a.vtu\"/><DataSet file=\"c.vtu\"/></Collection></VTKFile>\n");
  expect_error([&] { read_pvd(dir.file("bad.pvd")); }, Errc::format, dir.file("c.vtu"), "other cells");
  write_text(dir.file("missing.pvd"), head + "<DataSet file=\"a.vtu\"/><DataSet file=\"nope.vtu\"/></Collection></VTKFile>\n");
  expect_error([&] { read_pvd(dir.file("missing.pvd")); }, Errc::io, dir.file("nope.vtu"), "cannot open");
}

TEST(MeshReaders, DispatchesByLowerCasedExtension) {
  EXPECT_TRUE(is_mesh_file("a/b.VTU"));
  EXPECT_TRUE(is_mesh_file("b.pvd"));
  EXPECT_TRUE(is_mesh_file("b.msh"));
  EXPECT_TRUE(is_mesh_file("b.ele"));
  EXPECT_FALSE(is_mesh_file("b.raw"));
  EXPECT_FALSE(is_mesh_file("vtu"));
  expect_hex_grid(read_mesh_file(kData + "hex_ascii.vtu"));
  EXPECT_EQ(read_mesh_file(kData + "steps.pvd").steps, 3);
  expect_error([] { read_mesh_file("volume.nrrd"); }, Errc::unsupported, "volume.nrrd", ".vtu .pvd .vtk .msh .node .ele");
}

// ---------------------------------------------------------------------------------------------
// Errors

std::string ascii_vtu(const std::string& piece_body, int points = 4, int cells = 1, const std::string& type = "UnstructuredGrid") {
  return "<?xml version=\"1.0\"?>\n<VTKFile type=\"" + type + "\" version=\"0.1\" byte_order=\"LittleEndian\">\n<" +
         type + ">\n<Piece NumberOfPoints=\"" + std::to_string(points) + "\" NumberOfCells=\"" + std::to_string(cells) +
         "\">\n" + piece_body + "</Piece>\n</" + type + ">\n</VTKFile>\n";
}

const std::string kTetPoints =
    "<Points><DataArray type=\"Float32\" NumberOfComponents=\"3\" format=\"ascii\">0 0 0 1 0 0 0 1 0 0 0 1"
    "</DataArray></Points>\n";

std::string cells(const std::string& connectivity, const std::string& offsets, const std::string& types) {
  return "<Cells><DataArray type=\"Int64\" Name=\"connectivity\" format=\"ascii\">" + connectivity +
         "</DataArray><DataArray type=\"Int64\" Name=\"offsets\" format=\"ascii\">" + offsets +
         "</DataArray><DataArray type=\"UInt8\" Name=\"types\" format=\"ascii\">" + types + "</DataArray></Cells>\n";
}

TEST(VtuReader, HandWrittenAsciiTetReads) {
  testing::TempDir dir;
  write_text(dir.file("t.vtu"), ascii_vtu("<PointData><DataArray type=\"Int8\" Name=\"s\" format=\"ascii\">-1 2 -3 4"
                                          "</DataArray></PointData>" + kTetPoints + cells("0 1 2 3", "4", "10")));
  const MeshData d = read_vtu(dir.file("t.vtu"));
  EXPECT_EQ(d.connectivity, (std::vector<int64_t>{0, 1, 2, 3}));
  ASSERT_EQ(d.arrays.size(), 1u);
  EXPECT_EQ(d.arrays[0].values, (std::vector<double>{-1, 2, -3, 4}));
}

TEST(VtuReader, CountsOtherCellTypesByName) {
  testing::TempDir dir;
  write_text(dir.file("t.vtu"), ascii_vtu(kTetPoints + cells("0 1 2 3 0 1 2 3 0 1 2 3 0 1 2 3 0 1", "4 14 16 18",
                                                             "10 24 99 3"), 4, 4));
  const MeshData d = read_vtu(dir.file("t.vtu"));
  EXPECT_EQ(d.cell_count(), 1u);
  EXPECT_EQ(d.rejected_cells,
            (std::map<std::string, uint64_t>{{"quadratic tetra", 1}, {"VTK type 99", 1}, {"line", 1}}));
}

TEST(VtuReader, ConcatenatesPiecesOffsettingConnectivity) {
  testing::TempDir dir;
  const std::string piece = "<Piece NumberOfPoints=\"4\" NumberOfCells=\"1\">\n<PointData><DataArray type=\"UInt16\" "
                            "Name=\"s\" format=\"ascii\">1 2 3 4</DataArray></PointData>" +
                            kTetPoints + cells("0 1 3 2", "4", "10") + "</Piece>\n";
  write_text(dir.file("p.vtu"), "<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"0.1\">\n"
                                "<UnstructuredGrid>\n" + piece + piece + "</UnstructuredGrid>\n</VTKFile>\n");
  const MeshData d = read_vtu(dir.file("p.vtu"));
  EXPECT_EQ(d.point_count(), 8u);
  EXPECT_EQ(d.connectivity, (std::vector<int64_t>{0, 1, 3, 2, 4, 5, 7, 6}));
  EXPECT_EQ(d.cell_offsets, (std::vector<uint64_t>{0, 4, 8}));
  ASSERT_EQ(d.arrays.size(), 1u);
  EXPECT_EQ(d.arrays[0].values, (std::vector<double>{1, 2, 3, 4, 1, 2, 3, 4}));
}

TEST(VtuReader, RefusesWrongCountsNamingFileAndArray) {
  testing::TempDir dir;
  const std::string f = dir.file("bad.vtu");
  struct Case {
    std::string body, needle;
    int cells = 1;
  };
  const std::vector<Case> cases = {
      {kTetPoints + cells("0 1 2", "4", "10"), "past the 3 connectivity indices"},
      {kTetPoints + cells("0 1 2 3 0", "4", "10"), "connectivity has 5 indices, the offsets use 4"},
      {kTetPoints + cells("0 1 2 3 0 1 2 3", "4 3", "10 10"), "offsets decrease at cell 1", 2},
      {kTetPoints + cells("0 1 2 3 0", "5", "10"), "cell 0 (tetra) has 5 vertices, needs 4"},
      {kTetPoints + cells("0 1 2 3", "4 4", "10"), "'types' has 1 values, NumberOfCells is 2", 2},
      {cells("0 1 2 3", "4", "10"), "no <Points>"},
      {kTetPoints, "no <Cells>"},
      {"<PointData><DataArray type=\"Float32\" Name=\"T\" format=\"ascii\">1 2 3</DataArray></PointData>" + kTetPoints +
           cells("0 1 2 3", "4", "10"),
       "point array 'T' has 3 values, NumberOfPoints is 4"},
      {"<PointData><DataArray type=\"Float32\" Name=\"T\" format=\"ascii\">1 2 x 4</DataArray></PointData>" + kTetPoints +
           cells("0 1 2 3", "4", "10"),
       "'x' is not a valid number"},
      {"<Points><DataArray type=\"Float32\" NumberOfComponents=\"3\" format=\"ascii\">0 0 0 1</DataArray></Points>" +
           cells("0 1 2 3", "4", "10"),
       "Points hold 4 values, 3 x NumberOfPoints is 12"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.needle);
    write_text(f, ascii_vtu(c.body, 4, c.cells));
    expect_error([&] { read_vtu(f); }, Errc::format, f, c.needle);
  }
}

TEST(VtuReader, RefusesOtherDatasetTypesAndMissingFiles) {
  testing::TempDir dir;
  write_text(dir.file("p.vtp"), ascii_vtu(kTetPoints, 4, 0, "PolyData"));
  expect_error([&] { read_vtu(dir.file("p.vtp")); }, Errc::unsupported, dir.file("p.vtp"), "PolyData");
  expect_error([&] { read_vtu(dir.file("none.vtu")); }, Errc::io, dir.file("none.vtu"), "cannot open");
  expect_error([&] { read_pvd(kData + "hex_ascii.vtu"); }, Errc::unsupported, "hex_ascii.vtu", "UnstructuredGrid");
  write_text(dir.file("x.vtu"), "<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\">\n<UnstructuredGrid>\n<Piece>\n");
  expect_error([&] { read_vtu(dir.file("x.vtu")); }, Errc::format, dir.file("x.vtu"), "not well-formed XML at line 5");
}

TEST(VtuReader, RefusesTruncatedFiles) {
  testing::TempDir dir;
  for (const char* name : {"hex_appended_raw_raw_u32.vtu", "hex_appended_base64_zlib_u64.vtu", "hex_binary_raw_u32.vtu"}) {
    SCOPED_TRACE(name);
    const std::string text = testing::read_file(kData + name);
    const std::string appended_end = "</AppendedData>";
    size_t cut = text.find(appended_end);
    cut = cut == std::string::npos ? text.size() * 2 / 3 : cut - 40;
    write_text(dir.file(name), text.substr(0, cut));
    expect_error([&] { read_vtu(dir.file(name)); }, Errc::format, dir.file(name),
                 std::string(name).find("appended") != std::string::npos ? "truncated" : "not well-formed XML");
  }
}

TEST(VtuReader, EveryTruncationIsAnErrorOrTheWholeMesh) {
  testing::TempDir dir;
  const std::string f = dir.file("cut.vtu");
  for (const char* name : {"hex_appended_raw_zlib_u32.vtu", "hex_appended_base64_zlib_u64.vtu", "hex_binary_raw_u64.vtu"}) {
    SCOPED_TRACE(name);
    const std::string text = testing::read_file(kData + name);
    for (size_t cut = 0; cut < text.size(); cut += 11) {
      write_text(f, text.substr(0, cut));
      try {
        expect_hex_grid(read_vtu(f));  // only the closing tags after the appended data are gone
      } catch (const Error& e) {
        EXPECT_EQ(e.code(), Errc::format) << cut << ": " << e.what();
      }
    }
  }
}

TEST(VtuReader, RefusesBrokenBase64AndZlib) {
  testing::TempDir dir;
  const std::string text = testing::read_file(kData + "hex_binary_raw_u32.vtu");
  const size_t at = text.find("format=\"binary\"");
  ASSERT_NE(at, std::string::npos);
  const size_t data = text.find('>', at) + 20;
  std::string broken = text;
  broken[data] = '*';
  write_text(dir.file("b64.vtu"), broken);
  expect_error([&] { read_vtu(dir.file("b64.vtu")); }, Errc::format, dir.file("b64.vtu"),
               "point array 'temperature': invalid base64 character '*'");
  broken = text;
  broken.replace(data, 4, "AB=C");
  write_text(dir.file("pad.vtu"), broken);
  expect_error([&] { read_vtu(dir.file("pad.vtu")); }, Errc::format, dir.file("pad.vtu"), "bad base64 padding 'AB=C'");

  // One zlib block per array; UInt32 headers: 4 words (16 bytes), then the 2-byte zlib header.
  const TetMesh mesh = curve_mesh(50);
  write_vtu(dir.file("z.vtu"), mesh, {VtuWriteOptions::Encoding::appended_raw, true, false});
  std::string z = testing::read_file(dir.file("z.vtu"));
  const size_t start = z.find("   _") + 4;
  for (size_t i = 16 + 2; i < 16 + 12; ++i) z[start + i] = char(z[start + i] ^ 0x5a);
  write_text(dir.file("z.vtu"), z);
  expect_error([&] { read_vtu(dir.file("z.vtu")); }, Errc::format, dir.file("z.vtu"), "point array 'density_0': zlib block 0");
}

TEST(VtuReader, RefusesAppendedOffsetPastTheEnd) {
  testing::TempDir dir;
  write_vtu(dir.file("o.vtu"), curve_mesh(6), {VtuWriteOptions::Encoding::appended_raw, false, false});
  std::string text = testing::read_file(dir.file("o.vtu"));
  const size_t at = text.find("offset=\"0\"");
  ASSERT_NE(at, std::string::npos);
  text.replace(at, 10, "offset=\"99999\"");
  write_text(dir.file("o.vtu"), text);
  expect_error([&] { read_vtu(dir.file("o.vtu")); }, Errc::format, dir.file("o.vtu"), "appended offset 99999 is past the end");
}

}  // namespace
}  // namespace brickyard
