// Tetrahedral meshes on the command line: import (mesh files and mesh:FIELD), and what info,
// verify and export do for a tetrahedral store.

#include <algorithm>
#include <array>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <mutex>
#include <unordered_map>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "apps/commands.h"
#include "apps/parse.h"
#include "core/atomic_file.h"
#include "core/error.h"
#include "core/parallel.h"
#include "core/progress.h"
#include "core/timing.h"
#include "core/units.h"
#include "preprocess/mesh_readers.h"
#include "preprocess/tet_builder.h"
#include "storage/store.h"

namespace brickyard::cli {

namespace fs = std::filesystem;

bool is_mesh_source(const std::string& source) { return source.rfind("mesh:", 0) == 0 || is_mesh_file(source); }

void run_mesh_import(const MeshImportOptions& o) {
  TetBuildOptions b;
  b.cluster_tets = o.cluster_tets;
  b.store_bvh = o.bvh;
  b.force = o.force;
  if (!o.map_size.empty()) b.map_size = parse_bytes(o.map_size, "--map-size");
  std::unique_ptr<TetClusterSource> source;
  double read_seconds = 0;
  if (o.source.rfind("mesh:", 0) == 0) {
    ProceduralMeshSpec spec;
    spec.field = o.source.substr(5);
    for (const auto& s : o.params) spec.params.insert(parse_assignment(s, "--set"));
    spec.cells = o.cells;
    spec.jitter = o.jitter;
    spec.replicate = o.replicate;
    spec.steps = o.steps;
    spec.move = o.move;
    source = make_procedural_mesh(spec, b.cluster_tets);
  } else {
    if (!o.params.empty()) throw Error(Errc::invalid_argument, "--set applies to field: and mesh: sources only").with_field("--set");
    std::error_code ec;
    const uint64_t bytes = fs::is_regular_file(o.source, ec) ? uint64_t(fs::file_size(o.source, ec)) : 0;
    Stopwatch read_watch;
    std::string format;
    int file_steps = 1;
    // The reader's copy dies here, before the mesh is partitioned and built.
    TetMesh mesh = [&] {
      MeshData data = read_mesh_file(o.source);
      format = data.format;
      file_steps = data.steps;
      return tetrahedralize(std::move(data), ArraySelection{o.array, !o.single_step});
    }();
    read_seconds = read_watch.seconds();
    for (const std::string& line : mesh.report.lines()) std::cout << "  " << line << "\n";
    std::cout << fmt::format("  read and validated {} in {} ({}/s)\n", format_bytes(double(bytes)), format_duration(read_seconds),
                             format_bytes(double(bytes) / std::max(1e-9, read_seconds)));
    nlohmann::json j = {{"kind", "mesh_file"}, {"path", fs::absolute(o.source).lexically_normal().string()},
                        {"format", format}, {"bytes", bytes}, {"files", file_steps}};
    source = partition_mesh(std::move(mesh), b.cluster_tets, o.source, j.dump(), bytes);
  }
  std::cout << fmt::format("import {} ({} tets, {} vertices, {} time step{}) -> {}\n", source->name(), source->tet_count(),
                           source->vertex_count(), source->time_steps(), source->time_steps() == 1 ? "" : "s", o.out);
  Progress progress(fmt::format("import {}", fs::path(source->name()).filename().string()), source->tet_count(), "tets");
  const BuildResult r = build_tet_store(*source, o.out, b, &progress);
  if (r.up_to_date) {
    std::cout << fmt::format("{} is complete and up to date; nothing to do (--force rebuilds)\n", o.out);
    return;
  }
  progress.finish();
  if (r.rebuilt_incomplete) std::cout << "an interrupted earlier build was discarded and rebuilt\n";
  const MeshSummary& m = r.manifest.mesh;
  const double seconds = read_seconds + r.seconds;
  std::cout << fmt::format("wrote {}: {} tets in {} clusters ({} of records, pages of {}) in {} ({:.0f} tets/s{})\n", o.out,
                           m.tets, m.clusters, format_bytes(double(r.stored_bytes)), format_bytes(double(m.page_bytes)),
                           format_duration(seconds), double(m.tets) / std::max(1e-9, seconds),
                           r.input_bytes ? fmt::format(", {}/s of input", format_bytes(double(r.input_bytes) / std::max(1e-9, seconds))) : "");
}

void print_mesh_info(const std::string& path, const Store& store) {
  const Manifest& m = store.manifest();
  const MeshSummary& mesh = m.mesh;
  std::cout << fmt::format("store {}: {}, tetrahedral mesh, format version {}\n", path,
                           m.complete ? "complete" : "INCOMPLETE (" + incomplete_reason(path) + ")", m.format_version);
  std::cout << fmt::format("{} tetrahedra, {} vertices in {} clusters, pages of {}, {} time step{}{}\n", mesh.tets,
                           mesh.vertices, mesh.clusters, format_bytes(double(mesh.page_bytes)), m.time_steps,
                           m.time_steps == 1 ? "" : "s", mesh.moving ? " (moving vertices)" : "");
  std::cout << fmt::format("bounds ({:g}, {:g}, {:g}) - ({:g}, {:g}, {:g}), values [{:g}, {:g}]\n", mesh.bounds.lo.x,
                           mesh.bounds.lo.y, mesh.bounds.lo.z, mesh.bounds.hi.x, mesh.bounds.hi.y, mesh.bounds.hi.z,
                           m.min_value, m.max_value);
  if (!m.complete) return;
  const size_t table = store.clusters().size() * sizeof(TetCluster) + store.step_ranges().size() * sizeof(TetStepRange);
  std::cout << fmt::format("cluster table {}, {} cluster records\n", format_bytes(double(table)), store.record_count());
  if (!m.build.empty()) {
    const nlohmann::json build = nlohmann::json::parse(m.build);
    if (build.contains("bvh"))
      std::cout << fmt::format("BVHs stored with the clusters ({}, leaves of at most {} tets, step 0)\n",
                               build["bvh"].value("method", std::string("?")), build["bvh"].value("leaf_size", 0));
  }
  nlohmann::json source = nlohmann::json::parse(m.source);
  if (source.contains("report")) {
    const nlohmann::json& r = source["report"];
    std::cout << fmt::format("import: {} input cells, {} valid tets, {} re-oriented, {} skipped\n",
                             r.value("input_cells", uint64_t(0)), r.value("tets", uint64_t(0)), r.value("reoriented", uint64_t(0)),
                             [&] {
                               uint64_t n = 0;
                               if (r.contains("skipped"))
                                 for (const auto& [k, v] : r["skipped"].items()) n += v.value("count", uint64_t(0));
                               return n;
                             }());
  }
  if (source.contains("steps") && m.time_steps > 1) std::cout << "steps  " << source["steps"].dump() << "\n";
  source.erase("report");
  std::cout << "source " << source.dump() << "\n";
  std::cout << "build  " << nlohmann::json::parse(m.build).dump() << "\n";
}

namespace {

/// Problems of one decoded cluster page against its table entry.
void check_cluster(const Store& store, size_t c, const TetClusterPage& p, std::vector<std::string>& bad) {
  const TetCluster& e = store.clusters()[c];
  const uint32_t steps = uint32_t(store.manifest().time_steps);
  if (p.vertex_count != e.vertices || p.tet_count != e.tets)
    bad.push_back(fmt::format("page holds {} vertices and {} tets, the table {} and {}", p.vertex_count, p.tet_count, e.vertices, e.tets));
  if (p.steps != steps) bad.push_back(fmt::format("page holds {} time steps, the store {}", p.steps, steps));
  for (uint32_t s = 0; s < std::min(p.steps, steps); ++s) {
    const float* pos = p.positions_at(s);
    const float* val = p.values_at(s);
    const TetStepRange r = store.dataset().tets().range(c, int(s));
    bool outside = false;
    for (uint32_t v = 0; v < p.vertex_count && !outside; ++v)
      for (int a = 0; a < 3; ++a)
        if (!(pos[3 * v + a] >= e.lo[a] && pos[3 * v + a] <= e.hi[a])) {
          bad.push_back(fmt::format("vertex {} of step {} lies outside the cluster's bounds", v, s));
          outside = true;
          break;
        }
    for (uint32_t v = 0; v < p.vertex_count; ++v)
      if (!(val[v] >= r.min && val[v] <= r.max)) {
        bad.push_back(fmt::format("value {} of vertex {} in step {} is outside the step's range [{}, {}]", val[v], v, s, r.min, r.max));
        break;
      }
    for (uint32_t t = 0; t < p.tet_count; ++t) {
      const uint32_t* q = p.corners + 4 * size_t(t);
      if (q[0] >= p.vertex_count || q[1] >= p.vertex_count || q[2] >= p.vertex_count || q[3] >= p.vertex_count) {
        bad.push_back(fmt::format("tetrahedron {} names a vertex past the cluster's {}", t, p.vertex_count));
        return;
      }
      auto at = [&](uint32_t v) { return Vec3d(pos[3 * v], pos[3 * v + 1], pos[3 * v + 2]); };
      if (!(tet_volume6(at(q[0]), at(q[1]), at(q[2]), at(q[3])) > 0)) {
        bad.push_back(fmt::format("tetrahedron {} is not positively oriented in step {}", t, s));
        break;
      }
    }
  }
}

}  // namespace

int verify_mesh(const std::string& path, const Store& store) {
  const std::vector<TetCluster>& clusters = store.clusters();
  std::mutex bad_mutex;
  std::vector<std::pair<uint64_t, std::string>> bad;
  if (store.record_count() != clusters.size())
    bad.emplace_back(clusters.size(), fmt::format("{} cluster records for {} clusters", store.record_count(), clusters.size()));
  uint64_t tets = 0;
  for (const TetCluster& c : clusters) tets += c.tets;
  if (tets != store.manifest().mesh.tets)
    bad.emplace_back(clusters.size(), fmt::format("the clusters hold {} tets, the manifest says {}", tets, store.manifest().mesh.tets));
  Progress progress("verify", clusters.size(), "clusters");
  parallel_for<size_t>(0, clusters.size(), 16, [&](size_t c0, size_t c1) {
    auto txn = store.begin_read();
    std::vector<std::byte> page(size_t(store.manifest().mesh.page_bytes));
    std::vector<std::string> problems;
    for (size_t c = c0; c < c1; ++c) {
      problems.clear();
      try {
        store.read_page(txn, {RecordKind::tet_cluster, c}, page);
        check_cluster(store, c, TetClusterPage::view(page), problems);
      } catch (const Error& e) {
        problems.push_back(e.message());
      }
      std::lock_guard lock(bad_mutex);
      for (auto& p : problems) bad.emplace_back(c, std::move(p));
    }
    progress.advance(c1 - c0);
  });
  progress.finish();
  std::sort(bad.begin(), bad.end());
  for (const auto& [c, why] : bad) std::cout << fmt::format("BAD cluster {}: {}\n", c, why);
  std::cout << fmt::format("{}: {} clusters, {} tets decoded, {} problems\n", path, clusters.size(), tets, bad.size());
  return bad.empty() ? 0 : 1;
}

namespace {

/// The store's mesh in one piece (step 0's positions).
TetMesh gather_mesh(const Store& store) {
  TetMesh mesh;
  const int steps = store.manifest().time_steps;
  mesh.scalars.resize(size_t(steps));
  const nlohmann::json source = nlohmann::json::parse(store.manifest().source);
  mesh.array_name = source.value("array", std::string("scalar"));
  if (source.contains("steps") && source["steps"].is_array())
    for (const auto& s : source["steps"]) mesh.step_names.push_back(s.get<std::string>());
  // Clusters repeat the vertices they share; one vertex per distinct position (and scalars)
  // makes the exported mesh conforming again.
  struct Key {
    std::array<float, 3> p;
    float v;
    bool operator==(const Key&) const = default;
  };
  struct Hash {
    size_t operator()(const Key& k) const {
      uint32_t w[4];
      std::memcpy(w, k.p.data(), 12);
      std::memcpy(w + 3, &k.v, 4);
      uint64_t h = 1469598103934665603ull;
      for (uint32_t x : w) h = (h ^ x) * 1099511628211ull;
      return size_t(h);
    }
  };
  std::unordered_map<Key, uint32_t, Hash> index;
  auto txn = store.begin_read();
  std::vector<std::byte> page(size_t(store.manifest().mesh.page_bytes));
  std::vector<uint32_t> local;
  for (size_t c = 0; c < store.clusters().size(); ++c) {
    store.read_page(txn, {RecordKind::tet_cluster, c}, page);
    const TetClusterPage p = TetClusterPage::view(page);
    local.resize(p.vertex_count);
    for (uint32_t v = 0; v < p.vertex_count; ++v) {
      const Key k{{p.positions[3 * v], p.positions[3 * v + 1], p.positions[3 * v + 2]}, p.values[v]};
      auto [it, added] = index.try_emplace(k, uint32_t(mesh.vertex_count()));
      if (added) {
        mesh.positions.insert(mesh.positions.end(), k.p.begin(), k.p.end());
        for (int s = 0; s < steps; ++s) mesh.scalars[size_t(s)].push_back(p.values_at(uint32_t(s))[v]);
      }
      local[v] = it->second;
    }
    for (size_t i = 0; i < 4 * size_t(p.tet_count); ++i) mesh.tets.push_back(local[p.corners[i]]);
  }
  return mesh;
}

}  // namespace

void export_mesh(const Store& store, const std::string& out, const std::string& encoding) {
  if (!(out.size() > 4 && out.substr(out.size() - 4) == ".vtu"))
    throw Error(Errc::invalid_argument, "a tetrahedral store exports to a .vtu file").with_field("--out").with_file(out);
  if (store.manifest().mesh.moving)
    throw Error(Errc::unsupported, "a .vtu holds one set of points; this mesh's vertices move (export each step from a .pvd "
                                   "is not supported yet)")
        .with_file(store.path());
  VtuWriteOptions w;
  if (encoding == "ascii") w.encoding = VtuWriteOptions::Encoding::ascii;
  else if (encoding == "binary") w.encoding = VtuWriteOptions::Encoding::binary;
  else if (encoding == "appended" || encoding == "raw") w.encoding = VtuWriteOptions::Encoding::appended_raw;
  else if (encoding == "base64") w.encoding = VtuWriteOptions::Encoding::appended_base64;
  else if (encoding == "zlib") w.encoding = VtuWriteOptions::Encoding::appended_raw, w.compress = true;
  else
    throw Error(Errc::invalid_argument, fmt::format("'{}' is not ascii, binary, appended, base64 or zlib", encoding))
        .with_field("--encoding");
  check_writable(out);  // before the whole mesh is gathered
  const TetMesh mesh = gather_mesh(store);
  write_vtu(out, mesh, w);
  std::cout << fmt::format("wrote {} ({} tets, {} vertices, {} time step{})\n", out, mesh.tet_count(), mesh.vertex_count(),
                           mesh.time_steps(), mesh.time_steps() == 1 ? "" : "s");
}

}  // namespace brickyard::cli
