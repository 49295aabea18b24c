// The OpenVDB importer and exporter against grids made here with OpenVDB itself: every voxel
// read back from a store must be the grid's value at the same index coordinate, and an
// exported grid must hold the original's active voxels, values, background and class.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <optional>
#include <vector>

#include <fmt/format.h>
#include <openvdb/openvdb.h>
#include <openvdb/io/File.h>
#include <openvdb/tools/LevelSetSphere.h>
#include <openvdb/tools/LevelSetUtil.h>
#include <openvdb/tools/MeshToVolume.h>
#include <openvdb/tools/ValueTransformer.h>
#include <tbb/global_control.h>

#include "core/error.h"
#include "core/math.h"
#include "fields/field.h"
#include "preprocess/builder.h"
#include "preprocess/export.h"
#include "preprocess/volume_source.h"
#include "storage/store.h"
#include "test_util.h"

namespace brickyard {
namespace {

namespace vdb = openvdb;

#if defined(__SANITIZE_THREAD__)
// OpenVDB's tools here run their loops on TBB, whose hand-offs ThreadSanitizer cannot see: keep
// TBB on the calling thread for the whole program. brickyard's own loops use std::threads under
// TSan (core/parallel.h), so they stay parallel and checked.
const tbb::global_control serial_tbb(tbb::global_control::max_allowed_parallelism, 1);
#endif

BuildOptions bricks_of(int m) {
  BuildOptions o;
  o.brick_size = m;
  return o;
}

void write_grids(const std::string& path, const vdb::GridPtrVec& grids) {
  vdb::initialize();
  vdb::io::File file(path);
  file.write(grids);
  file.close();
}

// A narrow-band level set sphere of about 20 voxels radius, off the index origin so that the
// active bounding box starts at negative coordinates.
vdb::FloatGrid::Ptr sphere(const std::string& name) {
  vdb::initialize();
  auto grid = vdb::tools::createLevelSetSphere<vdb::FloatGrid>(5.0f, vdb::Vec3f(0.3f, -0.7f, 0.45f), 0.25f, 3.0f);
  grid->transform().postTranslate(vdb::Vec3d(1.5, -2.0, 3.25));
  grid->setName(name);
  return grid;
}

// The finest level of a store, densely, x fastest.
std::vector<float> finest_voxels(const Store& store) {
  const int level = store.layout().finest();
  std::vector<float> out;
  for_each_region_slab(store, level, export_region(store, level, std::nullopt),
                       [&](int64_t, int64_t, std::span<const std::byte> bytes) {
                         const float* p = reinterpret_cast<const float*>(bytes.data());
                         out.insert(out.end(), p, p + bytes.size() / sizeof(float));
                       });
  return out;
}

// Every voxel of the store's finest level against the grid at index_min + voxel.
template <typename GridT>
void expect_store_holds_grid(const Store& store, const GridT& grid) {
  const vdb::CoordBBox bbox = grid.evalActiveVoxelBoundingBox();
  const Vec3s d = store.manifest().dims;
  ASSERT_EQ(d, Vec3s(bbox.dim().x(), bbox.dim().y(), bbox.dim().z()));
  const std::vector<float> got = finest_voxels(store);
  ASSERT_EQ(got.size(), size_t(volume(d)));
  auto acc = grid.getConstAccessor();
  size_t i = 0;
  for (int64_t z = 0; z < d.z; ++z)
    for (int64_t y = 0; y < d.y; ++y)
      for (int64_t x = 0; x < d.x; ++x, ++i) {
        const vdb::Coord ijk = bbox.min() + vdb::Coord(int32_t(x), int32_t(y), int32_t(z));
        ASSERT_EQ(got[i], float(acc.getValue(ijk))) << "voxel (" << x << ", " << y << ", " << z << ")";
      }
}

template <typename F>
Error error_of(F&& f) {
  try {
    f();
  } catch (const Error& e) {
    return e;
  }
  ADD_FAILURE() << "no brickyard::Error thrown";
  return Error(Errc::internal, "nothing thrown");
}

bool contains(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

TEST(VdbImport, FogVolumeVoxelsMatchTheGridExactly) {
  testing::TempDir dir;
  auto grid = sphere("density");
  vdb::tools::sdfToFogVolume(*grid);
  ASSERT_EQ(grid->getGridClass(), vdb::GRID_FOG_VOLUME);
  write_grids(dir.file("fog.vdb"), {grid});

  ASSERT_TRUE(vdb_support());
  auto source = open_vdb_source(dir.file("fog.vdb"), "");  // the only grid
  const vdb::CoordBBox bbox = grid->evalActiveVoxelBoundingBox();
  EXPECT_EQ(source->type(), ValueType::f32);
  EXPECT_EQ(source->spacing(), Vec3d(0.25));
  const vdb::Vec3d o = grid->indexToWorld(bbox.min());
  EXPECT_EQ(source->origin(), Vec3d(o.x(), o.y(), o.z()));
  EXPECT_EQ(source->background(), 0.0);
  EXPECT_EQ(source->input_bytes(), std::filesystem::file_size(dir.file("fog.vdb")));
  const auto range = source->value_range_hint();
  ASSERT_TRUE(range);
  EXPECT_EQ(range->lo, 0.0);
  EXPECT_EQ(range->hi, 1.0);  // sdfToFogVolume saturates the inside at 1

  const BuildResult built = build_store(*source, dir.file("store"), bricks_of(16));
  EXPECT_GT(built.manifest.stats.back().empty, 0) << "the corners of the box are background";
  Store store(dir.file("store"));
  EXPECT_EQ(store.manifest().origin, source->origin());
  expect_store_holds_grid(store, *grid);

  const std::string json = store.manifest().source;
  EXPECT_TRUE(contains(json, "\"kind\":\"vdb\"")) << json;
  EXPECT_TRUE(contains(json, "\"grid\":\"density\"")) << json;
  EXPECT_TRUE(contains(json, "\"grid_class\":\"fog_volume\"")) << json;
  EXPECT_TRUE(contains(json, "\"value_type\":\"float\"")) << json;
  EXPECT_TRUE(contains(json, fmt::format("\"index_min\":[{},{},{}]", bbox.min().x(), bbox.min().y(), bbox.min().z())))
      << json;
}

TEST(VdbImport, ActiveTilesBecomeConstantNodesWithoutRecords) {
  testing::TempDir dir;
  vdb::initialize();
  auto grid = vdb::FloatGrid::create(0.0f);
  grid->setName("tiles");
  grid->tree().fill(vdb::CoordBBox(vdb::Coord(0), vdb::Coord(63)), 2.5f, true);
  ASSERT_GT(grid->tree().activeTileCount(), 0u) << "the fill must make tiles for this test to mean anything";
  auto acc = grid->getAccessor();
  acc.setValue(vdb::Coord(-20, -20, -20), 1.0f);
  acc.setValue(vdb::Coord(90, 70, 80), -3.0f);
  write_grids(dir.file("tiles.vdb"), {grid});

  auto source = open_vdb_source(dir.file("tiles.vdb"), "tiles");
  build_store(*source, dir.file("store"), bricks_of(16));
  Store store(dir.file("store"));
  expect_store_holds_grid(store, *grid);

  // Which finest bricks must be constant follows from the grid: every voxel of the brick and
  // its apron (replicated at the volume's faces) has one value.
  const GridLayout& layout = store.layout();
  const int level = layout.finest();
  const Vec3s d = layout.dims, nb = layout.level_bricks(level);
  const vdb::Coord index_min = grid->evalActiveVoxelBoundingBox().min();
  const int64_t M = store.format().brick_size, A = store.format().apron;
  auto txn = store.begin_read();
  int tile_bricks = 0, empty_bricks = 0;
  for (int64_t bz = 0; bz < nb.z; ++bz)
    for (int64_t by = 0; by < nb.y; ++by)
      for (int64_t bx = 0; bx < nb.x; ++bx) {
        std::optional<float> uniform;
        bool constant = true;
        for (int64_t z = bz * M - A; z < (bz + 1) * M + A && constant; ++z)
          for (int64_t y = by * M - A; y < (by + 1) * M + A && constant; ++y)
            for (int64_t x = bx * M - A; x < (bx + 1) * M + A && constant; ++x) {
              const vdb::Coord ijk = index_min + vdb::Coord(int32_t(std::clamp<int64_t>(x, 0, d.x - 1)),
                                                            int32_t(std::clamp<int64_t>(y, 0, d.y - 1)),
                                                            int32_t(std::clamp<int64_t>(z, 0, d.z - 1)));
              const float v = acc.getValue(ijk);
              if (!uniform) uniform = v;
              constant = *uniform == v;
            }
        const BrickKey key{uint32_t(level), uint32_t(bx), uint32_t(by), uint32_t(bz)};
        const NodeRecord& node = store.nodes().at(key);
        ASSERT_EQ(node.is_constant(), constant) << "brick " << bx << "," << by << "," << bz;
        ASSERT_EQ(store.record(txn, key).has_value(), !constant);
        if (!constant) continue;
        EXPECT_EQ(node.constant, *uniform);
        EXPECT_EQ(node.is_empty(), *uniform == 0.0f);
        tile_bricks += *uniform == 2.5f;
        empty_bricks += node.is_empty();
      }
  // The tile spans index 0..63, store voxels 20..83: bricks 2 to 4 (31..80 with aprons) lie
  // inside it along each axis.
  EXPECT_EQ(tile_bricks, 27);
  EXPECT_GT(empty_bricks, 0);

  // And back: constant bricks become tiles again, and the same voxels are active.
  export_vdb(store, level, export_region(store, level, std::nullopt), dir.file("out.vdb"), "");
  vdb::io::File file(dir.file("out.vdb"));
  file.open();
  auto out = vdb::gridPtrCast<vdb::FloatGrid>(file.readGrid("tiles"));
  ASSERT_TRUE(out);
  EXPECT_GT(out->tree().activeTileCount(), 0u);
  EXPECT_EQ(out->activeVoxelCount(), grid->activeVoxelCount());
  EXPECT_EQ(out->getGridClass(), vdb::GRID_UNKNOWN);
  for (auto it = grid->cbeginValueOn(); it; ++it) {
    vdb::CoordBBox box;
    it.getBoundingBox(box);
    for (const vdb::Coord& ijk : {box.min(), box.max()}) {
      ASSERT_TRUE(out->tree().isValueOn(ijk)) << ijk;
      ASSERT_EQ(out->tree().getValue(ijk), *it) << ijk;
    }
  }

  // A box of the level keeps its voxels where they were and nothing else.
  const VoxelBox box{{25, 30, 10}, {70, 91, 90}};
  export_vdb(store, level, export_region(store, level, box), dir.file("box.vdb"), "part");
  vdb::io::File box_file(dir.file("box.vdb"));
  box_file.open();
  auto part = vdb::gridPtrCast<vdb::FloatGrid>(box_file.readGrid("part"));
  ASSERT_TRUE(part);
  const vdb::CoordBBox index_box(index_min + vdb::Coord(25, 30, 10), index_min + vdb::Coord(69, 90, 89));
  EXPECT_TRUE(index_box.isInside(part->evalActiveVoxelBoundingBox())) << part->evalActiveVoxelBoundingBox();
  auto part_acc = part->getConstAccessor();
  vdb::Index64 inside = 0;
  for (auto ijk = index_box.beginZYX(); ijk; ++ijk) {
    ASSERT_EQ(part_acc.getValue(*ijk), acc.getValue(*ijk)) << *ijk;
    ASSERT_EQ(part_acc.isValueOn(*ijk), acc.isValueOn(*ijk)) << *ijk;
    inside += acc.isValueOn(*ijk);
  }
  EXPECT_EQ(part->activeVoxelCount(), inside);
}

TEST(VdbExport, LevelSetRoundTripKeepsActiveVoxelsBackgroundAndClass) {
  testing::TempDir dir;
  auto grid = sphere("ls");
  const float bg = grid->background();
  ASSERT_EQ(bg, 0.75f);
  write_grids(dir.file("ls.vdb"), {grid});
  auto source = open_vdb_source(dir.file("ls.vdb"), "ls");
  EXPECT_EQ(source->background(), 0.75);
  build_store(*source, dir.file("store"), bricks_of(16));
  Store store(dir.file("store"));
  EXPECT_TRUE(contains(store.manifest().source, "\"grid_class\":\"level_set\""));
  const int finest = store.layout().finest();
  export_vdb(store, finest, export_region(store, finest, std::nullopt), dir.file("out.vdb"), "");
  EXPECT_FALSE(std::filesystem::exists(dir.file("out.vdb.partial")));

  vdb::io::File file(dir.file("out.vdb"));
  file.open();
  auto out = vdb::gridPtrCast<vdb::FloatGrid>(file.readGrid("ls"));  // the source grid's name
  ASSERT_TRUE(out);
  EXPECT_EQ(out->background(), bg);
  EXPECT_EQ(out->getGridClass(), vdb::GRID_LEVEL_SET);
  EXPECT_EQ(out->activeVoxelCount(), grid->activeVoxelCount());
  auto acc = out->getConstAccessor();
  for (auto it = grid->cbeginValueOn(); it; ++it) {
    ASSERT_TRUE(acc.isValueOn(it.getCoord())) << it.getCoord();
    ASSERT_EQ(acc.getValue(it.getCoord()), *it) << it.getCoord();
  }
  // The inside is inactive at -background, as in the original, and stored as tiles.
  const vdb::Coord centre(1, -3, 2);  // the sphere's centre, (0.3, -0.7, 0.45) / 0.25, rounded
  ASSERT_FALSE(grid->tree().isValueOn(centre));
  ASSERT_EQ(grid->tree().getValue(centre), -bg);
  EXPECT_FALSE(acc.isValueOn(centre));
  EXPECT_EQ(acc.getValue(centre), -bg);
  EXPECT_LT(out->tree().leafCount(), grid->tree().leafCount() + 8);
  // Same index coordinates, same world positions.
  for (const vdb::Coord& ijk : {vdb::Coord(0), vdb::Coord(-17, 4, 9), vdb::Coord(25, -3, 11)}) {
    const vdb::Vec3d a = grid->indexToWorld(ijk), b = out->indexToWorld(ijk);
    EXPECT_NEAR((a - b).length(), 0.0, 1e-9) << ijk;
  }

  // A coarser level: voxel i is the minimum of the finest voxels 2i and 2i+1 along each axis
  // (a level set's default, which keeps its zero crossing), placed at their centre; index
  // coordinates are the source's halved.
  const int coarse = finest - 1;
  export_vdb(store, coarse, export_region(store, coarse, std::nullopt), dir.file("coarse.vdb"), "half");
  vdb::io::File coarse_file(dir.file("coarse.vdb"));
  coarse_file.open();
  auto half = vdb::gridPtrCast<vdb::FloatGrid>(coarse_file.readGrid("half"));
  ASSERT_TRUE(half);
  EXPECT_EQ(half->getGridClass(), vdb::GRID_LEVEL_SET);
  EXPECT_DOUBLE_EQ(half->voxelSize().x(), 0.5);
  const vdb::Coord index_min = grid->evalActiveVoxelBoundingBox().min();
  const vdb::Coord half_min(index_min.x() >> 1, index_min.y() >> 1, index_min.z() >> 1);
  const Vec3s cd = store.layout().level_dims(coarse), fd = store.layout().dims;
  auto fine = grid->getConstAccessor();
  auto coarse_acc = half->getConstAccessor();
  int active = 0;
  for (int64_t z = 0; z < cd.z; ++z)
    for (int64_t y = 0; y < cd.y; ++y)
      for (int64_t x = 0; x < cd.x; ++x) {
        float v[8];
        int n = 0;
        for (int dz = 0; dz < 2; ++dz)
          for (int dy = 0; dy < 2; ++dy)
            for (int dx = 0; dx < 2; ++dx)
              v[n++] = fine.getValue(index_min + vdb::Coord(int32_t(std::min(2 * x + dx, fd.x - 1)),
                                                            int32_t(std::min(2 * y + dy, fd.y - 1)),
                                                            int32_t(std::min(2 * z + dz, fd.z - 1))));
        const float least = *std::min_element(v, v + 8);
        const vdb::Coord ijk = half_min + vdb::Coord(int32_t(x), int32_t(y), int32_t(z));
        ASSERT_EQ(coarse_acc.getValue(ijk), least) << ijk;
        ASSERT_EQ(coarse_acc.isValueOn(ijk), std::abs(coarse_acc.getValue(ijk)) != bg) << ijk;
        active += coarse_acc.isValueOn(ijk);
        if (2 * x + 1 < fd.x && 2 * y + 1 < fd.y && 2 * z + 1 < fd.z) {
          const vdb::Vec3d centre_fine = grid->indexToWorld(vdb::Vec3d(index_min.x() + 2 * x + 0.5,
                                                                       index_min.y() + 2 * y + 0.5,
                                                                       index_min.z() + 2 * z + 0.5));
          ASSERT_NEAR((half->indexToWorld(ijk) - centre_fine).length(), 0.0, 1e-9) << ijk;
        }
      }
  EXPECT_GT(active, 0);
}

// A one-voxel-thick open shell made a level set with OpenVDB's own tools: the unsigned
// distance to a hemisphere's triangles (meshToUnsignedDistanceField), less half a voxel, so
// that the inside is the voxels within half a voxel of the surface.
vdb::FloatGrid::Ptr thin_open_shell(double radius_voxels) {
  vdb::initialize();
  std::vector<vdb::Vec3s> points;
  std::vector<vdb::Vec3I> triangles;
  const int rings = 24, sectors = 48;
  for (int i = 0; i <= rings; ++i)  // from the pole (i = 0) to the rim (i = rings), at z >= 0
    for (int j = 0; j < sectors; ++j) {
      const double theta = 0.5 * kPi * i / rings, phi = 2 * kPi * j / sectors;
      points.emplace_back(float(radius_voxels * std::sin(theta) * std::cos(phi)),
                          float(radius_voxels * std::sin(theta) * std::sin(phi)), float(radius_voxels * std::cos(theta)));
    }
  for (int i = 0; i < rings; ++i)
    for (int j = 0; j < sectors; ++j) {
      const unsigned a = unsigned(i * sectors + j), b = unsigned(i * sectors + (j + 1) % sectors);
      triangles.emplace_back(a, b, a + sectors);
      triangles.emplace_back(b, b + sectors, a + sectors);
    }
  const auto xform = vdb::math::Transform::createLinearTransform(1.0);
  auto grid = vdb::tools::meshToUnsignedDistanceField<vdb::FloatGrid>(*xform, points, triangles, {}, 3.0f);
  vdb::tools::foreach (grid->beginValueAll(), [](const vdb::FloatGrid::ValueAllIter& it) { it.setValue(*it - 0.5f); });
  grid->tree().root().setBackground(grid->background() - 0.5f, true);
  grid->setGridClass(vdb::GRID_LEVEL_SET);
  grid->setName("shell");
  return grid;
}

TEST(VdbImport, LevelSetsKeepThinPartsAtCoarserLevels) {
  testing::TempDir dir;
  auto grid = thin_open_shell(24.0);
  write_grids(dir.file("shell.vdb"), {grid});
  auto source = open_vdb_source(dir.file("shell.vdb"), "");
  EXPECT_TRUE(source->is_level_set());
  build_store(*source, dir.file("min.store"), bricks_of(16));  // the default for a level set: min
  BuildOptions averaged = bricks_of(16);
  averaged.downsample = Downsample::average;
  build_store(*open_vdb_source(dir.file("shell.vdb"), ""), dir.file("avg.store"), averaged);
  Store min(dir.file("min.store")), avg(dir.file("avg.store"));
  EXPECT_TRUE(contains(min.manifest().build, "\"downsample\":\"min\"")) << min.manifest().build;
  EXPECT_TRUE(contains(min.manifest().build, "\"level_set\":true")) << min.manifest().build;
  EXPECT_TRUE(contains(avg.manifest().build, "\"downsample\":\"average\"")) << avg.manifest().build;
  // The finest levels are the grid itself; the next two keep the shell under min and lose most
  // of it under averaging. The shell's area, 2 pi r^2 in voxels of a level, bounds what a
  // one-voxel layer holds from below.
  expect_store_holds_grid(min, *grid);
  for (int step = 1; step <= 2; ++step) {
    const int level = min.layout().finest() - step;
    auto inside = [&](const Store& s) {
      int64_t n = 0;
      for_each_region_slab(s, level, export_region(s, level, std::nullopt), [&](int64_t, int64_t, std::span<const std::byte> b) {
        const float* p = reinterpret_cast<const float*>(b.data());
        for (size_t i = 0; i < b.size() / sizeof(float); ++i) n += p[i] < 0;
      });
      return n;
    };
    const double r = 24.0 / double(1 << step);
    EXPECT_GT(double(inside(min)), 0.9 * 2 * kPi * r * r) << "level " << level;
    EXPECT_LT(double(inside(avg)), 0.5 * double(inside(min))) << "level " << level;
  }
}

TEST(VdbImport, DoubleAndInt32GridsConvertToFloat) {
  testing::TempDir dir;
  vdb::initialize();
  auto dgrid = vdb::DoubleGrid::create(0.1);
  dgrid->setName("d");
  auto dacc = dgrid->getAccessor();
  for (int i = 0; i < 40; ++i) dacc.setValue(vdb::Coord(i, (i * 7) % 13, -(i % 5)), 1.0 / (i + 3) + 1e-12 * i);
  dgrid->tree().fill(vdb::CoordBBox(vdb::Coord(8, 0, -4), vdb::Coord(15, 7, 3)), 2.0 / 3.0, true);
  auto igrid = vdb::Int32Grid::create(-7);
  igrid->setName("i");
  auto iacc = igrid->getAccessor();
  const int32_t big = (1 << 24) + 1;  // not a float: becomes 2^24
  for (int i = 0; i < 30; ++i) iacc.setValue(vdb::Coord(3 * i, i % 4, 2), i * 1001 - 12345);
  iacc.setValue(vdb::Coord(5, 9, 1), big);
  write_grids(dir.file("mixed.vdb"), {dgrid, igrid});

  auto dsrc = open_vdb_source(dir.file("mixed.vdb"), "d");
  EXPECT_EQ(dsrc->background(), double(0.1f));  // as stored in f32, so empty bricks are found
  EXPECT_TRUE(dsrc->may_contain_nonfinite());
  build_store(*dsrc, dir.file("d"), bricks_of(8));
  Store dstore(dir.file("d"));
  expect_store_holds_grid(dstore, *dgrid);
  EXPECT_TRUE(contains(dstore.manifest().source, "\"value_type\":\"double\""));

  auto isrc = open_vdb_source(dir.file("mixed.vdb"), "i");
  EXPECT_FALSE(isrc->may_contain_nonfinite());
  const auto range = isrc->value_range_hint();
  ASSERT_TRUE(range);
  EXPECT_EQ(range->lo, -12345.0);
  EXPECT_EQ(range->hi, double(1 << 24));
  build_store(*isrc, dir.file("i"), bricks_of(8));
  Store istore(dir.file("i"));
  expect_store_holds_grid(istore, *igrid);
  EXPECT_EQ(istore.manifest().max_value, double(1 << 24));
  EXPECT_EQ(istore.manifest().background, -7.0);
}

TEST(VdbExport, StoresFromOtherSourcesExportAsDensityAtVoxelCoordinates) {
  testing::TempDir dir;
  const Vec3s dims{21, 14, 9};
  auto source = make_field_source(make_field("gyroid"), dims, ValueType::u8);
  build_store(*source, dir.file("store"), bricks_of(8));
  Store store(dir.file("store"));
  const int level = store.layout().finest();
  const VoxelBox all = export_region(store, level, std::nullopt);
  std::vector<uint8_t> voxels;
  for_each_region_slab(store, level, all, [&](int64_t, int64_t, std::span<const std::byte> bytes) {
    const uint8_t* p = reinterpret_cast<const uint8_t*>(bytes.data());
    voxels.insert(voxels.end(), p, p + bytes.size());
  });
  export_vdb(store, level, all, dir.file("out.vdb"), "");

  vdb::io::File file(dir.file("out.vdb"));
  file.open();
  auto out = vdb::gridPtrCast<vdb::FloatGrid>(file.readGrid("density"));
  ASSERT_TRUE(out);
  EXPECT_EQ(out->getGridClass(), vdb::GRID_UNKNOWN);
  EXPECT_EQ(out->background(), 0.0f);
  auto acc = out->getConstAccessor();
  size_t i = 0, zeros = 0;
  for (int32_t z = 0; z < dims.z; ++z)
    for (int32_t y = 0; y < dims.y; ++y)
      for (int32_t x = 0; x < dims.x; ++x, ++i) {
        const vdb::Coord ijk(x, y, z);
        ASSERT_EQ(acc.getValue(ijk), float(voxels[i])) << ijk;
        ASSERT_EQ(acc.isValueOn(ijk), voxels[i] != 0) << ijk;
        zeros += voxels[i] == 0;
      }
  EXPECT_EQ(out->activeVoxelCount(), voxels.size() - zeros);
  const Manifest& m = store.manifest();
  const vdb::Vec3d p = out->indexToWorld(vdb::Coord(20, 13, 8));
  EXPECT_NEAR(p.x(), m.origin.x + 20 * m.spacing.x, 1e-12);
  EXPECT_NEAR(p.y(), m.origin.y + 13 * m.spacing.y, 1e-12);
  EXPECT_NEAR(p.z(), m.origin.z + 8 * m.spacing.z, 1e-12);
}

TEST(VdbImport, ErrorsNameTheFileOrGrid) {
  testing::TempDir dir;
  const std::string missing = dir.file("missing.vdb");
  Error e = error_of([&] { open_vdb_source(missing, ""); });
  EXPECT_EQ(e.code(), Errc::io);
  EXPECT_EQ(e.file(), missing);

  const std::string text = dir.file("text.vdb");
  std::ofstream(text) << "this is not a VDB file, only text with the extension of one\n";
  e = error_of([&] { open_vdb_source(text, ""); });
  EXPECT_EQ(e.code(), Errc::format);
  EXPECT_EQ(e.file(), text);

  vdb::initialize();
  auto a = vdb::FloatGrid::create(0.0f), b = vdb::FloatGrid::create(0.0f);
  a->setName("alpha");
  b->setName("beta");
  a->tree().setValue(vdb::Coord(1, 2, 3), 1.0f);
  b->tree().setValue(vdb::Coord(1, 2, 3), 2.0f);
  auto nothing = vdb::FloatGrid::create(0.0f);
  nothing->setName("nothing");
  nothing->tree().setValueOff(vdb::Coord(4, 4, 4), 9.0f);
  auto v = vdb::Vec3SGrid::create();
  v->setName("velocity");
  v->tree().setValue(vdb::Coord(0), vdb::Vec3s(1, 2, 3));
  const std::string two = dir.file("two.vdb");
  write_grids(two, {a, b, nothing, v});

  e = error_of([&] { open_vdb_source(two, "gamma"); });
  EXPECT_EQ(e.code(), Errc::not_found);
  EXPECT_EQ(e.file(), two);
  for (const char* name : {"'gamma'", "'alpha'", "'beta'", "'velocity'"}) EXPECT_TRUE(contains(e.message(), name)) << e.what();

  e = error_of([&] { open_vdb_source(two, ""); });
  EXPECT_EQ(e.code(), Errc::invalid_argument);
  EXPECT_TRUE(contains(e.message(), "'alpha'") && contains(e.message(), "'beta'")) << e.what();

  e = error_of([&] { open_vdb_source(two, "velocity"); });
  EXPECT_EQ(e.code(), Errc::unsupported);
  EXPECT_EQ(e.file(), two);
  EXPECT_TRUE(contains(e.message(), "'velocity'") && contains(e.message(), "vec3s")) << e.what();

  e = error_of([&] { open_vdb_source(two, "nothing"); });
  EXPECT_EQ(e.code(), Errc::invalid_argument);
  EXPECT_TRUE(contains(e.message(), "'nothing'") && contains(e.message(), "no active voxels")) << e.what();

  EXPECT_EQ(open_vdb_source(two, "beta")->dims(), Vec3s(1));
}

TEST(VdbExport, ErrorsLeaveNoFileBehind) {
  testing::TempDir dir;
  auto grid = sphere("ls");
  write_grids(dir.file("ls.vdb"), {grid});
  auto source = open_vdb_source(dir.file("ls.vdb"), "");
  build_store(*source, dir.file("store"), bricks_of(16));
  Store store(dir.file("store"));
  const int levels = store.layout().levels;

  Error e = error_of([&] { export_region(store, levels, std::nullopt); });
  EXPECT_EQ(e.code(), Errc::invalid_argument);
  EXPECT_EQ(e.field(), "--level");
  const std::string out = dir.file("out.vdb");
  e = error_of([&] { export_vdb(store, levels, VoxelBox{Vec3s(0), Vec3s(4)}, out, ""); });
  EXPECT_EQ(e.code(), Errc::invalid_argument);
  e = error_of([&] { export_vdb(store, 0, VoxelBox{Vec3s(0), Vec3s(1000)}, out, ""); });
  EXPECT_EQ(e.code(), Errc::invalid_argument);
  EXPECT_EQ(e.field(), "--box");
  EXPECT_FALSE(std::filesystem::exists(out));

  const std::string unwritable = dir.file("no/such/dir/out.vdb");
  e = error_of([&] { export_vdb(store, 0, export_region(store, 0, std::nullopt), unwritable, ""); });
  EXPECT_EQ(e.code(), Errc::io);
  EXPECT_EQ(e.file(), unwritable);
  EXPECT_FALSE(std::filesystem::exists(unwritable + ".partial"));

  // The grid is written, then cannot be moved over a directory: the partial file goes too.
  const std::string taken = dir.file("taken.vdb");
  std::filesystem::create_directories(std::filesystem::path(taken) / "inside");
  e = error_of([&] { export_vdb(store, 0, export_region(store, 0, std::nullopt), taken, ""); });
  EXPECT_EQ(e.code(), Errc::io);
  EXPECT_EQ(e.file(), taken);
  EXPECT_TRUE(std::filesystem::is_directory(taken));
  EXPECT_FALSE(std::filesystem::exists(taken + ".partial"));
}

}  // namespace
}  // namespace brickyard
