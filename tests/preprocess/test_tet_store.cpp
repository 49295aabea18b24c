// Tetrahedral meshes from reader output to a clustered store: validation (every degenerate kind
// counted, with cell ids, and skipped; inverted tets re-oriented), the split of hexahedra,
// wedges and pyramids, the choice of arrays and time steps, partitioning, procedural meshes,
// and the store's table against its pages.

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <array>
#include <limits>
#include <map>
#include <set>

#include "preprocess/mesh_data.h"
#include "preprocess/mesh_readers.h"
#include "preprocess/tet_builder.h"
#include "storage/store.h"
#include "test_util.h"

namespace brickyard {
namespace {

/// Two unit cubes' worth of points on a 3x2x2 lattice, a scalar x + 10 y + 100 z.
MeshData lattice(int nx = 3, int ny = 2, int nz = 2) {
  MeshData d;
  d.source = "lattice.vtu";
  d.format = "test";
  PointArray a{"f", {}};
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i) {
        d.points.insert(d.points.end(), {double(i), double(j), double(k)});
        a.values.push_back(i + 10.0 * j + 100.0 * k);
      }
  d.arrays.push_back(a);
  return d;
}

int64_t at(int i, int j, int k, int nx = 3, int ny = 2) { return (k * ny + j) * nx + i; }

double volume_of(const TetMesh& m) {
  double v = 0;
  for (size_t t = 0; t < m.tet_count(); ++t) {
    Vec3d p[4];
    for (int c = 0; c < 4; ++c) {
      const uint32_t w = m.tets[4 * t + size_t(c)];
      p[c] = Vec3d(m.positions[3 * w], m.positions[3 * w + 1], m.positions[3 * w + 2]);
    }
    const double v6 = tet_volume6(p[0], p[1], p[2], p[3]);
    EXPECT_GT(v6, 0) << "tet " << t;
    v += v6 / 6;
  }
  return v;
}

TEST(Tetrahedralize, CountsEveryDegenerateKindWithItsCellsAndSkipsThem) {
  MeshData d = lattice();
  d.add_cell(MeshCellType::tetra, {at(0, 0, 0), at(1, 0, 0), at(0, 1, 0), at(0, 0, 1)});  // 0: valid
  d.add_cell(MeshCellType::tetra, {at(0, 0, 0), at(0, 1, 0), at(1, 0, 0), at(0, 0, 1)});  // 1: inverted
  d.add_cell(MeshCellType::tetra, {at(0, 0, 0), at(1, 0, 0), at(2, 0, 0), at(0, 0, 1)});  // 2: flat
  d.add_cell(MeshCellType::tetra, {at(0, 0, 0), at(0, 0, 0), at(2, 0, 0), at(0, 0, 1)});  // 3: duplicate
  d.add_cell(MeshCellType::tetra, {at(0, 0, 0), 99, at(2, 0, 0), at(0, 0, 1)});           // 4: out of range
  d.add_cell(MeshCellType::tetra, {at(0, 0, 0), -1, at(2, 0, 0), at(0, 0, 1)});           // 5: negative
  d.add_cell(MeshCellType::tetra, {at(1, 0, 0), at(2, 1, 0), at(1, 1, 0), at(1, 0, 1)});  // 6: NaN point
  d.add_cell(MeshCellType::tetra, {at(1, 1, 1), at(2, 1, 1), at(1, 0, 1), at(1, 1, 0)});  // 7: Inf scalar
  d.points[size_t(at(2, 1, 0)) * 3 + 1] = std::numeric_limits<double>::quiet_NaN();
  d.arrays[0].values[size_t(at(2, 1, 1))] = std::numeric_limits<double>::infinity();
  d.rejected_cells["triangle"] = 3;
  const TetMesh m = tetrahedralize(std::move(d), {});
  const MeshReport& r = m.report;
  EXPECT_EQ(r.tets, 2u);
  EXPECT_EQ(m.tet_count(), 2u);
  EXPECT_EQ(r.reoriented, 1u);
  EXPECT_EQ(r.zero_volume.count, 1u);
  EXPECT_EQ(r.zero_volume.first_cells, std::vector<uint64_t>{2});
  EXPECT_EQ(r.duplicate_vertex.first_cells, std::vector<uint64_t>{3});
  EXPECT_EQ(r.index_out_of_range.first_cells, (std::vector<uint64_t>{4, 5}));
  EXPECT_EQ(r.nonfinite_point.first_cells, std::vector<uint64_t>{6});
  EXPECT_EQ(r.nonfinite_scalar.first_cells, std::vector<uint64_t>{7});
  EXPECT_EQ(r.rejected_cells.at("triangle"), 3u);
  EXPECT_NEAR(volume_of(m), 2.0 / 6, 1e-12);
  const std::vector<std::string> lines = r.lines();
  auto has = [&](const std::string& s) {
    for (const auto& l : lines)
      if (l.find(s) != std::string::npos) return true;
    return false;
  };
  EXPECT_TRUE(has("2 tets skipped: vertex index out of range (cells 4, 5)"));
  EXPECT_TRUE(has("1 inverted tets re-oriented"));
  EXPECT_TRUE(has("3 triangle cells rejected"));
  // Only the points the valid tets use are kept.
  EXPECT_EQ(m.vertex_count(), 4u);
}

TEST(Tetrahedralize, AMeshWithNothingValidIsAnErrorThatSaysWhy) {
  MeshData d = lattice();
  d.add_cell(MeshCellType::tetra, {at(0, 0, 0), at(1, 0, 0), at(2, 0, 0), at(0, 0, 1)});
  try {
    (void)tetrahedralize(std::move(d), {});
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), Errc::format);
    EXPECT_EQ(e.file(), "lattice.vtu");
    EXPECT_NE(e.message().find("no valid tetrahedron is left: every cell was skipped"), std::string::npos) << e.what();
    EXPECT_NE(e.message().find("zero volume"), std::string::npos) << e.what();
  }
  MeshData surface = lattice();
  surface.rejected_cells["triangle"] = 4;
  try {
    (void)tetrahedralize(std::move(surface), {});
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(e.message().find("no volume cells"), std::string::npos) << e.what();
  }
}

TEST(Tetrahedralize, SplitsHexWedgeAndPyramidCellsFillingTheirVolume) {
  MeshData d = lattice();
  d.add_cell(MeshCellType::hexahedron, {at(0, 0, 0), at(1, 0, 0), at(1, 1, 0), at(0, 1, 0), at(0, 0, 1), at(1, 0, 1),
                                        at(1, 1, 1), at(0, 1, 1)});
  d.add_cell(MeshCellType::wedge, {at(1, 0, 0), at(2, 0, 0), at(1, 1, 0), at(1, 0, 1), at(2, 0, 1), at(1, 1, 1)});
  d.add_cell(MeshCellType::pyramid, {at(1, 1, 0), at(2, 1, 0), at(2, 1, 1), at(1, 1, 1), at(2, 0, 0)});
  const TetMesh m = tetrahedralize(std::move(d), {});
  EXPECT_EQ(m.report.split.at("hexahedron"), 1u);
  EXPECT_EQ(m.report.split.at("wedge"), 1u);
  EXPECT_EQ(m.report.split.at("pyramid"), 1u);
  EXPECT_EQ(m.tet_count(), 12u + 8u + 2u);
  EXPECT_EQ(m.report.centre_points, 2u);
  // Unit cube + half cube + pyramid of base 1 and height 1.
  EXPECT_NEAR(volume_of(m), 1.0 + 0.5 + 1.0 / 3, 1e-12);
  // The hexahedron's centre gets the mean of its corners: the trilinear value there.
  bool found = false;
  for (size_t v = 0; v < m.vertex_count(); ++v)
    if (m.positions[3 * v] == 0.5f && m.positions[3 * v + 1] == 0.5f && m.positions[3 * v + 2] == 0.5f) {
      EXPECT_FLOAT_EQ(m.scalars[0][v], 0.5f + 5 + 50);
      found = true;
    }
  EXPECT_TRUE(found);
  const std::vector<std::string> lines = m.report.lines();
  EXPECT_NE(std::find(lines.begin(), lines.end(), "1 hexahedron -> 12 tets"), lines.end());
}

TEST(Tetrahedralize, ASeriesOfNumberedArraysBecomesTimeSteps) {
  auto with_arrays = [] {
    MeshData d = lattice();
    d.arrays.clear();
    for (const char* name : {"T_2", "T_0", "T_1", "p"}) {
      PointArray a{name, std::vector<double>(d.point_count(), name[0] == 'p' ? 9.0 : double(name[2] - '0'))};
      d.arrays.push_back(a);
    }
    d.add_cell(MeshCellType::tetra, {at(0, 0, 0), at(1, 0, 0), at(0, 1, 0), at(0, 0, 1)});
    return d;
  };
  TetMesh m = tetrahedralize(with_arrays(), {});
  ASSERT_EQ(m.time_steps(), 3);
  EXPECT_EQ(m.array_name, "T");
  for (int s = 0; s < 3; ++s) EXPECT_EQ(m.scalars[size_t(s)][0], float(s));
  EXPECT_EQ(m.step_names, (std::vector<std::string>{"T_0", "T_1", "T_2"}));
  m = tetrahedralize(with_arrays(), {"T_1", true});
  EXPECT_EQ(m.time_steps(), 1);
  EXPECT_EQ(m.scalars[0][0], 1.0f);
  m = tetrahedralize(with_arrays(), {"p", true});
  EXPECT_EQ(m.scalars[0][0], 9.0f);
  m = tetrahedralize(with_arrays(), {"", false});
  EXPECT_EQ(m.time_steps(), 1);
  try {
    (void)tetrahedralize(with_arrays(), {"pressure", true});
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.field(), "--array");
    EXPECT_NE(e.message().find("no point array 'pressure' (arrays: T_2, T_0, T_1, p)"), std::string::npos) << e.what();
  }
}

TEST(TetStore, PartitionsIntoCoherentClustersWhoseTableMatchesTheirPages) {
  testing::TempDir dir;
  MeshData d = lattice(9, 9, 9);
  auto id = [](int i, int j, int k) { return at(i, j, k, 9, 9); };
  for (int k = 0; k < 8; ++k)
    for (int j = 0; j < 8; ++j)
      for (int i = 0; i < 8; ++i)
        d.add_cell(MeshCellType::hexahedron, {id(i, j, k), id(i + 1, j, k), id(i + 1, j + 1, k), id(i, j + 1, k),
                                              id(i, j, k + 1), id(i + 1, j, k + 1), id(i + 1, j + 1, k + 1), id(i, j + 1, k + 1)});
  TetMesh mesh = tetrahedralize(std::move(d), {});
  const uint64_t tets = mesh.tet_count();
  auto source = partition_mesh(std::move(mesh), 100, "lattice", R"({"kind": "test"})", 0);
  TetBuildOptions o;
  o.cluster_tets = 100;
  const BuildResult r = build_tet_store(*source, dir.file("m.store"), o);
  EXPECT_EQ(r.manifest.mesh.tets, tets);
  Store store(dir.file("m.store"));
  EXPECT_EQ(store.kind(), DataKind::tetrahedral);
  EXPECT_TRUE(store.manifest().complete);
  ASSERT_EQ(store.clusters().size(), source->cluster_count());
  EXPECT_GE(store.clusters().size(), tets / 100);
  double volume_sum = 0;
  uint64_t sum = 0;
  std::vector<std::byte> page(store.manifest().mesh.page_bytes);
  auto txn = store.begin_read();
  for (size_t c = 0; c < store.clusters().size(); ++c) {
    const TetCluster& e = store.clusters()[c];
    EXPECT_LE(e.tets, 100u);
    EXPECT_GE(e.tets, 50u);
    sum += e.tets;
    store.read_page(txn, {RecordKind::tet_cluster, c}, page);
    const TetClusterPage p = TetClusterPage::view(page);
    ASSERT_EQ(p.tet_count, e.tets);
    Vec3d lo(1e9), hi(-1e9);
    for (uint32_t v = 0; v < p.vertex_count; ++v)
      for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], double(p.positions[3 * v + a])), hi[a] = std::max(hi[a], double(p.positions[3 * v + a]));
    for (int a = 0; a < 3; ++a) {
      EXPECT_EQ(lo[a], e.lo[a]);
      EXPECT_EQ(hi[a], e.hi[a]);
    }
    for (uint32_t t = 0; t < p.tet_count; ++t) {
      auto q = [&](int k) {
        const uint32_t w = p.corners[4 * t + uint32_t(k)];
        return Vec3d(p.positions[3 * w], p.positions[3 * w + 1], p.positions[3 * w + 2]);
      };
      volume_sum += tet_volume6(q(0), q(1), q(2), q(3)) / 6;
    }
    // Coherent: a cluster of ~100 tets of a unit lattice spans a few cells, not the mesh.
    EXPECT_LT((hi - lo).x + (hi - lo).y + (hi - lo).z, 9.0) << c;
  }
  EXPECT_EQ(sum, tets);
  EXPECT_NEAR(volume_sum, 512, 1e-9);
}

TEST(TetStore, AProceduralMeshStreamsClustersWithSharedVerticesAtTheSamePlace) {
  testing::TempDir dir;
  ProceduralMeshSpec spec;
  spec.field = "sphere";
  spec.cells = 10;
  spec.jitter = 0.2;
  spec.replicate = 2;
  spec.steps = 2;
  auto source = make_procedural_mesh(spec, 6 * 27);  // blocks of 3^3 cubes
  EXPECT_EQ(source->tet_count(), 6u * 1000 * 8);
  TetBuildOptions o;
  o.cluster_tets = 6 * 27;
  build_tet_store(*source, dir.file("p.store"), o);
  Store store(dir.file("p.store"));
  EXPECT_EQ(store.manifest().time_steps, 2);
  EXPECT_EQ(store.clusters().size(), 4u * 4 * 4 * 8);
  EXPECT_EQ(store.manifest().mesh.bounds.hi, Vec3d(2.0));
  // Every position is shared by the same set of clusters in every step: collect them all and
  // check that vertices agree where clusters meet (the same point never has two values).
  std::map<std::array<float, 3>, std::pair<float, float>> seen;
  std::vector<std::byte> page(store.manifest().mesh.page_bytes);
  auto txn = store.begin_read();
  double volume = 0;
  for (size_t c = 0; c < store.clusters().size(); ++c) {
    store.read_page(txn, {RecordKind::tet_cluster, c}, page);
    const TetClusterPage p = TetClusterPage::view(page);
    ASSERT_EQ(p.steps, 2u);
    const TetStepRange r0 = store.dataset().tets().range(c, 0), r1 = store.dataset().tets().range(c, 1);
    for (uint32_t v = 0; v < p.vertex_count; ++v) {
      const std::array<float, 3> k = {p.positions[3 * v], p.positions[3 * v + 1], p.positions[3 * v + 2]};
      const std::pair<float, float> vals = {p.values_at(0)[v], p.values_at(1)[v]};
      EXPECT_GE(vals.first, r0.min);
      EXPECT_LE(vals.second, r1.max);
      if (k[0] == 1.0f || k[1] == 1.0f || k[2] == 1.0f) continue;  // replicas meet here with their own values
      auto [it, added] = seen.try_emplace(k, vals);
      if (!added) {
        EXPECT_EQ(it->second, vals);
      }
    }
    for (uint32_t t = 0; t < p.tet_count; ++t) {
      auto q = [&](int i) {
        const uint32_t w = p.corners[4 * t + uint32_t(i)];
        return Vec3d(p.positions[3 * w], p.positions[3 * w + 1], p.positions[3 * w + 2]);
      };
      volume += tet_volume6(q(0), q(1), q(2), q(3)) / 6;
    }
  }
  EXPECT_NEAR(volume, 8.0, 1e-5);
}

TEST(TetStore, AProceduralMeshWithMovingVerticesShearsItInEveryStep) {
  testing::TempDir dir;
  ProceduralMeshSpec spec;
  spec.field = "sphere";
  spec.cells = 12;
  spec.jitter = 0.1;
  spec.steps = 3;
  spec.move = 0.05;
  auto source = make_procedural_mesh(spec, 6 * 64);
  EXPECT_TRUE(source->moving());
  TetBuildOptions o;
  o.cluster_tets = 6 * 64;
  build_tet_store(*source, dir.file("m.store"), o);
  Store store(dir.file("m.store"));
  ASSERT_TRUE(store.manifest().mesh.moving);
  std::vector<std::byte> page(store.manifest().mesh.page_bytes);
  auto txn = store.begin_read();
  double moved = 0, volume[3] = {0, 0, 0};
  for (size_t c = 0; c < store.clusters().size(); ++c) {
    store.read_page(txn, {RecordKind::tet_cluster, c}, page);
    const TetClusterPage p = TetClusterPage::view(page);
    ASSERT_EQ(p.position_sets, 3u);
    const TetCluster& e = store.clusters()[c];
    const float* p0 = p.positions_at(0);
    for (uint32_t s = 0; s < 3; ++s) {
      const float* ps = p.positions_at(s);
      for (uint32_t v = 0; v < p.vertex_count; ++v) {
        // A shear: x moves with y, y with z, z stays; the cluster's box holds every step.
        EXPECT_NEAR(ps[3 * v], p0[3 * v] + 0.05 * s * std::sin(2 * M_PI * p0[3 * v + 1]), 1e-6);
        EXPECT_EQ(ps[3 * v + 2], p0[3 * v + 2]);
        for (int a = 0; a < 3; ++a) EXPECT_TRUE(ps[3 * v + a] >= e.lo[a] && ps[3 * v + a] <= e.hi[a]);
        moved = std::max(moved, double(std::abs(ps[3 * v + 1] - p0[3 * v + 1])));
      }
      for (uint32_t t = 0; t < p.tet_count; ++t) {
        auto at = [&](int i) {
          const uint32_t w = p.corners[4 * t + uint32_t(i)];
          return Vec3d(ps[3 * w], ps[3 * w + 1], ps[3 * w + 2]);
        };
        const double v6 = tet_volume6(at(0), at(1), at(2), at(3));
        EXPECT_GT(v6, 0) << "tet " << t << " of cluster " << c << " in step " << s;
        volume[s] += v6 / 6;
      }
    }
  }
  EXPECT_GT(moved, 0.05);
  for (int s = 0; s < 3; ++s) EXPECT_NEAR(volume[s], 1.0, 2e-3) << s;  // a shear keeps the volume

  // A displacement the cells cannot follow folds tets: refused, naming the option.
  spec.cells = 4;
  spec.move = 0.3;
  auto folding = make_procedural_mesh(spec, 6 * 64);
  try {
    build_tet_store(*folding, dir.file("folded.store"), o);
    ADD_FAILURE() << "a folding motion was accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.field(), "--move") << e.what();
    EXPECT_NE(std::string(e.what()).find("folds tetrahedron"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(std::filesystem::exists(dir.file("folded.store") + "/manifest.json"));
}

TEST(TetStore, AProceduralMeshIsCutIntoBlocksOfEqualSize) {
  // Pages take fixed cache slots of the largest cluster's size: 24 cells in blocks of at most
  // 11 are three blocks of 8, not 11, 11 and a sliver of 2.
  ProceduralMeshSpec spec;
  spec.field = "sphere";
  spec.cells = 24;
  auto source = make_procedural_mesh(spec, 8192);
  ASSERT_EQ(source->cluster_count(), 27u);
  ClusterData d;
  for (uint64_t c = 0; c < source->cluster_count(); ++c) {
    source->cluster(c, d);
    EXPECT_EQ(d.corners.size(), size_t(8 * 8 * 8 * 6 * 4)) << c;
  }
}

TEST(TetStore, AnInterruptedBuildLeavesNoCompleteStore) {
  testing::TempDir dir;
  class Failing final : public TetClusterSource {
   public:
    std::string name() const override { return "failing"; }
    std::string describe_json() const override { return "{}"; }
    int time_steps() const override { return 1; }
    std::string array_name() const override { return "f"; }
    std::vector<std::string> step_names() const override { return {"f"}; }
    uint64_t cluster_count() const override { return 400; }
    uint64_t tet_count() const override { return 400; }
    uint64_t vertex_count() const override { return 1600; }
    void cluster(uint64_t i, ClusterData& out) const override {
      if (i == 300) throw Error(Errc::io, "disk gone").with_file("failing");
      out.positions = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1};
      out.values = {0, 1, 2, 3};
      out.corners = {0, 1, 2, 3};
    }
    const MeshReport& report() const override { return report_; }
    uint64_t input_bytes() const override { return 0; }

   private:
    MeshReport report_;
  } failing;
  EXPECT_THROW(build_tet_store(failing, dir.file("f.store"), {}), Error);
  EXPECT_EQ(probe_store(dir.file("f.store")), StoreState::incomplete);
  EXPECT_THROW(Store{dir.file("f.store")}, Error);
}

}  // namespace
}  // namespace brickyard
