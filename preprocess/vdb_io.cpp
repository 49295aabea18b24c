// OpenVDB grids as builder sources, and store levels written back as OpenVDB grids. The only
// library file that includes OpenVDB: its headers are slow to compile and drag in Boost and
// Imath, none of which other layers should see.
//
// Index space: a grid's active voxel bounding box becomes the store's volume, so store voxel
// v of the finest level is VDB index coordinate index_min + v. The source's describe_json()
// records index_min (and the grid's name and class) in the manifest, which is how export_vdb
// puts voxels back at their original index coordinates.

#include <sys/stat.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <limits>
#include <memory>
#include <mutex>
#include <new>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <openvdb/openvdb.h>
#include <openvdb/io/File.h>
#include <openvdb/tools/Dense.h>
#include <openvdb/tools/Prune.h>
#include <tbb/global_control.h>

#include "core/atomic_file.h"
#include "core/error.h"
#include "core/parallel.h"
#include "core/progress.h"
#include "preprocess/export.h"
#include "preprocess/volume_source.h"
#include "storage/store.h"

namespace brickyard {
namespace {

namespace vdb = openvdb;

using SupportedGrids = vdb::TypeList<vdb::FloatGrid, vdb::DoubleGrid, vdb::Int32Grid>;
using LeafT = vdb::FloatTree::LeafNodeType;

// OpenVDB runs its own loops on TBB (reading, pruning, the statistics it writes with a grid),
// and ThreadSanitizer cannot see TBB's hand-offs (see core/parallel.h). Under TSan, OpenVDB's
// calls are made inside this guard, which keeps TBB on the calling thread; brickyard's own loops
// here go through brickyard::parallel_for and stay parallel, so TSan still checks them.
class OpenVdbCall {
#if defined(__SANITIZE_THREAD__)
  tbb::global_control serial_{tbb::global_control::max_allowed_parallelism, 1};
#endif
};

void initialize_openvdb() {
  static std::once_flag once;
  std::call_once(once, [] { vdb::initialize(); });
}

int64_t floor_div(int64_t a, int64_t b) { return a / b - ((a % b != 0) && ((a < 0) != (b < 0))); }

std::string_view class_name(vdb::GridClass c) {
  switch (c) {
    case vdb::GRID_LEVEL_SET: return "level_set";
    case vdb::GRID_FOG_VOLUME: return "fog_volume";
    default: return "unknown";
  }
}

std::string quoted_list(const std::vector<std::string>& names) {
  if (names.empty()) return "none";
  std::string s;
  for (const auto& n : names) s += (s.empty() ? "'" : ", '") + n + "'";
  return s;
}

struct FileStat {
  uint64_t bytes = 0;
  int64_t mtime_ns = 0;
};

// OpenVDB reports a missing file and a file of the wrong kind with the same exception, so ask
// the operating system first: that is what tells Errc::io from Errc::format.
FileStat stat_input(const std::string& path) {
  check_readable_file(path);
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) throw Error(Errc::io, fmt::format("cannot open: {}", std::strerror(errno))).with_file(path);
  struct stat st {};
  const int rc = ::fstat(::fileno(f), &st);
  const int err = errno;
  std::fclose(f);
  if (rc != 0) throw Error(Errc::io, fmt::format("cannot stat: {}", std::strerror(err))).with_file(path);
  if (S_ISDIR(st.st_mode)) throw Error(Errc::io, "is a directory, not an OpenVDB file").with_file(path);
  return {uint64_t(st.st_size), int64_t(st.st_mtim.tv_sec) * 1000000000 + st.st_mtim.tv_nsec};
}

// ---------------------------------------------------------------------------------------------
// Import.

// One float, double or int32 grid, delivered as dense f32 slabs of its active bounding box.
// Doubles are rounded to float, and int32 values beyond 2^24 lose their low bits: the store's
// value types are u8, u16 and f32.
class VdbSource final : public VolumeSource {
 public:
  VdbSource(std::string path, vdb::GridBase::Ptr grid, const FileStat& file)
      : path_(std::move(path)), grid_(std::move(grid)), file_(file) {
    bbox_ = grid_->evalActiveVoxelBoundingBox();
    if (bbox_.empty())
      throw Error(Errc::invalid_argument, fmt::format("grid '{}' has no active voxels: nothing to import", grid_->getName()))
          .with_file(path_)
          .with_field("--grid");
    const vdb::math::Transform& xf = grid_->transform();
    // brickyard stores axis-aligned grids with per-axis spacing: a scale and a translation.
    bool axis_aligned = xf.isLinear();
    if (axis_aligned) {
      const vdb::Mat4d m = xf.baseMap()->getAffineMap()->getMat4();
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
          if (i == j ? !(m(i, j) > 0) : std::abs(m(i, j)) > 1e-9 * std::abs(m(j, j))) axis_aligned = false;
    }
    if (!axis_aligned)
      throw Error(Errc::unsupported,
                  fmt::format("grid '{}' has a rotated, sheared, mirrored or non-linear transform ({}); brickyard "
                              "imports axis-aligned grids with positive voxel sizes",
                              grid_->getName(), xf.mapType()))
          .with_file(path_);
    const vdb::Vec3d vs = xf.voxelSize();
    spacing_ = {vs.x(), vs.y(), vs.z()};
    const vdb::Vec3d o = xf.indexToWorld(bbox_.min());
    origin_ = {o.x(), o.y(), o.z()};
    grid_->apply<SupportedGrids>([&](const auto& g) {
      using ValueT = typename std::decay_t<decltype(g)>::ValueType;
      // As stored: the builder compares f32 voxels with it to flag empty bricks.
      background_ = double(float(g.background()));
      value_type_ = std::is_same_v<ValueT, float> ? "float" : std::is_same_v<ValueT, double> ? "double" : "int32";
      floating_ = std::is_floating_point_v<ValueT>;
    });
  }

  std::string name() const override { return path_; }
  Vec3s dims() const override {
    const vdb::Coord d = bbox_.dim();
    return {d.x(), d.y(), d.z()};
  }
  ValueType type() const override { return ValueType::f32; }
  Vec3d spacing() const override { return spacing_; }
  Vec3d origin() const override { return origin_; }
  double background() const override { return background_; }
  bool is_level_set() const override { return grid_->getGridClass() == vdb::GRID_LEVEL_SET; }
  bool may_contain_nonfinite() const override { return floating_; }
  uint64_t input_bytes() const override { return file_.bytes; }

  std::optional<ValueRange> value_range_hint() const override {
    std::call_once(range_once_, [this] { range_ = compute_range(); });
    return range_;
  }

  void read_slab(int64_t z0, int64_t z1, std::span<std::byte> out) override {
    const vdb::Coord lo = bbox_.min(), hi = bbox_.max();
    const int64_t nx = bbox_.dim().x(), ny = bbox_.dim().y();
    BY_CHECK_EQ(out.size(), size_t((z1 - z0) * nx * ny) * sizeof(float));
    if (z1 <= z0) return;
    const vdb::CoordBBox slab(vdb::Coord(lo.x(), lo.y(), lo.z() + int32_t(z0)),
                              vdb::Coord(hi.x(), hi.y(), lo.z() + int32_t(z1) - 1));
    // Dense wraps `out` without copying; LayoutXYZ is x fastest, the builder's order.
    vdb::tools::Dense<float, vdb::tools::LayoutXYZ> dense(slab, reinterpret_cast<float*>(out.data()));
    // Bands of whole leaf rows in y, so that each leaf node is visited by one task; tiles and
    // background come out of RootNode::copyToDense as fills.
    const int32_t y_base = lo.y() & ~int32_t(LeafT::DIM - 1);
    const int64_t bands = (hi.y() - y_base) / int32_t(LeafT::DIM) + 1;
    const int64_t band_voxels = nx * int64_t(LeafT::DIM) * (z1 - z0);
    grid_->apply<SupportedGrids>([&](const auto& g) {
      parallel_for<int64_t>(0, bands, std::max<int64_t>(1, (int64_t(1) << 16) / band_voxels), [&](int64_t b0, int64_t b1) {
        for (int64_t b = b0; b < b1; ++b) {
          vdb::CoordBBox band = slab;
          band.min().y() = std::max(lo.y(), y_base + int32_t(b * LeafT::DIM));
          band.max().y() = std::min(hi.y(), y_base + int32_t((b + 1) * LeafT::DIM) - 1);
          g.tree().root().copyToDense(band, dense);
        }
      });
    });
  }

  std::string describe_json() const override {
    const vdb::Coord m = bbox_.min();
    nlohmann::json j = {{"kind", "vdb"},
                        {"path", path_},
                        {"bytes", file_.bytes},
                        {"mtime_ns", file_.mtime_ns},
                        {"grid", grid_->getName()},
                        {"grid_class", std::string(class_name(grid_->getGridClass()))},
                        {"value_type", value_type_},
                        {"index_min", {m.x(), m.y(), m.z()}},
                        {"background", background_}};
    return j.dump();
  }

 private:
  // Every value the bounding box can hold: leaf voxels (inactive ones too: a level set's inside
  // is inactive at -background), tile values and the background; non-finite values are left to
  // the builder's scan.
  std::optional<ValueRange> compute_range() const {
    double lo = background_, hi = background_;
    grid_->apply<SupportedGrids>([&](const auto& g) {
      using TreeT = typename std::decay_t<decltype(g)>::TreeType;
      auto include = [](double v, double& l, double& h) {
        if (std::isfinite(v)) {
          l = std::min(l, v);
          h = std::max(h, v);
        }
      };
      typename TreeT::ValueAllCIter tiles = g.tree().cbeginValueAll();
      tiles.setMaxDepth(TreeT::ValueAllCIter::LEAF_DEPTH - 1);
      for (; tiles; ++tiles) include(double(float(*tiles)), lo, hi);
      std::vector<const typename TreeT::LeafNodeType*> leaves;
      leaves.reserve(g.tree().leafCount());
      for (auto it = g.tree().cbeginLeaf(); it; ++it) leaves.push_back(&*it);
      std::mutex mutex;  // guards lo and hi from here on
      const double tiles_lo = lo, tiles_hi = hi;
      parallel_for<size_t>(0, leaves.size(), 64, [&](size_t i0, size_t i1) {
        double l = tiles_lo, h = tiles_hi;
        for (size_t i = i0; i < i1; ++i)
          for (auto v = leaves[i]->cbeginValueAll(); v; ++v) include(double(float(*v)), l, h);
        std::lock_guard lock(mutex);
        lo = std::min(lo, l);
        hi = std::max(hi, h);
      });
    });
    return ValueRange{lo, hi};
  }

  std::string path_;
  vdb::GridBase::Ptr grid_;
  FileStat file_;
  vdb::CoordBBox bbox_;
  Vec3d spacing_{1.0}, origin_{0.0};
  double background_ = 0;
  std::string value_type_;
  bool floating_ = true;
  mutable std::once_flag range_once_;
  mutable std::optional<ValueRange> range_;
};

// ---------------------------------------------------------------------------------------------
// Export.

// What the manifest says about a VDB source (defaults for stores imported from anything else).
struct VdbProvenance {
  std::string grid;
  vdb::GridClass grid_class = vdb::GRID_UNKNOWN;
  Vec3s index_min{0};
};

VdbProvenance read_provenance(const Manifest& m) {
  VdbProvenance p;
  const nlohmann::json j = nlohmann::json::parse(m.source, nullptr, /*allow_exceptions=*/false);
  if (!j.is_object() || !j.contains("kind") || j["kind"] != "vdb") return p;
  if (j.contains("grid") && j["grid"].is_string()) p.grid = j["grid"].get<std::string>();
  if (j.contains("grid_class") && j["grid_class"] == "level_set") p.grid_class = vdb::GRID_LEVEL_SET;
  if (j.contains("grid_class") && j["grid_class"] == "fog_volume") p.grid_class = vdb::GRID_FOG_VOLUME;
  if (j.contains("index_min") && j["index_min"].is_array() && j["index_min"].size() == 3)
    for (int a = 0; a < 3; ++a)
      if (j["index_min"][size_t(a)].is_number_integer()) p.index_min[a] = j["index_min"][size_t(a)].get<int64_t>();
  return p;
}

// Leaf nodes holding one brick's voxels inside the region, built apart from the tree so that
// bricks convert in parallel; `box` is the part of each leaf they own (index coordinates).
struct BrickLeaves {
  vdb::CoordBBox box;
  std::vector<std::unique_ptr<LeafT>> leaves;
};

class VdbWriter {
 public:
  VdbWriter(const Store& store, int level, const VoxelBox& region, const VdbProvenance& source, int step)
      : store_(store), step_(step), level_(level), region_(region), format_(store.format()),
        background_(float(store.manifest().background)),
        // A level set's inactive voxels are +-background (outside and inside); a background that is
        // not positive cannot be a level set's, so such a store is written as a plain grid.
        level_set_(source.grid_class == vdb::GRID_LEVEL_SET && background_ > 0) {
    const int64_t scale = int64_t(1) << store.layout().steps(level);
    // Finest-level voxels go back to the source grid's index coordinates; a coarser level's
    // coordinates are the source's divided by 2^steps, rounded down.
    for (int a = 0; a < 3; ++a) offset_[a] = int32_t(floor_div(source.index_min[a], scale));
    grid_ = vdb::FloatGrid::create(background_);
    grid_->setGridClass(level_set_ ? vdb::GRID_LEVEL_SET
                                   : (source.grid_class == vdb::GRID_FOG_VOLUME ? vdb::GRID_FOG_VOLUME : vdb::GRID_UNKNOWN));
    grid_->setTransform(make_transform(store.manifest(), double(scale)));
  }

  vdb::FloatGrid::Ptr run(Progress* progress) {
    const int64_t M = format_.brick_size;
    const Vec3s b0 = region_.lo / M, b1 = (region_.hi - Vec3s(1)) / M;
    const Vec3s size = region_.size();
    for (int64_t bz = b0.z; bz <= b1.z; ++bz) {
      // Step 1: constant bricks become fills (tiles wherever they cover whole nodes).
      std::vector<BrickKey> varying;
      for (int64_t by = b0.y; by <= b1.y; ++by)
        for (int64_t bx = b0.x; bx <= b1.x; ++bx) {
          const BrickKey key{uint32_t(level_), uint32_t(bx), uint32_t(by), uint32_t(bz)};
          const NodeRecord& node = store_.nodes(step_).at(key);
          if (!node.is_constant()) {
            varying.push_back(key);
            continue;
          }
          const float v = node.constant;
          if (v == background_) continue;
          grid_->tree().fill(index_box(key), v, !is_inactive(v));
        }
      // Step 2: the other bricks, decoded and converted to leaf nodes in parallel.
      std::vector<BrickLeaves> converted(varying.size());
      parallel_for<size_t>(0, varying.size(), 1, [&](size_t i0, size_t i1) {
        auto txn = store_.begin_read();
        std::vector<std::byte> voxels(format_.bytes());
        for (size_t i = i0; i < i1; ++i) {
          store_.read_brick(txn, varying[i], voxels, step_);
          converted[i] = dispatch_value_type(format_.type, [&](auto tag) {
            return to_leaves(varying[i], reinterpret_cast<const decltype(tag)*>(voxels.data()));
          });
        }
      });
      // Step 3: into the tree. A leaf shared with a neighbouring brick takes only this brick's voxels.
      for (BrickLeaves& b : converted)
        for (auto& leaf : b.leaves) {
          if (LeafT* existing = grid_->tree().probeLeaf(leaf->origin())) {
            vdb::CoordBBox own = leaf->getNodeBoundingBox();
            own.intersect(b.box);
            for (auto ijk = own.beginZYX(); ijk; ++ijk) {
              const vdb::Index i = LeafT::coordToOffset(*ijk);
              existing->setValueOnly(i, leaf->getValue(i));
              existing->setActiveState(i, leaf->isValueOn(i));
            }
          } else {
            grid_->tree().addLeaf(leaf.release());
          }
        }
      if (progress) {
        const int64_t z0 = std::max(region_.lo.z, bz * M), z1 = std::min(region_.hi.z, (bz + 1) * M);
        progress->advance(uint64_t((z1 - z0) * size.x * size.y));
      }
    }
    // Step 4: uniform leaves and nodes collapse into tiles; for a level set, nodes that are all
    // inactive become inside or outside tiles.
    [[maybe_unused]] const OpenVdbCall call;
    vdb::tools::prune(grid_->tree());
    if (level_set_) vdb::tools::pruneLevelSet(grid_->tree());
    else vdb::tools::pruneInactive(grid_->tree());
    return grid_;
  }

 private:
  // Index coordinate ijk is level voxel ijk - offset, and coarse voxel i is centred at finest
  // coordinate (i + 0.5) * scale - 0.5 (layout.h).
  vdb::math::Transform::Ptr make_transform(const Manifest& m, double scale) const {
    const Vec3d vs = m.spacing * scale;
    vdb::Vec3d t;
    for (int a = 0; a < 3; ++a) t[a] = m.origin[a] + m.spacing[a] * ((0.5 - double(offset_[a])) * scale - 0.5);
    vdb::math::MapBase::Ptr map;
    if (vs.x == vs.y && vs.y == vs.z) map = std::make_shared<vdb::math::UniformScaleTranslateMap>(vs.x, t);
    else map = std::make_shared<vdb::math::ScaleTranslateMap>(vdb::Vec3d(vs.x, vs.y, vs.z), t);
    return std::make_shared<vdb::math::Transform>(map);
  }

  bool is_inactive(float v) const { return level_set_ ? std::abs(v) == background_ : v == background_; }

  // The brick's interior clipped to the region, in index coordinates (inclusive).
  vdb::CoordBBox index_box(const BrickKey& key) const {
    const int64_t M = format_.brick_size;
    const Vec3s b{int64_t(key.x), int64_t(key.y), int64_t(key.z)};
    vdb::CoordBBox box;
    for (int a = 0; a < 3; ++a) {
      box.min()[a] = int32_t(std::max(region_.lo[a], b[a] * M)) + offset_[a];
      box.max()[a] = int32_t(std::min(region_.hi[a], (b[a] + 1) * M)) - 1 + offset_[a];
    }
    return box;
  }

  template <typename T>
  BrickLeaves to_leaves(const BrickKey& key, const T* voxels) const {
    const int64_t M = format_.brick_size, A = format_.apron, E = format_.edge();
    BrickLeaves out;
    out.box = index_box(key);
    // Brick-local position of index coordinate 0 (the apron comes first in each row).
    const vdb::Coord local0(int32_t(A - int64_t(key.x) * M) - offset_[0], int32_t(A - int64_t(key.y) * M) - offset_[1],
                            int32_t(A - int64_t(key.z) * M) - offset_[2]);
    const int32_t mask = ~int32_t(LeafT::DIM - 1);
    const vdb::Coord& lo = out.box.min();
    const vdb::Coord& hi = out.box.max();
    for (int32_t oz = lo.z() & mask; oz <= hi.z(); oz += LeafT::DIM)
      for (int32_t oy = lo.y() & mask; oy <= hi.y(); oy += LeafT::DIM)
        for (int32_t ox = lo.x() & mask; ox <= hi.x(); ox += LeafT::DIM) {
          auto leaf = std::make_unique<LeafT>(vdb::Coord(ox, oy, oz), background_, false);
          bool any = false;
          const int32_t x0 = std::max(ox, lo.x()), x1 = std::min(ox + int32_t(LeafT::DIM) - 1, hi.x());
          for (int32_t z = std::max(oz, lo.z()); z <= std::min(oz + int32_t(LeafT::DIM) - 1, hi.z()); ++z)
            for (int32_t y = std::max(oy, lo.y()); y <= std::min(oy + int32_t(LeafT::DIM) - 1, hi.y()); ++y) {
              const T* row = voxels + ((int64_t(z + local0.z()) * E + (y + local0.y())) * E + local0.x());
              for (int32_t x = x0; x <= x1; ++x) {
                const float v = float(row[x]);
                const vdb::Index i = LeafT::coordToOffset(vdb::Coord(x, y, z));
                if (!is_inactive(v)) {
                  leaf->setValueOn(i, v);
                  any = true;
                } else if (v != background_) {
                  leaf->setValueOff(i, v);
                  any = true;
                }
              }
            }
          if (any) out.leaves.push_back(std::move(leaf));
        }
    return out;
  }

  const Store& store_;
  int step_;
  int level_;
  VoxelBox region_;
  BrickFormat format_;
  float background_;
  bool level_set_;
  int32_t offset_[3] = {0, 0, 0};
  vdb::FloatGrid::Ptr grid_;
};

}  // namespace

namespace {
/// OpenVDB allocates what sizes in the file say, unchecked (a damaged chunk size can ask for an
/// exabyte), and lets std::bad_alloc escape: say which file, and that it may be damaged.
Error out_of_memory_reading(const std::string& path, const std::string& what) {
  Error e(Errc::resource, fmt::format("OpenVDB ran out of memory reading {}: the file is damaged, or needs more memory "
                                      "than this machine has", what));
  e.with_file(path);
  return e;
}
}  // namespace

bool vdb_support() { return true; }

std::unique_ptr<VolumeSource> open_vdb_source(const std::string& path, const std::string& grid_name) {
  initialize_openvdb();
  const FileStat st = stat_input(path);
  [[maybe_unused]] const OpenVdbCall call;
  vdb::io::File file(path);
  try {
    file.open(/*delayLoad=*/false);
  } catch (const vdb::Exception& e) {
    throw Error(Errc::format, fmt::format("not a readable OpenVDB file ({})", e.what())).with_file(path);
  } catch (const std::bad_alloc&) {
    throw out_of_memory_reading(path, "its header");
  } catch (const std::exception& e) {
    throw Error(Errc::format, fmt::format("not a readable OpenVDB file ({})", e.what())).with_file(path);
  }
  std::vector<std::string> names;
  for (auto it = file.beginName(); it != file.endName(); ++it) names.push_back(*it);

  // Step 1: which grid.
  std::string name = grid_name;
  if (name.empty()) {
    if (names.size() != 1)
      throw Error(names.empty() ? Errc::not_found : Errc::invalid_argument,
                  names.empty() ? std::string("the file has no grids")
                                : fmt::format("the file has {} grids ({}); choose one with --grid", names.size(),
                                              quoted_list(names)))
          .with_file(path)
          .with_field("--grid");
    name = names.front();
  } else if (std::find(names.begin(), names.end(), name) == names.end()) {
    throw Error(Errc::not_found, fmt::format("no grid named '{}'; the file has {}", name, quoted_list(names)))
        .with_file(path)
        .with_field("--grid");
  }

  // Step 2: its type, from the metadata alone, before reading any voxels.
  vdb::GridBase::Ptr grid;
  try {
    grid = file.readGridMetadata(name);
  } catch (const vdb::LookupError& e) {
    throw Error(Errc::unsupported, fmt::format("grid '{}' has a type this OpenVDB cannot read ({})", name, e.what()))
        .with_file(path)
        .with_field("--grid");
  } catch (const vdb::Exception& e) {
    throw Error(Errc::format, fmt::format("cannot read grid '{}' ({})", name, e.what())).with_file(path);
  } catch (const std::bad_alloc&) {
    throw out_of_memory_reading(path, fmt::format("grid '{}'", name));
  } catch (const std::exception& e) {
    throw Error(Errc::format, fmt::format("cannot read grid '{}' ({})", name, e.what())).with_file(path);
  }
  if (!grid->isType<vdb::FloatGrid>() && !grid->isType<vdb::DoubleGrid>() && !grid->isType<vdb::Int32Grid>())
    throw Error(Errc::unsupported, fmt::format("grid '{}' holds {} values ({}); brickyard imports float, double and "
                                               "int32 grids",
                                               name, grid->valueType(), grid->type()))
        .with_file(path)
        .with_field("--grid");

  // Step 3: the voxels.
  try {
    grid = file.readGrid(name);
    file.close();
  } catch (const vdb::Exception& e) {
    throw Error(Errc::format, fmt::format("cannot read grid '{}' ({})", name, e.what())).with_file(path);
  } catch (const std::bad_alloc&) {
    throw out_of_memory_reading(path, fmt::format("grid '{}'", name));
  } catch (const std::exception& e) {
    throw Error(Errc::format, fmt::format("cannot read grid '{}' ({})", name, e.what())).with_file(path);
  }
  return std::make_unique<VdbSource>(path, std::move(grid), st);
}

void export_vdb(const Store& store, int level, const VoxelBox& region, const std::string& path,
                const std::string& grid_name, Progress* progress, int step) {
  initialize_openvdb();
  export_region(store, level, region);  // the same checks as every export: level and box
  (void)store.dataset(step);            // and the time step
  const VdbProvenance source = read_provenance(store.manifest());
  vdb::FloatGrid::Ptr grid = VdbWriter(store, level, region, source, step).run(progress);
  grid->setName(!grid_name.empty() ? grid_name : (!source.grid.empty() ? source.grid : "density"));
  grid->insertMeta("brickyard_level", vdb::Int32Metadata(level));
  grid->insertMeta("brickyard_store", vdb::StringMetadata(store.path()));

  // Atomic like the raw export: a reader never sees a half-written file under `path`.
  refuse_to_replace_non_regular(path);
  const std::string tmp = path + ".partial";
  try {
    [[maybe_unused]] const OpenVdbCall call;
    vdb::io::File file(tmp);
    file.write(vdb::GridCPtrVec{grid});
    file.close();
  } catch (const std::exception& e) {
    std::remove(tmp.c_str());
    throw Error(Errc::io, fmt::format("cannot write: {}", e.what())).with_file(path);
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) {
    std::remove(tmp.c_str());
    throw Error(Errc::io, fmt::format("cannot move into place: {}", ec.message())).with_file(path);
  }
}

}  // namespace brickyard
