// Corruption drill (issue 42): random bit flips in a store's records (bricks, octree pages, tet
// clusters, the node, octree and cluster tables, the manifest), each in a fresh copy, then
// `brickyard verify` and `brickyard render` with every back end, as a user would run them.
//
//   corruption_drill BRICKYARD WORKDIR [FLIPS [SEED]]
//
// A flip must end one of these ways, or the drill fails (exit 1), printing the case:
// - verify exits 1 naming the damaged record, or exits 0 when no decoded byte changed (a flip
//   in a header's reserved bytes or its own min/max, which nothing reads: counted apart);
// - each render exits 0 (it read nothing damaged), 3 naming the damaged record (the one policy:
//   drawn around, reported), or 1 with brickyard's own error naming the store where the store
//   cannot be opened (a damaged manifest or table); never a crash, never another exit status.
// It prints k of n per record kind. ctest runs a few dozen flips; the note's figures come from
// `build/tests/corruption_drill build/bin/brickyard /tmp/drill 1000`.

#include <sys/wait.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <random>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "core/brick_key.h"
#include "storage/lmdb_env.h"

namespace fs = std::filesystem;
using namespace brickyard;

namespace {

struct Run {
  int status = -1;  // exit status, or 128 + signal
  std::string output;
};

Run run(const std::string& command) {
  Run r;
  std::FILE* pipe = ::popen((command + " 2>&1").c_str(), "r");
  if (!pipe) return r;
  char buf[4096];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, pipe)) > 0) r.output.append(buf, n);
  const int status = ::pclose(pipe);
  r.status = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  return r;
}

bool contains(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

uint64_t big_endian(std::span<const std::byte> key) {
  uint64_t v = 0;
  for (std::byte b : key) v = v << 8 | uint64_t(b);
  return v;
}

/// What a flip hit, and the words its report must hold.
struct Target {
  std::string kind;  // brick, octree page, tet cluster, node table, octree table, cluster table, manifest
  std::string database;
  std::vector<std::byte> key;
  std::string named;  // the record as verify and render name it
};

std::vector<Target> targets_of(const std::string& store, bool mesh) {
  lmdb::Env env(store, {.read_only = true});
  std::vector<Target> out;
  const auto scan = [&](const std::string& database, auto&& classify) {
    const lmdb::Database db = env.open_database(database, false);
    lmdb::ReadTxn txn(env);
    txn.for_each(db, [&](lmdb::Bytes key, lmdb::Bytes) {
      Target t{"", database, std::vector<std::byte>(key.begin(), key.end()), ""};
      classify(t);
      out.push_back(std::move(t));
      return true;
    });
  };
  scan("manifest", [](Target& t) { t.kind = "manifest", t.named = "manifest"; });
  if (mesh) {
    scan("tets", [](Target& t) { t.kind = "tet cluster", t.named = fmt::format("cluster {}", big_endian(t.key)); });
    scan("tet_clusters", [](Target& t) { t.kind = "cluster table", t.named = "chunk"; });
    return out;
  }
  scan("bricks", [](Target& t) {
    t.kind = "brick";
    t.named = BrickKey::from_bytes(reinterpret_cast<const uint8_t*>(t.key.data())).to_string();
  });
  scan("nodes", [](Target& t) { t.kind = "node table", t.named = "node table chunk"; });
  scan("octree", [](Target& t) {
    const uint64_t id = big_endian(t.key);
    if (id >> 56 == 0xff) t.kind = "octree table", t.named = "octree page table chunk";
    else {
      const BrickKey k = BrickKey::from_code(id);  // a page's id is its root's (depth, coordinates)
      t.kind = "octree page", t.named = fmt::format("octree page depth {} ({}, {}, {})", k.level, k.x, k.y, k.z);
    }
  });
  return out;
}

size_t flip(const std::string& store, const Target& t, std::mt19937_64& rng, uint64_t* bit_out) {
  lmdb::Env env(store, {});
  const lmdb::Database db = env.open_database(t.database, false);
  std::vector<std::byte> value;
  {
    lmdb::ReadTxn txn(env);
    const auto v = txn.get(db, t.key);
    if (!v) return 0;
    value.assign(v->begin(), v->end());
  }
  const uint64_t bit = std::uniform_int_distribution<uint64_t>(0, 8 * value.size() - 1)(rng);
  value[size_t(bit / 8)] ^= std::byte(1u << (bit % 8));
  lmdb::BatchWriter writer(env);
  writer.put(db, t.key, std::move(value));
  writer.commit();
  *bit_out = bit;
  return size_t(bit / 8);
}

struct Tally {
  int flips = 0, named = 0, unchanged = 0, renders = 0, drawn_around = 0, refused = 0, untouched = 0, failures = 0;
};

}  // namespace

int main(int argc, char** argv) {
  if (argc < 3) {
    std::cerr << "usage: corruption_drill BRICKYARD WORKDIR [FLIPS [SEED]]\n";
    return 2;
  }
  const std::string by = argv[1], work = argv[2];
  const int flips = argc > 3 ? std::atoi(argv[3]) : 40;
  std::mt19937_64 rng(argc > 4 ? std::strtoull(argv[4], nullptr, 10) : 42);
  fs::remove_all(work);
  fs::create_directories(work);
  const std::string grid = work + "/grid", mesh = work + "/mesh";
  for (const std::string& cmd : {fmt::format("{} -q import field:fbm --size 48 --type f32 --brick-size 16 --octree --out {}", by, grid),
                                 fmt::format("{} -q import mesh:sphere --cells 10 --cluster-tets 256 --out {}", by, mesh)}) {
    const Run r = run(cmd);
    if (r.status != 0) {
      std::cerr << cmd << " failed:\n" << r.output;
      return 1;
    }
  }
  const std::string camera = R"("camera": {"eye": [1.8, -1.2, 1.4], "target": [0.5, 0.5, 0.5], "fov_degrees": 40})";
  const auto write_scene = [&](const std::string& name, const std::string& dataset, const std::string& body) {
    std::ofstream(work + "/" + name) << "{\"dataset\": \"" << dataset << R"(", "image": {"width": 32, "height": 32}, )" << camera
                                     << ", " << body << R"(, "quality": {"lod_ratio": 0.01}})" << "\n";
    return work + "/" + name;
  };
  const std::string copy = work + "/copy";
  const std::string grid_scene = write_scene("grid.json", "copy", R"("mode": "iso", "isosurfaces": [{"value": 0.5}])");
  const std::string mesh_scene = write_scene("mesh.json", "copy", R"("mode": "iso", "isosurfaces": [{"value": 0.3}])");
  const std::vector<std::string> grid_backends = {"raymarch", "reference", "gobbetti", "gigavoxels", "octree_cgt"};
  const std::vector<std::string> mesh_backends = {"tet_bvh", "reference"};
  const std::vector<Target> grid_targets = targets_of(grid, false), mesh_targets = targets_of(mesh, true);

  std::map<std::string, Tally> tally;
  for (int i = 0; i < flips; ++i) {
    const bool on_mesh = i % 5 == 4;  // a fifth of the flips on the mesh store
    const std::vector<Target>& targets = on_mesh ? mesh_targets : grid_targets;
    // Half the flips on records, half spread over the kinds, so that the few table and
    // manifest records are hit often enough to count.
    std::map<std::string, std::vector<const Target*>> by_kind;
    for (const Target& t : targets) by_kind[t.kind].push_back(&t);
    const Target* t = nullptr;
    if (rng() % 2) {
      t = &targets[rng() % targets.size()];
    } else {
      auto it = by_kind.begin();
      std::advance(it, long(rng() % by_kind.size()));
      t = it->second[rng() % it->second.size()];
    }
    fs::remove_all(copy);
    fs::copy(on_mesh ? mesh : grid, copy);
    uint64_t bit = 0;
    const size_t byte = flip(copy, *t, rng, &bit);
    Tally& k = tally[t->kind];
    ++k.flips;
    const std::string what = fmt::format("flip {}: {} {} bit {} (byte {})", i, t->kind, t->named, bit, byte);
    const auto fail = [&](const std::string& why, const Run& r) {
      ++k.failures;
      std::cout << "FAIL " << what << ": " << why << " (exit " << r.status << ")\n" << r.output << "\n";
    };
    const Run v = run(fmt::format("{} -q verify {}", by, copy));
    const bool record = t->kind == "brick" || t->kind == "octree page" || t->kind == "tet cluster";
    if (v.status == 1 && contains(v.output, t->named)) ++k.named;
    else if (v.status == 0 && record) ++k.unchanged;  // its checksum held: no decoded byte changed
    else fail("verify did not name it", v);
    for (const std::string& backend : on_mesh ? mesh_backends : grid_backends) {
      const Run r = run(fmt::format("{} -q render {} --backend {} -o {}/out.png", by, on_mesh ? mesh_scene : grid_scene, backend, work));
      ++k.renders;
      if (r.status == 0) ++k.untouched;
      else if (r.status == 3 && contains(r.output, t->named) && contains(r.output, "could not be read")) ++k.drawn_around;
      else if (r.status == 1 && !record && contains(r.output, "brickyard: error: " + copy + ": ")) ++k.refused;
      else fail(backend + " broke the policy", r);
    }
  }
  int failures = 0;
  std::cout << fmt::format("{:<14} {:>6} {:>14} {:>12} {:>8} {:>13} {:>8} {:>10} {:>9}\n", "record", "flips", "verify named",
                           "unchanged", "renders", "drawn around", "refused", "untouched", "failures");
  for (const auto& [kind, k] : tally) {
    std::cout << fmt::format("{:<14} {:>6} {:>14} {:>12} {:>8} {:>13} {:>8} {:>10} {:>9}\n", kind, k.flips, k.named, k.unchanged,
                             k.renders, k.drawn_around, k.refused, k.untouched, k.failures);
    failures += k.failures;
  }
  std::cout << (failures ? fmt::format("{} failures\n", failures) : std::string("all flips handled\n"));
  return failures ? 1 : 0;
}
