// The legacy VTK, gmsh and TetGen readers: small files written here with known points, cells
// and arrays (checked exactly), files written by the formats' own tools (tests/data/mesh, made
// by make_gmsh_tetgen_files.sh and make_vtk_files.py; checked against their known geometry:
// the cells of a box fill its volume exactly), and broken files refused with the line at fault.

#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <string>
#include <tuple>
#include <vector>

#include <fmt/format.h>

#include "core/error.h"
#include "preprocess/mesh_readers.h"
#include "test_util.h"

namespace brickyard {
namespace {

using brickyard::testing::TempDir;

const std::string kData = std::string(BRICKYARD_SOURCE_DIR) + "/tests/data/mesh/";

void write(const std::string& path, const std::string& content) {
  std::ofstream(path, std::ios::binary | std::ios::trunc) << content;
}

// Bytes of a binary file: values in a chosen byte order, and text.
struct Bytes {
  std::string data;
  bool big_endian = false;
  template <typename T>
  Bytes& put(T v) {
    char b[sizeof(T)];
    std::memcpy(b, &v, sizeof(T));
    if (big_endian != (std::endian::native == std::endian::big)) std::reverse(b, b + sizeof(T));
    data.append(b, sizeof(T));
    return *this;
  }
  Bytes& text(const std::string& s) {
    data += s;
    return *this;
  }
};

// Runs f, expecting Error with `code` whose message contains every one of `parts`.
template <typename F>
void expect_error(F&& f, Errc code, std::vector<std::string> parts) {
  try {
    f();
    ADD_FAILURE() << "no error thrown";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), code) << e.what();
    for (const std::string& p : parts) EXPECT_NE(std::string(e.what()).find(p), std::string::npos) << "'" << p << "' not in: " << e.what();
  }
}

double vol6(const MeshData& m, int64_t a, int64_t b, int64_t c, int64_t d) {
  const double* p = m.points.data();
  double u[3], v[3], w[3];
  for (int k = 0; k < 3; ++k) {
    u[k] = p[3 * b + k] - p[3 * a + k];
    v[k] = p[3 * c + k] - p[3 * a + k];
    w[k] = p[3 * d + k] - p[3 * a + k];
  }
  return (u[1] * v[2] - u[2] * v[1]) * w[0] + (u[2] * v[0] - u[0] * v[2]) * w[1] + (u[0] * v[1] - u[1] * v[0]) * w[2];
}

// Total volume of tets and straight prisms (split 0123, 1234, 2345), and every index in range.
double volume(const MeshData& m) {
  double total = 0;
  for (size_t c = 0; c < m.cell_count(); ++c) {
    const int64_t* v = m.connectivity.data() + m.cell_offsets[c];
    for (uint64_t k = m.cell_offsets[c]; k < m.cell_offsets[c + 1]; ++k) {
      EXPECT_GE(m.connectivity[k], 0);
      EXPECT_LT(m.connectivity[k], int64_t(m.point_count()));
    }
    if (m.cell_types[c] == MeshCellType::tetra) total += std::abs(vol6(m, v[0], v[1], v[2], v[3])) / 6;
    if (m.cell_types[c] == MeshCellType::wedge)
      total += (std::abs(vol6(m, v[0], v[1], v[2], v[3])) + std::abs(vol6(m, v[1], v[2], v[3], v[4])) +
                std::abs(vol6(m, v[2], v[3], v[4], v[5]))) / 6;
  }
  return total;
}

std::vector<int64_t> cell(const MeshData& m, size_t c) {
  return {m.connectivity.begin() + int64_t(m.cell_offsets[c]), m.connectivity.begin() + int64_t(m.cell_offsets[c + 1])};
}

const PointArray* array(const MeshData& m, const std::string& name) {
  for (const PointArray& a : m.arrays)
    if (a.name == name) return &a;
  return nullptr;
}

// ---------------------------------------------------------------------------------------------
// Legacy VTK

// 9 points: a unit tet on 0-3; a voxel on 4-7 and 0-3 (values only, no geometry needed).
const char* kVtkPoints =
    "0 0 0  1 0 0  0 1 0  0 0 1\n"
    "2 0 0  3 0 0  2 1 0  3 1 0\n"
    "2 0 1\n";

TEST(LegacyVtkReader, ReadsAsciiClassicCellsScalarsAndFieldArrays) {
  TempDir dir;
  const std::string path = dir.file("a.vtk");
  write(path, std::string("# vtk DataFile Version 3.0\nmy title\nASCII\n\nDATASET UNSTRUCTURED_GRID\n"
                          "FIELD FieldData 1\nTIME 1 1 double\n2.5\n"
                          "POINTS 9 float\n") + kVtkPoints +
                  "CELLS 4 20\n4 0 1 2 3\n8 4 5 6 7 0 1 2 3\n3 4 5 6\n1 8\n"
                  "CELL_TYPES 4\n10\n11\n5\n1\n"
                  "CELL_DATA 4\nSCALARS mat int 1\nLOOKUP_TABLE default\n1 2 3 4\n"
                  "VECTORS cv float\n0 0 0 0 0 0 0 0 0 0 0 0\n"
                  "POINT_DATA 9\nSCALARS temp%20C double\nLOOKUP_TABLE default\n0 1 2 3 4 5 6 7 8\n"
                  "SCALARS two float 2\nLOOKUP_TABLE default\n0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0\n"
                  "VECTORS v float\n1 2 3 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0\n"
                  "FIELD FieldData 2\nids 1 9 vtktypeint64\n10 11 12 13 14 15 16 17 18\n"
                  "vec 2 9 float\n0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0\n"
                  "LOOKUP_TABLE lut 2\n0 0 0 1  1 1 1 1\n");
  const MeshData m = read_legacy_vtk(path);
  EXPECT_EQ(m.format, "vtk");
  EXPECT_EQ(m.source, path);
  ASSERT_EQ(m.point_count(), 9u);
  EXPECT_EQ(m.points[3 * 7 + 0], 3.0);
  EXPECT_EQ(m.points[3 * 7 + 1], 1.0);
  ASSERT_EQ(m.cell_count(), 2u);
  EXPECT_EQ(m.cell_types[0], MeshCellType::tetra);
  EXPECT_EQ(cell(m, 0), (std::vector<int64_t>{0, 1, 2, 3}));
  EXPECT_EQ(m.cell_types[1], MeshCellType::hexahedron);  // a voxel, reordered
  EXPECT_EQ(cell(m, 1), (std::vector<int64_t>{4, 5, 7, 6, 0, 1, 3, 2}));
  EXPECT_EQ(m.rejected_cells, (std::map<std::string, uint64_t>{{"triangle", 1}, {"vertex", 1}}));
  ASSERT_EQ(m.arrays.size(), 2u);
  EXPECT_EQ(m.arrays[0].name, "temp C");
  EXPECT_EQ(m.arrays[0].values, (std::vector<double>{0, 1, 2, 3, 4, 5, 6, 7, 8}));
  EXPECT_EQ(m.arrays[1].name, "ids");
  EXPECT_EQ(m.arrays[1].values[8], 18.0);
}

// The same mesh in BINARY (big-endian), with cells in the 5.1 layout or the classic one.
std::string binary_vtk(bool layout51) {
  Bytes b;
  b.big_endian = true;
  b.text(layout51 ? "# vtk DataFile Version 5.1\nt\nBINARY\nDATASET UNSTRUCTURED_GRID\n" : "# vtk DataFile Version 4.2\nt\nBINARY\nDATASET UNSTRUCTURED_GRID\n");
  b.text("POINTS 5 double\n");
  const double pts[15] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0.25, 0.25, -1};
  for (double v : pts) b.put(v);
  b.text("\nMETADATA\nINFORMATION 0\n\n");
  if (layout51) {
    b.text("CELLS 3 9\nOFFSETS vtktypeint64\n");
    for (int64_t v : {0, 4, 9}) b.put(v);
    b.text("\nCONNECTIVITY vtktypeint64\n");
    for (int64_t v : {0, 1, 2, 3, 0, 1, 3, 2, 4}) b.put(v);
  } else {
    b.text("CELLS 2 11\n");
    for (int32_t v : {4, 0, 1, 2, 3, 5, 0, 1, 3, 2, 4}) b.put(v);
  }
  b.text("\nCELL_TYPES 2\n");
  for (int32_t v : {10, 14}) b.put(v);
  b.text("\nPOINT_DATA 5\nSCALARS s unsigned_short 1\nLOOKUP_TABLE default\n");
  for (uint16_t v : {1, 2, 3, 65535, 5}) b.put(v);
  b.text("\nNORMALS n float\n");
  for (int i = 0; i < 15; ++i) b.put(float(i));
  b.text("\nFIELD FieldData 1\nf 1 5 float\n");
  for (float v : {0.5f, 1.5f, 2.5f, 3.5f, -4.5f}) b.put(v);
  b.text("\n");
  return b.data;
}

TEST(LegacyVtkReader, ReadsBigEndianBinaryInBothCellLayouts) {
  TempDir dir;
  for (bool layout51 : {true, false}) {
    SCOPED_TRACE(layout51 ? "5.1" : "classic");
    const std::string path = dir.file("b.vtk");
    write(path, binary_vtk(layout51));
    const MeshData m = read_legacy_vtk(path);
    ASSERT_EQ(m.point_count(), 5u);
    EXPECT_EQ(m.points[14], -1.0);
    EXPECT_EQ(m.points[12], 0.25);
    ASSERT_EQ(m.cell_count(), 2u);
    EXPECT_EQ(m.cell_types[1], MeshCellType::pyramid);
    EXPECT_EQ(cell(m, 1), (std::vector<int64_t>{0, 1, 3, 2, 4}));
    ASSERT_EQ(m.arrays.size(), 2u);
    EXPECT_EQ(m.arrays[0].values, (std::vector<double>{1, 2, 3, 65535, 5}));
    EXPECT_EQ(m.arrays[1].name, "f");
    EXPECT_EQ(m.arrays[1].values[4], -4.5);
  }
}

TEST(LegacyVtkReader, ReadsFilesWrittenByVtk) {
  // tests/data/mesh/make_vtk_files.py: a tetra, a wedge, a pyramid, a triangle and a voxel;
  // temperature = x + 2y + 3z, id = 10 i, velocity (3 components) skipped.
  int read = 0;
  for (const char* name : {"mixed_legacy_ascii.vtk", "mixed_legacy42_ascii.vtk", "mixed_legacy_binary.vtk"}) {
    const std::string path = kData + name;
    if (!std::filesystem::exists(path)) continue;
    SCOPED_TRACE(name);
    ++read;
    const MeshData m = read_legacy_vtk(path);
    ASSERT_EQ(m.point_count(), 26u);
    ASSERT_EQ(m.cell_count(), 4u);
    EXPECT_EQ(m.cell_types, (std::vector<MeshCellType>{MeshCellType::tetra, MeshCellType::wedge, MeshCellType::pyramid,
                                                       MeshCellType::hexahedron}));
    EXPECT_EQ(cell(m, 1), (std::vector<int64_t>{4, 5, 6, 7, 8, 9}));
    EXPECT_EQ(cell(m, 3), (std::vector<int64_t>{18, 19, 21, 20, 22, 23, 25, 24}));
    EXPECT_EQ(m.rejected_cells, (std::map<std::string, uint64_t>{{"triangle", 1}}));
    const PointArray* t = array(m, "temperature");
    const PointArray* id = array(m, "id");
    ASSERT_TRUE(t && id);
    EXPECT_EQ(m.arrays.size(), 2u);
    for (size_t i = 0; i < 26; ++i) {
      EXPECT_DOUBLE_EQ(t->values[i], m.points[3 * i] + 2 * m.points[3 * i + 1] + 3 * m.points[3 * i + 2]);
      EXPECT_EQ(id->values[i], 10.0 * double(i));
    }
  }
  if (read == 0) GTEST_SKIP() << "no VTK-written .vtk files in " << kData;
}

TEST(LegacyVtkReader, RefusesOtherDatasetsAndBrokenFiles) {
  TempDir dir;
  const std::string path = dir.file("e.vtk");
  const std::string head = "# vtk DataFile Version 3.0\nt\nASCII\nDATASET UNSTRUCTURED_GRID\n";
  write(path, "# vtk DataFile Version 3.0\nt\nASCII\nDATASET STRUCTURED_POINTS\nDIMENSIONS 2 2 2\n");
  expect_error([&] { read_legacy_vtk(path); }, Errc::unsupported, {"STRUCTURED_POINTS", path});
  write(path, "not a vtk file\n");
  expect_error([&] { read_legacy_vtk(path); }, Errc::format, {"line 1"});
  write(path, head + "POINTS 3 float\n0 0 0 1 0 0 0 1\n");  // truncated
  expect_error([&] { read_legacy_vtk(path); }, Errc::format, {"POINTS"});
  write(path, head + "POINTS 2 float\n0 0 0\n1 x 0\n");
  expect_error([&] { read_legacy_vtk(path); }, Errc::format, {"line 7", "'x'"});
  write(path, head + "POINTS 1000000000000000 float\n0 0 0\n");  // a lying count: no allocation
  expect_error([&] { read_legacy_vtk(path); }, Errc::format, {"POINTS"});
  write(path, head + "POINTS 1 bit\n0 0 0\n");
  expect_error([&] { read_legacy_vtk(path); }, Errc::unsupported, {"bit"});
  write(path, head + "POINTS 4 float\n0 0 0 1 0 0 0 1 0 0 0 1\nCELLS 1 5\n4 0 1 2 3\nCELL_TYPES 2\n10 10\n");
  expect_error([&] { read_legacy_vtk(path); }, Errc::format, {"CELL_TYPES"});
  write(path, head + "POINTS 4 float\n0 0 0 1 0 0 0 1 0 0 0 1\nCELLS 1 6\n4 0 1 2 3\nCELL_TYPES 1\n10\n");
  expect_error([&] { read_legacy_vtk(path); }, Errc::format, {"CELLS"});
  write(path, head + "POINTS 1 float\n0 0 0\nBOGUS 3\n");
  expect_error([&] { read_legacy_vtk(path); }, Errc::format, {"line 7", "BOGUS"});
  std::string bin = binary_vtk(true);
  write(path, bin.substr(0, bin.size() / 2));
  expect_error([&] { read_legacy_vtk(path); }, Errc::format, {path});
  expect_error([&] { read_legacy_vtk(dir.file("missing.vtk")); }, Errc::io, {"missing.vtk"});
}

// ---------------------------------------------------------------------------------------------
// gmsh

// One tet, one hex, one prism, one pyramid on 13 nodes with sparse tags 10, 20, ... 130;
// a triangle and a line are rejected. temp has two time steps, p one; vel (3 components) skipped.
const double kGmshPoints[13][3] = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {1, 1, 0}, {1, 0, 1},
                                   {1, 1, 1}, {0, 1, 1}, {0.5, 0.5, 2}, {2, 0, 0}, {2, 1, 0}, {2, 0, 1}, {2, 1, 1}};
const std::vector<std::vector<int>> kGmshElements = {
    {4, 1, 2, 3, 4}, {5, 1, 2, 5, 3, 4, 6, 7, 8}, {6, 2, 10, 5, 6, 12, 7}, {7, 4, 6, 7, 8, 9}, {2, 1, 2, 3}, {1, 1, 2}};

std::string gmsh_node_data_ascii(const std::string& name, int step, int ncomp, const std::vector<int>& nodes) {
  std::string s = fmt::format("$NodeData\n1\n\"{}\"\n1\n{}.5\n3\n{}\n{}\n{}\n", name, step, step, ncomp, nodes.size());
  for (int n : nodes) {
    s += std::to_string(10 * n);
    for (int c = 0; c < ncomp; ++c) s += fmt::format(" {}", 100 * step + n + c);
    s += "\n";
  }
  return s + "$EndNodeData\n";
}

std::string gmsh_ascii(int version) {
  std::string s = version == 2 ? "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$PhysicalNames\n1\n3 1 \"vol\"\n$EndPhysicalNames\n"
                               : "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Entities\n0 0 0 1\n1 0 0 0 1 1 1 0 0\n$EndEntities\n";
  if (version == 2) {
    s += "$Nodes\n13\n";
    for (int i = 0; i < 13; ++i) s += fmt::format("{} {} {} {}\n", 10 * (i + 1), kGmshPoints[i][0], kGmshPoints[i][1], kGmshPoints[i][2]);
    s += "$EndNodes\n$Elements\n6\n";
    for (size_t e = 0; e < kGmshElements.size(); ++e) {
      s += fmt::format("{} {} 2 1 1", e + 1, kGmshElements[e][0]);
      for (size_t k = 1; k < kGmshElements[e].size(); ++k) s += fmt::format(" {}", 10 * kGmshElements[e][k]);
      s += "\n";
    }
  } else {  // two node blocks (5 and 8 nodes), one element block per element
    s += "$Nodes\n2 13 10 130\n";
    for (auto [first, count] : {std::pair{0, 5}, std::pair{5, 8}}) {
      s += fmt::format("3 1 0 {}\n", count);
      for (int i = first; i < first + count; ++i) s += fmt::format("{}\n", 10 * (i + 1));
      for (int i = first; i < first + count; ++i) s += fmt::format("{} {} {}\n", kGmshPoints[i][0], kGmshPoints[i][1], kGmshPoints[i][2]);
    }
    s += "$EndNodes\n$Elements\n6 6 1 6\n";
    for (size_t e = 0; e < kGmshElements.size(); ++e) {
      s += fmt::format("3 1 {} 1\n{}", kGmshElements[e][0], e + 1);
      for (size_t k = 1; k < kGmshElements[e].size(); ++k) s += fmt::format(" {}", 10 * kGmshElements[e][k]);
      s += "\n";
    }
  }
  s += "$EndElements\n";
  std::vector<int> all;
  for (int i = 1; i <= 13; ++i) all.push_back(i);
  s += gmsh_node_data_ascii("temp", 0, 1, all) + gmsh_node_data_ascii("vel", 0, 3, all) +
       gmsh_node_data_ascii("temp", 1, 1, all) + gmsh_node_data_ascii("p", 0, 1, {2, 5});
  return s;
}

// The same in binary (little-endian), with NodeData.
std::string gmsh_binary(int version) {
  Bytes b;
  b.text(version == 2 ? "$MeshFormat\n2.2 1 8\n" : "$MeshFormat\n4.1 1 8\n").put(int32_t(1)).text("\n$EndMeshFormat\n");
  b.text("$Nodes\n");
  if (version == 2) {
    b.text("13\n");
    for (int i = 0; i < 13; ++i) b.put(int32_t(10 * (i + 1))).put(kGmshPoints[i][0]).put(kGmshPoints[i][1]).put(kGmshPoints[i][2]);
  } else {
    b.put(uint64_t(1)).put(uint64_t(13)).put(uint64_t(10)).put(uint64_t(130));
    b.put(int32_t(3)).put(int32_t(1)).put(int32_t(0)).put(uint64_t(13));
    for (int i = 0; i < 13; ++i) b.put(uint64_t(10 * (i + 1)));
    for (int i = 0; i < 13; ++i) b.put(kGmshPoints[i][0]).put(kGmshPoints[i][1]).put(kGmshPoints[i][2]);
  }
  b.text("\n$EndNodes\n$Elements\n");
  if (version == 2) {
    b.text("6\n");
    for (size_t e = 0; e < kGmshElements.size(); ++e) {
      b.put(int32_t(kGmshElements[e][0])).put(int32_t(1)).put(int32_t(2));
      b.put(int32_t(e + 1)).put(int32_t(1)).put(int32_t(1));
      for (size_t k = 1; k < kGmshElements[e].size(); ++k) b.put(int32_t(10 * kGmshElements[e][k]));
    }
  } else {
    b.put(uint64_t(6)).put(uint64_t(6)).put(uint64_t(1)).put(uint64_t(6));
    for (size_t e = 0; e < kGmshElements.size(); ++e) {
      b.put(int32_t(3)).put(int32_t(1)).put(int32_t(kGmshElements[e][0])).put(uint64_t(1)).put(uint64_t(e + 1));
      for (size_t k = 1; k < kGmshElements[e].size(); ++k) b.put(uint64_t(10 * kGmshElements[e][k]));
    }
  }
  b.text("\n$EndElements\n");
  for (auto [name, step, ncomp] : {std::tuple{"temp", 0, 1}, std::tuple{"vel", 0, 3}, std::tuple{"temp", 1, 1}}) {
    b.text(fmt::format("$NodeData\n1\n\"{}\"\n1\n0.0\n3\n{}\n{}\n13\n", name, step, ncomp));
    for (int n = 1; n <= 13; ++n) {
      b.put(int32_t(10 * n));
      for (int c = 0; c < ncomp; ++c) b.put(double(100 * step + n + c));
    }
    b.text("\n$EndNodeData\n");
  }
  b.text("$NodeData\n1\n\"p\"\n1\n0.0\n3\n0\n1\n2\n").put(int32_t(20)).put(2.0).put(int32_t(50)).put(5.0).text("\n$EndNodeData\n");
  return b.data;
}

void expect_gmsh_mesh(const MeshData& m) {
  ASSERT_EQ(m.point_count(), 13u);
  EXPECT_EQ(m.points[3 * 8 + 2], 2.0);
  ASSERT_EQ(m.cell_count(), 4u);
  EXPECT_EQ(m.cell_types, (std::vector<MeshCellType>{MeshCellType::tetra, MeshCellType::hexahedron, MeshCellType::wedge,
                                                     MeshCellType::pyramid}));
  EXPECT_EQ(cell(m, 0), (std::vector<int64_t>{0, 1, 2, 3}));  // tags 10..40 -> 0..3
  EXPECT_EQ(cell(m, 2), (std::vector<int64_t>{1, 9, 4, 5, 11, 6}));
  EXPECT_EQ(m.rejected_cells, (std::map<std::string, uint64_t>{{"line", 1}, {"triangle", 1}}));
  ASSERT_EQ(m.arrays.size(), 3u);
  EXPECT_EQ(m.arrays[0].name, "temp_0");
  EXPECT_EQ(m.arrays[1].name, "temp_1");
  EXPECT_EQ(m.arrays[2].name, "p");
  for (size_t i = 0; i < 13; ++i) {
    EXPECT_EQ(m.arrays[0].values[i], double(i + 1));
    EXPECT_EQ(m.arrays[1].values[i], double(101 + i));
  }
  EXPECT_EQ(m.arrays[2].values[1], 2.0);
  EXPECT_EQ(m.arrays[2].values[4], 5.0);
  EXPECT_TRUE(std::isnan(m.arrays[2].values[0]));  // a node the view does not give
}

TEST(GmshReader, ReadsAsciiAndBinaryMsh2AndMsh41WithSparseTagsAndNodeData) {
  TempDir dir;
  for (int version : {2, 4}) {
    for (bool binary : {false, true}) {
      SCOPED_TRACE(fmt::format("MSH {} {}", version, binary ? "binary" : "ASCII"));
      const std::string path = dir.file("m.msh");
      write(path, binary ? gmsh_binary(version) : gmsh_ascii(version));
      const MeshData m = read_gmsh(path);
      EXPECT_EQ(m.format, version == 2 ? "msh2" : "msh4");
      expect_gmsh_mesh(m);
    }
  }
}

TEST(GmshReader, ReadsBigEndianBinary) {
  TempDir dir;
  Bytes b;
  b.big_endian = true;
  b.text("$MeshFormat\n2.2 1 8\n").put(int32_t(1)).text("\n$EndMeshFormat\n$Nodes\n4\n");
  for (int i = 0; i < 4; ++i) b.put(int32_t(i + 1)).put(double(i == 1)).put(double(i == 2)).put(double(i == 3));
  b.text("\n$EndNodes\n$Elements\n1\n").put(int32_t(4)).put(int32_t(1)).put(int32_t(0)).put(int32_t(7));
  for (int32_t v : {1, 2, 3, 4}) b.put(v);
  b.text("\n$EndElements\n");
  write(dir.file("be.msh"), b.data);
  const MeshData m = read_gmsh(dir.file("be.msh"));
  ASSERT_EQ(m.point_count(), 4u);
  EXPECT_EQ(m.points[3 * 3 + 2], 1.0);
  EXPECT_EQ(cell(m, 0), (std::vector<int64_t>{0, 1, 2, 3}));
}

TEST(GmshReader, ReadsFilesWrittenByGmsh) {
  // make_gmsh_tetgen_files.sh: the unit cube in tets (45 nodes; its faces, edges and corners
  // are saved too), in MSH 2.2 and 4.1, ASCII and binary; all four hold the same mesh.
  std::optional<MeshData> first;
  for (const char* name : {"box_msh22.msh", "box_msh22_bin.msh", "box_msh41.msh", "box_msh41_bin.msh"}) {
    SCOPED_TRACE(name);
    const MeshData m = read_gmsh(kData + name);
    EXPECT_EQ(m.format, std::string(name).find("41") != std::string::npos ? "msh4" : "msh2");
    EXPECT_EQ(m.point_count(), 45u);
    EXPECT_GT(m.cell_count(), 24u);
    EXPECT_NEAR(volume(m), 1.0, 1e-9);
    for (double v : m.points) EXPECT_TRUE(v >= -1e-12 && v <= 1 + 1e-12);
    EXPECT_GT(m.rejected_cells.at("triangle"), 0u);
    EXPECT_EQ(m.rejected_cells.at("point"), 8u);
    EXPECT_EQ(m.rejected_cells.at("line") % 12, 0u);
    if (!first) {
      first = m;
    } else {
      ASSERT_EQ(m.points.size(), first->points.size());
      for (size_t i = 0; i < m.points.size(); ++i) EXPECT_NEAR(m.points[i], first->points[i], 1e-15);  // ASCII: 16 digits
      EXPECT_EQ(m.connectivity, first->connectivity);
      EXPECT_EQ(m.rejected_cells, first->rejected_cells);
    }
  }
  // A 2 x 1 x 0.5 slab of prisms: two layers, so every cell is a wedge of height 0.25 with
  // vertex i+3 straight above vertex i.
  for (const char* name : {"prism_msh41.msh", "prism_msh2_bin.msh"}) {
    SCOPED_TRACE(name);
    const MeshData m = read_gmsh(kData + name);
    ASSERT_GT(m.cell_count(), 0u);
    for (size_t c = 0; c < m.cell_count(); ++c) {
      ASSERT_EQ(m.cell_types[c], MeshCellType::wedge);
      const std::vector<int64_t> v = cell(m, c);
      for (int k = 0; k < 3; ++k) {
        EXPECT_EQ(m.points[3 * v[k]], m.points[3 * v[k + 3]]);
        EXPECT_EQ(m.points[3 * v[k] + 1], m.points[3 * v[k + 3] + 1]);
        EXPECT_NEAR(m.points[3 * v[k + 3] + 2] - m.points[3 * v[k] + 2], 0.25, 1e-12);
      }
    }
    EXPECT_NEAR(volume(m), 1.0, 1e-9);
  }
}

TEST(GmshReader, RefusesBrokenFiles) {
  TempDir dir;
  const std::string path = dir.file("e.msh");
  const std::string head = "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n";
  write(path, head + "$Nodes\n3\n1 0 0 0\n2 1 0 0\n$EndNodes\n");  // fewer nodes than it says
  expect_error([&] { read_gmsh(path); }, Errc::format, {"line 8", "$EndNodes"});
  write(path, head + "$Nodes\n2\n1 0 0 0\n2 1 0 0\n3 0 1 0\n$EndNodes\n");  // more
  expect_error([&] { read_gmsh(path); }, Errc::format, {"line 8", "$EndNodes"});
  write(path, head + "$Nodes\n2\n1 0 0 0\n2 1 zero 0\n");
  expect_error([&] { read_gmsh(path); }, Errc::format, {"line 7", "'zero'"});
  write(path, head + "$Nodes\n2\n1 0 0 0\n2 1.000000 0.0000");  // truncated
  expect_error([&] { read_gmsh(path); }, Errc::format, {"ends"});
  write(path, head + "$Nodes\n99999999999999\n1 0 0 0\n$EndNodes\n");  // a lying count
  expect_error([&] { read_gmsh(path); }, Errc::format, {"$Nodes"});
  write(path, head + "$Comments\nno end\n");
  expect_error([&] { read_gmsh(path); }, Errc::format, {"$EndComments"});
  write(path, "$MeshFormat\n4.0 0 8\n$EndMeshFormat\n");
  expect_error([&] { read_gmsh(path); }, Errc::unsupported, {"4.0"});
  write(path, "solid cube\n");
  expect_error([&] { read_gmsh(path); }, Errc::format, {"$MeshFormat"});
  write(path, Bytes().text("$MeshFormat\n2.2 1 8\n").put(int32_t(7)).text("\n$EndMeshFormat\n").data);
  expect_error([&] { read_gmsh(path); }, Errc::format, {"byte-order"});
  const std::string bin = gmsh_binary(4);
  write(path, bin.substr(0, bin.find("$EndNodes") - 30));
  expect_error([&] { read_gmsh(path); }, Errc::format, {"$Nodes"});
  write(path, bin.substr(0, bin.find("$EndElements") - 9));
  expect_error([&] { read_gmsh(path); }, Errc::format, {"ends"});
  write(path, head + gmsh_node_data_ascii("t", 0, 1, {1}));  // data for a node that does not exist
  expect_error([&] { read_gmsh(path); }, Errc::format, {"node tag 10"});
  expect_error([&] { read_gmsh(dir.file("none.msh")); }, Errc::io, {"none.msh"});
}

// ---------------------------------------------------------------------------------------------
// TetGen

TEST(TetgenReader, ReadsNodeAndEleFromAnyOfTheirNames) {
  TempDir dir;
  for (int base : {0, 1}) {
    SCOPED_TRACE(base);
    write(dir.file("t.node"), fmt::format("# a comment\n5 3 2 1  # header\n"
                                          "{} 0 0 0 1.5 -1 0\n{} 1 0 0 2.5 -2 1\n\n{} 0 1 0 3.5 -3 1\n"
                                          "{} 0 0 1 4.5 -4 0\n{} 1 1 1 5.5 -5 0\n# end\n",
                                          base, base + 1, base + 2, base + 3, base + 4));
    write(dir.file("t.ele"), fmt::format("2 4 1\n{0} {0} {1} {2} {3} 7\n{1} {1} {2} {3} {4} 8\n", base, base + 1, base + 2,
                                         base + 3, base + 4));
    for (const std::string& name : {dir.file("t.node"), dir.file("t.ele"), dir.file("t")}) {
      const MeshData m = read_tetgen(name);
      EXPECT_EQ(m.format, "tetgen");
      ASSERT_EQ(m.point_count(), 5u);
      EXPECT_EQ(m.points[3 * 4 + 1], 1.0);
      ASSERT_EQ(m.cell_count(), 2u);
      EXPECT_EQ(cell(m, 0), (std::vector<int64_t>{0, 1, 2, 3}));
      EXPECT_EQ(cell(m, 1), (std::vector<int64_t>{1, 2, 3, 4}));
      ASSERT_EQ(m.arrays.size(), 2u);
      EXPECT_EQ(m.arrays[0].name, "attr0");
      EXPECT_EQ(m.arrays[0].values, (std::vector<double>{1.5, 2.5, 3.5, 4.5, 5.5}));
      EXPECT_EQ(m.arrays[1].name, "attr1");
      EXPECT_EQ(m.arrays[1].values[4], -5.0);
    }
  }
}

TEST(TetgenReader, KeepsTheCornersOfSecondOrderTetsAndDeliversIndicesUnchecked) {
  TempDir dir;
  write(dir.file("q.node"), "4 3 0 0\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n");
  write(dir.file("q.ele"), "2 10 0\n1 1 2 3 4 9 9 9 9 9 9\n2 1 2 3 99 1 1 1 1 1 1\n");
  const MeshData m = read_tetgen(dir.file("q"));
  ASSERT_EQ(m.cell_count(), 2u);
  EXPECT_EQ(cell(m, 0), (std::vector<int64_t>{0, 1, 2, 3}));
  EXPECT_EQ(cell(m, 1), (std::vector<int64_t>{0, 1, 2, 98}));  // tetrahedralize()'s to check
}

TEST(TetgenReader, ReadsFilesWrittenByTetgen) {
  // make_gmsh_tetgen_files.sh: tetgen -qa0.05 cube.poly, the unit cube with the attribute
  // x + 2y + 3z at its 8 corners (TetGen 1.5 gives the Steiner points it adds attribute 0).
  const MeshData m = read_tetgen(kData + "cube.1.node");
  EXPECT_EQ(m.point_count(), 50u);
  EXPECT_EQ(m.cell_count(), 68u);
  EXPECT_NEAR(volume(m), 1.0, 1e-9);
  ASSERT_EQ(m.arrays.size(), 1u);
  for (size_t i = 0; i < 8; ++i)
    EXPECT_NEAR(m.arrays[0].values[i], m.points[3 * i] + 2 * m.points[3 * i + 1] + 3 * m.points[3 * i + 2], 1e-9) << i;
}

TEST(TetgenReader, RefusesBrokenFiles) {
  TempDir dir;
  write(dir.file("b.node"), "3 3 0 0\n0 0 0 0\n1 1 0 0\n2 0 1 0\n");
  expect_error([&] { read_tetgen(dir.file("b")); }, Errc::io, {"b.ele"});
  write(dir.file("b.ele"), "1 4 0\n0 0 1 2 three\n");
  expect_error([&] { read_tetgen(dir.file("b")); }, Errc::format, {"b.ele", "line 2", "'three'"});
  write(dir.file("b.ele"), "2 4 0\n0 0 1 2 2\n1   1   2   0");  // truncated
  expect_error([&] { read_tetgen(dir.file("b")); }, Errc::format, {"b.ele", "ends"});
  write(dir.file("b.ele"), "100000000000 4 0\n0 0 1 2 2\n");  // a lying count
  expect_error([&] { read_tetgen(dir.file("b")); }, Errc::format, {"b.ele", "tetrahedra"});
  write(dir.file("b.node"), "4 3 0 0\n0 0 0 0\n1 1 0 0\n2 0 1 0\n");  // fewer points than it says
  expect_error([&] { read_tetgen(dir.file("b")); }, Errc::format, {"b.node"});
  write(dir.file("b.node"), "2 3 0 0\n5 0 0 0\n6 1 0 0\n");
  expect_error([&] { read_tetgen(dir.file("b")); }, Errc::format, {"line 2", "0 or 1"});
  write(dir.file("b.node"), "2 2 0 0\n0 0 0\n1 1 0\n");
  expect_error([&] { read_tetgen(dir.file("b")); }, Errc::unsupported, {"dimension 2"});
}

}  // namespace
}  // namespace brickyard
