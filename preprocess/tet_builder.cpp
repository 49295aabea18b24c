#include "preprocess/tet_builder.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <mutex>

#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <tbb/task_arena.h>

#include "core/error.h"
#include "core/parallel.h"
#include "core/progress.h"
#include "core/timing.h"
#include "dataset/tet_bvh.h"
#include "fields/random.h"
#include "storage/page_codec.h"
#include "storage/store.h"

namespace brickyard {
namespace {

// ------------------------------------------------------------------------- partitioned mesh

class PartitionedMesh final : public TetClusterSource {
 public:
  PartitionedMesh(TetMesh&& mesh, uint32_t cluster_tets, std::string name, std::string source_json, uint64_t input_bytes)
      : mesh_(std::move(mesh)), name_(std::move(name)), source_json_(std::move(source_json)), input_bytes_(input_bytes) {
    const uint64_t n = mesh_.tet_count();
    if (n > std::numeric_limits<uint32_t>::max())
      throw Error(Errc::unsupported, fmt::format("{} tets in one file: more than this reader partitions in memory", n))
          .with_file(name_);
    centroids_.resize(size_t(n) * 3);
    order_.resize(size_t(n));
    parallel_for<size_t>(0, size_t(n), 1 << 14, [&](size_t a, size_t b) {
      for (size_t t = a; t < b; ++t) {
        order_[t] = uint32_t(t);
        for (int ax = 0; ax < 3; ++ax) {
          float c = 0;
          for (int k = 0; k < 4; ++k) c += mesh_.positions[size_t(mesh_.tets[t * 4 + size_t(k)]) * 3 + size_t(ax)];
          centroids_[t * 3 + size_t(ax)] = 0.25f * c;
        }
      }
    });
    split(0, size_t(n), std::max<uint32_t>(1, cluster_tets));
    std::sort(leaves_.begin(), leaves_.end());
    centroids_ = {};
  }

  std::string name() const override { return name_; }
  std::string describe_json() const override { return source_json_; }
  int time_steps() const override { return mesh_.time_steps(); }
  bool moving() const override { return !mesh_.step_positions.empty(); }
  std::string array_name() const override { return mesh_.array_name; }
  std::vector<std::string> step_names() const override { return mesh_.step_names; }
  uint64_t cluster_count() const override { return leaves_.size(); }
  uint64_t tet_count() const override { return mesh_.tet_count(); }
  uint64_t vertex_count() const override { return mesh_.vertex_count(); }
  const MeshReport& report() const override { return mesh_.report; }
  uint64_t input_bytes() const override { return input_bytes_; }

  void cluster(uint64_t i, ClusterData& out) const override {
    const auto [b, e] = leaves_[size_t(i)];
    std::vector<uint32_t> global;
    global.reserve((e - b) * 4);
    for (size_t k = b; k < e; ++k)
      for (int c = 0; c < 4; ++c) global.push_back(mesh_.tets[size_t(order_[k]) * 4 + size_t(c)]);
    out.corners.resize(global.size());
    std::vector<uint32_t> unique = global;
    std::sort(unique.begin(), unique.end());
    unique.erase(std::unique(unique.begin(), unique.end()), unique.end());
    for (size_t k = 0; k < global.size(); ++k)
      out.corners[k] = uint32_t(std::lower_bound(unique.begin(), unique.end(), global[k]) - unique.begin());
    const size_t v = unique.size();
    out.positions.clear();
    auto add_set = [&](const std::vector<float>& p) {
      for (uint32_t g : unique) out.positions.insert(out.positions.end(), {p[size_t(g) * 3], p[size_t(g) * 3 + 1], p[size_t(g) * 3 + 2]});
    };
    add_set(mesh_.positions);
    for (const auto& sp : mesh_.step_positions) add_set(sp);
    out.values.resize(v * mesh_.scalars.size());
    for (size_t s = 0; s < mesh_.scalars.size(); ++s)
      for (size_t k = 0; k < v; ++k) out.values[s * v + k] = mesh_.scalars[s][unique[k]];
  }

 private:
  /// Median split along the longest axis of the centroids' box, until a part fits a cluster.
  void split(size_t begin, size_t end, uint32_t cluster_tets) {
    if (end - begin <= cluster_tets) {
      std::lock_guard lock(mutex_);
      leaves_.emplace_back(begin, end);
      return;
    }
    float lo[3] = {std::numeric_limits<float>::infinity(), std::numeric_limits<float>::infinity(),
                   std::numeric_limits<float>::infinity()};
    float hi[3] = {-lo[0], -lo[1], -lo[2]};
    for (size_t k = begin; k < end; ++k)
      for (int a = 0; a < 3; ++a) {
        const float c = centroids_[size_t(order_[k]) * 3 + size_t(a)];
        lo[a] = std::min(lo[a], c), hi[a] = std::max(hi[a], c);
      }
    int axis = 0;
    for (int a = 1; a < 3; ++a)
      if (hi[a] - lo[a] > hi[axis] - lo[axis]) axis = a;
    const size_t mid = begin + (end - begin) / 2;
    std::nth_element(order_.begin() + long(begin), order_.begin() + long(mid), order_.begin() + long(end),
                     [&](uint32_t x, uint32_t y) {
                       const float cx = centroids_[size_t(x) * 3 + size_t(axis)], cy = centroids_[size_t(y) * 3 + size_t(axis)];
                       return cx < cy || (cx == cy && x < y);
                     });
    if (end - begin > (size_t(1) << 16)) {
      // parallel_for, not tbb::parallel_invoke: its ThreadSanitizer build runs on threads
      // the sanitizer sees joined.
      parallel_for<int>(0, 2, 1, [&](int a, int b) {
        for (int half = a; half < b; ++half) half == 0 ? split(begin, mid, cluster_tets) : split(mid, end, cluster_tets);
      });
    } else {
      split(begin, mid, cluster_tets);
      split(mid, end, cluster_tets);
    }
  }

  TetMesh mesh_;
  std::string name_, source_json_;
  uint64_t input_bytes_;
  std::vector<float> centroids_;
  std::vector<uint32_t> order_;
  std::mutex mutex_;
  std::vector<std::pair<size_t, size_t>> leaves_;
};

// ------------------------------------------------------------------------- procedural mesh

/// The six tets of a cube around its diagonal 0-7 (corner v = x + 2y + 4z).
constexpr std::array<std::array<int, 4>, 6> kKuhn = {
    {{0, 1, 3, 7}, {0, 1, 5, 7}, {0, 2, 3, 7}, {0, 2, 6, 7}, {0, 4, 5, 7}, {0, 4, 6, 7}}};

class ProceduralMesh final : public TetClusterSource {
 public:
  ProceduralMesh(const ProceduralMeshSpec& spec, uint32_t cluster_tets) : spec_(spec), field_(make_field(spec.field, spec.params)) {
    if (spec.cells < 1 || spec.cells > 4096)
      throw Error(Errc::invalid_argument, fmt::format("{} cells per axis (need 1 to 4096)", spec.cells)).with_field("--cells");
    if (!(spec.jitter >= 0 && spec.jitter <= 0.2))
      throw Error(Errc::invalid_argument, fmt::format("jitter {} (need 0 to 0.2 cells: more folds the cubes' tets)", spec.jitter))
          .with_field("--jitter");
    if (spec.replicate < 1 || spec.replicate > 64)
      throw Error(Errc::invalid_argument, fmt::format("{} replications per axis (need 1 to 64)", spec.replicate))
          .with_field("--replicate");
    if (spec.steps < 1 || spec.steps > 1024)
      throw Error(Errc::invalid_argument, fmt::format("{} time steps (need 1 to 1024)", spec.steps)).with_field("--steps");
    if (!(std::abs(spec.move) <= 1))
      throw Error(Errc::invalid_argument, fmt::format("move {} (need -1 to 1: a fraction of the domain per step)", spec.move))
          .with_field("--move");
    // Blocks of equal size (24 cells in blocks of at most 11: 3 of 8, not 11, 11 and 2): pages
    // take fixed slots of the largest cluster's size, so a sliver would waste most of its slot.
    const int64_t largest =
        std::clamp<int64_t>(int64_t(std::cbrt(double(std::max<uint32_t>(6, cluster_tets)) / 6.0)), 1, spec.cells);
    blocks_ = (spec.cells + largest - 1) / largest;
    block_ = (spec.cells + blocks_ - 1) / blocks_;
    domain_ = field_->domain();
    cell_ = domain_.extent() / double(spec.cells);
    const uint64_t cubes = uint64_t(spec.cells) * uint64_t(spec.cells) * uint64_t(spec.cells) * replicas();
    report_.input_cells = cubes;
    report_.input_points = uint64_t(spec.cells + 1) * uint64_t(spec.cells + 1) * uint64_t(spec.cells + 1) * replicas();
    report_.split["hexahedron (Kuhn, 6 tets)"] = cubes;
    report_.split_tets = report_.tets = 6 * cubes;
  }

  std::string name() const override { return fmt::format("mesh {}", spec_.field); }
  std::string describe_json() const override {
    nlohmann::json params = nlohmann::json::object();
    for (const FieldParam& p : field_->params()) params[p.name] = p.value;
    nlohmann::json j = {{"kind", "procedural_mesh"}, {"field", spec_.field}, {"params", params},
                        {"cells", spec_.cells}, {"jitter", spec_.jitter}, {"replicate", spec_.replicate},
                        {"steps", spec_.steps}, {"step_shift", spec_.step_shift}, {"move", spec_.move},
                        {"seed", spec_.seed}};
    return j.dump();
  }
  int time_steps() const override { return spec_.steps; }
  bool moving() const override { return spec_.move != 0 && spec_.steps > 1; }
  std::string array_name() const override { return spec_.field; }
  std::vector<std::string> step_names() const override {
    std::vector<std::string> out;
    for (int s = 0; s < spec_.steps; ++s) out.push_back(spec_.steps == 1 ? spec_.field : fmt::format("{}_{}", spec_.field, s));
    return out;
  }
  uint64_t cluster_count() const override { return uint64_t(blocks_ * blocks_ * blocks_) * replicas(); }
  uint64_t tet_count() const override { return report_.tets; }
  uint64_t vertex_count() const override { return report_.input_points; }
  const MeshReport& report() const override { return report_; }
  uint64_t input_bytes() const override { return 0; }

  void cluster(uint64_t i, ClusterData& out) const override {
    const uint64_t per_replica = uint64_t(blocks_ * blocks_ * blocks_);
    const uint64_t r = i / per_replica, b = i % per_replica;
    const int64_t R = spec_.replicate;
    const Vec3d offset = Vec3d(double(int64_t(r) % R), double(int64_t(r) / R % R), double(int64_t(r) / (R * R))) * domain_.extent();
    const int64_t bx = int64_t(b) % blocks_, by = int64_t(b) / blocks_ % blocks_, bz = int64_t(b) / (blocks_ * blocks_);
    const int64_t x0 = bx * block_, y0 = by * block_, z0 = bz * block_;
    const int64_t nx = std::min(block_, spec_.cells - x0), ny = std::min(block_, spec_.cells - y0), nz = std::min(block_, spec_.cells - z0);
    const int64_t vx = nx + 1, vy = ny + 1, vz = nz + 1;
    const size_t v = size_t(vx * vy * vz);
    const size_t sets = moving() ? size_t(spec_.steps) : 1;
    out.positions.resize(sets * v * 3);
    out.values.resize(v * size_t(spec_.steps));
    for (int64_t k = 0; k < vz; ++k)
      for (int64_t j = 0; j < vy; ++j)
        for (int64_t ii = 0; ii < vx; ++ii) {
          const size_t l = size_t((k * vy + j) * vx + ii);
          const Vec3d p = vertex(x0 + ii, y0 + j, z0 + k);
          for (int a = 0; a < 3; ++a) out.positions[l * 3 + size_t(a)] = float(p[a] + offset[a]);
          for (size_t set = 1; set < sets; ++set) {
            const Vec3d moved = moved_vertex(p, int(set));
            for (int a = 0; a < 3; ++a) out.positions[(set * v + l) * 3 + size_t(a)] = float(moved[a] + offset[a]);
          }
          for (int s = 0; s < spec_.steps; ++s) {
            // The value at the stored (float) position, so that the mesh's linear field
            // agrees with the field at its vertices to the last bit the store keeps.
            const Vec3d q(double(float(p.x + offset.x)) - offset.x, double(float(p.y + offset.y)) - offset.y,
                          double(float(p.z + offset.z)) - offset.z);
            const Vec3d shifted = q - Vec3d(spec_.step_shift * double(s) * domain_.extent().x, 0, 0);
            out.values[size_t(s) * v + l] = float(field_->value(shifted));
          }
        }
    out.corners.clear();
    out.corners.reserve(size_t(nx * ny * nz) * 24);
    for (int64_t k = 0; k < nz; ++k)
      for (int64_t j = 0; j < ny; ++j)
        for (int64_t ii = 0; ii < nx; ++ii) {
          uint32_t c[8];
          for (int n = 0; n < 8; ++n)
            c[n] = uint32_t(((k + (n >> 2 & 1)) * vy + (j + (n >> 1 & 1))) * vx + (ii + (n & 1)));
          for (const auto& t : kKuhn) {
            uint32_t q[4] = {c[t[0]], c[t[1]], c[t[2]], c[t[3]]};
            auto at = [&](uint32_t w) { return Vec3d(out.positions[w * 3], out.positions[w * 3 + 1], out.positions[w * 3 + 2]); };
            if (tet_volume6(at(q[0]), at(q[1]), at(q[2]), at(q[3])) < 0) std::swap(q[2], q[3]);
            out.corners.insert(out.corners.end(), q, q + 4);
          }
        }
    check_moved_tets(out, v, sets, i);
  }

 private:
  uint64_t replicas() const { return uint64_t(spec_.replicate) * uint64_t(spec_.replicate) * uint64_t(spec_.replicate); }

  /// Where vertex p is at `step` (a shear: x moves with y, y with z; the map's Jacobian is
  /// unit upper triangular, so it keeps volume, and a straight-edged tet much smaller than the
  /// wave keeps its orientation).
  Vec3d moved_vertex(const Vec3d& p, int step) const {
    const Vec3d e = domain_.extent(), u = (p - domain_.lo) / e;
    const double amount = spec_.move * double(step), two_pi = 2 * 3.14159265358979323846;
    return {p.x + amount * e.x * std::sin(two_pi * u.y), p.y + amount * e.y * std::sin(two_pi * u.z), p.z};
  }

  /// Grid vertex (i, j, k) with its jitter: a hash of its index, so every cluster that shares
  /// it puts it at the same place; vertices on the domain's faces stay on them.
  Vec3d vertex(int64_t i, int64_t j, int64_t k) const {
    const int64_t g[3] = {i, j, k};
    Vec3d p;
    const uint64_t n1 = uint64_t(spec_.cells + 1);
    SplitMix64 rng(spec_.seed * 0x9e3779b97f4a7c15ull + (uint64_t(k) * n1 + uint64_t(j)) * n1 + uint64_t(i));
    for (int a = 0; a < 3; ++a) {
      const double u = rng.uniform(-1.0, 1.0);
      const bool face = g[a] == 0 || g[a] == spec_.cells;
      p[a] = domain_.lo[a] + (double(g[a]) + (face ? 0.0 : spec_.jitter * u)) * cell_[a];
    }
    return p;
  }

  /// A tet folded by the motion (cells too coarse for the wave's curvature) is refused.
  void check_moved_tets(const ClusterData& d, size_t v, size_t sets, uint64_t cluster) const {
    for (size_t set = 1; set < sets; ++set) {
      const float* pos = d.positions.data() + set * v * 3;
      auto at = [&](uint32_t w) { return Vec3d(pos[w * 3], pos[w * 3 + 1], pos[w * 3 + 2]); };
      for (size_t t = 0; t < d.corners.size(); t += 4)
        if (!(tet_volume6(at(d.corners[t]), at(d.corners[t + 1]), at(d.corners[t + 2]), at(d.corners[t + 3])) > 0))
          throw Error(Errc::invalid_argument,
                      fmt::format("move {} folds tetrahedron {} of cluster {} at step {} (cells of 1/{} are too coarse for "
                                  "a displacement of {} of the domain): lower --move or raise --cells",
                                  spec_.move, t / 4, cluster, set, spec_.cells, spec_.move * double(set)))
              .with_field("--move");
    }
  }

  ProceduralMeshSpec spec_;
  std::unique_ptr<Field> field_;
  Box3d domain_;
  Vec3d cell_;
  int64_t block_ = 1, blocks_ = 1;
  MeshReport report_;
};

// ------------------------------------------------------------------------------- the build

struct EncodedCluster {
  TetCluster entry;
  std::vector<TetStepRange> ranges;
  std::vector<std::byte> record;
  uint64_t page_bytes = 0;
};

EncodedCluster encode_cluster(const TetClusterSource& source, uint64_t id, const std::string& name, bool store_bvh) {
  ClusterData d;
  source.cluster(id, d);
  EncodedCluster e;
  const uint32_t steps = uint32_t(source.time_steps());
  const uint32_t v = steps ? uint32_t(d.values.size() / steps) : 0;
  BY_CHECK(v > 0 && !d.corners.empty());
  TetCluster& c = e.entry;
  c.vertices = v;
  c.tets = uint32_t(d.corners.size() / 4);
  for (int a = 0; a < 3; ++a) c.lo[a] = std::numeric_limits<float>::infinity(), c.hi[a] = -std::numeric_limits<float>::infinity();
  for (size_t k = 0; k + 2 < d.positions.size(); k += 3)
    for (size_t a = 0; a < 3; ++a) c.lo[a] = std::min(c.lo[a], d.positions[k + a]), c.hi[a] = std::max(c.hi[a], d.positions[k + a]);
  c.min = std::numeric_limits<float>::infinity(), c.max = -std::numeric_limits<float>::infinity();
  for (uint32_t s = 0; s < steps; ++s) {
    const auto [lo, hi] = std::minmax_element(d.values.begin() + long(s) * v, d.values.begin() + long(s + 1) * v);
    e.ranges.push_back({*lo, *hi});
    c.min = std::min(c.min, *lo), c.max = std::max(c.max, *hi);
  }
  std::vector<std::byte> page;
  try {
    page = TetClusterPage::encode(d.positions, d.values, d.corners, steps);
  } catch (Error& err) {
    throw err.with_file(name).with_key(fmt::format("cluster {}", id));
  }
  if (store_bvh) {
    // Step 0's BVH as tet_bvh builds it by default, after the tetrahedra.
    const auto method = tet_bvh::BuildMethod::bih;
    const tet_bvh::ClusterBvh bvh = tet_bvh::ClusterBvh::build(TetClusterPage::view(page), 0, method, kStoredBvhLeafSize);
    const std::vector<std::byte> tail = bvh.encode(page.size(), method, kStoredBvhLeafSize);
    page.insert(page.end(), tail.begin(), tail.end());
  }
  e.page_bytes = page.size();
  e.record = encode_page({RecordKind::tet_cluster, id}, page);
  return e;
}

}  // namespace

std::unique_ptr<TetClusterSource> partition_mesh(TetMesh&& mesh, uint32_t cluster_tets, std::string name,
                                                 std::string source_json, uint64_t input_bytes) {
  return std::make_unique<PartitionedMesh>(std::move(mesh), cluster_tets, std::move(name), std::move(source_json), input_bytes);
}

std::unique_ptr<TetClusterSource> make_procedural_mesh(const ProceduralMeshSpec& spec, uint32_t cluster_tets) {
  return std::make_unique<ProceduralMesh>(spec, cluster_tets);
}

BuildResult build_tet_store(const TetClusterSource& source, const std::string& dir, const TetBuildOptions& options,
                            Progress* progress) {
  if (options.cluster_tets < 64 || options.cluster_tets > (1u << 20))
    throw Error(Errc::invalid_argument, fmt::format("{} tets a cluster (need 64 to 1048576)", options.cluster_tets))
        .with_field("--cluster-tets");
  Stopwatch watch;
  BuildResult result;
  nlohmann::json provenance = nlohmann::json::parse(source.describe_json());
  provenance["array"] = source.array_name();
  provenance["steps"] = source.step_names();
  provenance["report"] = nlohmann::json::parse(source.report().to_json());
  const std::string source_json = provenance.dump();
  nlohmann::json build = {{"cluster_tets", options.cluster_tets}};
  if (options.store_bvh) build["bvh"] = {{"method", "bih"}, {"leaf_size", kStoredBvhLeafSize}};
  const std::string build_json = build.dump();
  StoreBuildTarget target(dir, source_json, build_json, options.force, result);
  if (target.up_to_date()) {
    result.up_to_date = true;
    return result;
  }

  Manifest manifest;
  manifest.kind = DataKind::tetrahedral;
  manifest.format_version = kMeshStoreFormatVersion;
  manifest.time_steps = source.time_steps();
  manifest.mesh.moving = source.moving();
  manifest.source = source_json;
  manifest.build = build_json;

  lmdb::EnvOptions env;
  const uint64_t estimate = source.tet_count() * 24 + source.vertex_count() * 16 * uint64_t(source.time_steps());
  env.map_size = options.map_size ? options.map_size : std::max<uint64_t>(uint64_t(64) << 20, estimate + estimate / 2);
  env.growth = options.map_growth;
  env.max_map_size = options.map_growth ? uint64_t(1) << 44 : env.map_size;
  env.no_sync = true;
  auto store = std::make_unique<StoreWriter>(target.path(), manifest, env, options.batch_bytes);

  const uint64_t clusters = source.cluster_count();
  std::vector<TetCluster> table(static_cast<size_t>(clusters));
  std::vector<TetStepRange> ranges;
  if (manifest.time_steps > 1) ranges.resize(size_t(clusters) * size_t(manifest.time_steps));
  // A window of clusters is generated and compressed in parallel, then written in order:
  // memory is a window of pages whatever the mesh's size.
  const uint64_t window = uint64_t(std::max(4, tbb::this_task_arena::max_concurrency()) * 8);
  std::vector<EncodedCluster> encoded;
  uint64_t tets = 0, page_bytes = 0;
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  Box3d bounds{Vec3d{lo}, Vec3d{hi}};
  for (uint64_t w0 = 0; w0 < clusters; w0 += window) {
    const uint64_t w1 = std::min(clusters, w0 + window);
    encoded.assign(size_t(w1 - w0), {});
    parallel_for<uint64_t>(w0, w1, 1, [&](uint64_t a, uint64_t b) {
      for (uint64_t i = a; i < b; ++i) encoded[size_t(i - w0)] = encode_cluster(source, i, source.name(), options.store_bvh);
    });
    for (uint64_t i = w0; i < w1; ++i) {
      EncodedCluster& e = encoded[size_t(i - w0)];
      table[size_t(i)] = e.entry;
      if (!ranges.empty()) std::copy(e.ranges.begin(), e.ranges.end(), ranges.begin() + long(i) * manifest.time_steps);
      tets += e.entry.tets;
      page_bytes = std::max(page_bytes, e.page_bytes);
      lo = std::min(lo, double(e.entry.min)), hi = std::max(hi, double(e.entry.max));
      for (int a = 0; a < 3; ++a)
        bounds.lo[a] = std::min(bounds.lo[a], double(e.entry.lo[a])), bounds.hi[a] = std::max(bounds.hi[a], double(e.entry.hi[a]));
      result.stored_bytes += e.record.size();
      store->put_cluster_record(i, std::move(e.record));
      if (progress) progress->advance(e.entry.tets);
    }
  }
  manifest.min_value = lo;
  manifest.max_value = hi;
  manifest.mesh.bounds = bounds;
  manifest.mesh.clusters = clusters;
  manifest.mesh.tets = tets;
  manifest.mesh.vertices = source.vertex_count();
  manifest.mesh.page_bytes = page_bytes;
  store->finish(manifest, table, ranges);
  store.reset();  // closed before its directory is swapped into place
  target.commit();
  manifest.complete = true;
  result.manifest = manifest;
  result.seconds = watch.seconds();
  result.input_bytes = source.input_bytes();
  return result;
}

}  // namespace brickyard
