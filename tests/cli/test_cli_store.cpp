// End-to-end tests of import, info, verify and export, as a user runs them.

#include <gtest/gtest.h>

#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <thread>
#include <vector>

#include <fmt/format.h>

#include "core/error.h"
#include "preprocess/builder.h"
#include "preprocess/builder_test_util.h"
#include "preprocess/volume_source.h"
#include "storage/store.h"
#include "storage/lmdb_env.h"
#include "store_damage.h"
#include "storage/store_lock.h"
#include "stops_halfway.h"
#include "test_util.h"

extern char** environ;

namespace brickyard {
namespace {

const std::string kExe = BRICKYARD_EXE;

testing::CommandResult brickyard(const std::string& args) { return testing::run_command(kExe + " " + args); }
bool contains(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

void write_floats(const std::string& path, const std::vector<float>& v) {
  std::ofstream out(path, std::ios::binary);
  out.write(reinterpret_cast<const char*>(v.data()), std::streamsize(v.size() * 4));
}

TEST(CliStore, ImportInfoVerifyExportRoundTrip) {
  testing::TempDir dir;
  ASSERT_EQ(brickyard("-q generate gyroid --size 70,50,40 --type u16 --out " + dir.file("g.raw")).exit_code, 0);
  auto r = brickyard("import " + dir.file("g.raw") + " --out " + dir.file("s") + " --brick-size 16");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(contains(r.output, "70x50x40 u16")) << r.output;
  EXPECT_TRUE(contains(r.output, "import g.raw: 273 KiB in")) << r.output;  // of input, with its rate

  r = brickyard("info " + dir.file("s"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  for (const char* part : {": complete, format version 1", "volume 70x50x40 u16", "bricks 16^3 + apron 1, lz4 after byte-shuffle",
                           "4 levels", "level", "constant", "ratio", "histogram [", "quantiles p1", "\"kind\":\"raw\""})
    EXPECT_TRUE(contains(r.output, part)) << part << " missing from\n" << r.output;
  r = brickyard("info --json " + dir.file("s"));
  EXPECT_TRUE(contains(r.output, "\"complete\": true")) << r.output;

  r = brickyard("verify " + dir.file("s"));
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(contains(r.output, "0 problems")) << r.output;

  r = brickyard("export " + dir.file("s") + " --out " + dir.file("back.raw"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(testing::read_file(dir.file("back.raw")), testing::read_file(dir.file("g.raw")));
  r = brickyard("export " + dir.file("s") + " --level 1 --box 1,2,3,9,8,7 --out " + dir.file("box.raw"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(std::filesystem::file_size(dir.file("box.raw")), size_t(8 * 6 * 4 * 2));
  r = brickyard("export " + dir.file("s") + " --level 7 --out " + dir.file("x.raw"));
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_TRUE(contains(r.output, "level 7 does not exist (the store has levels 0 to 3)")) << r.output;

  // Same command again, even on the same data regenerated (a new mtime, the same checksum):
  // nothing to do. Other parameters: refused without --force.
  ASSERT_EQ(brickyard("-q generate gyroid --size 70,50,40 --type u16 --out " + dir.file("g.raw")).exit_code, 0);
  r = brickyard("import " + dir.file("g.raw") + " --out " + dir.file("s") + " --brick-size 16");
  EXPECT_EQ(r.exit_code, 0);
  EXPECT_TRUE(contains(r.output, "complete and up to date")) << r.output;
  EXPECT_FALSE(contains(r.output, "import g.raw:")) << r.output;  // no progress line for no work
  r = brickyard("import " + dir.file("g.raw") + " --out " + dir.file("s") + " --brick-size 32");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_TRUE(contains(r.output, "pass --force")) << r.output;
}

TEST(CliStore, ImportsProceduralFieldsDirectly) {
  testing::TempDir dir;
  auto r = brickyard("-q import field:sparse-blobs --size 64 --type u8 --out " + dir.file("s"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  r = brickyard("info " + dir.file("s"));
  EXPECT_TRUE(contains(r.output, "\"field\":\"sparse-blobs\"")) << r.output;
  EXPECT_EQ(brickyard("verify " + dir.file("s")).exit_code, 0);
}

TEST(CliStore, ImportOctreeInfoVerifyAndRenderIt) {
  testing::TempDir dir;
  auto r = brickyard("-q import field:sparse-blobs --size 48 --type u8 --brick-size 16 --octree --out " + dir.file("s"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(contains(r.output, "wrote the octree of")) << r.output;
  r = brickyard("info " + dir.file("s"));
  for (const char* part : {"octree depth 6: ", "subtrees consolidated", "of the raw grid's 108 KiB", "lossless"})
    EXPECT_TRUE(contains(r.output, part)) << part << " missing from\n" << r.output;
  r = brickyard("verify " + dir.file("s"));
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(contains(r.output, "pages decoded, 0 problems")) << r.output;
  // The same import again: nothing to do, the octree is there.
  r = brickyard("import field:sparse-blobs --size 48 --type u8 --brick-size 16 --octree --out " + dir.file("s"));
  EXPECT_TRUE(contains(r.output, "nothing to do")) << r.output;
  // Lossy and clamped rebuilds say what they did.
  r = brickyard("-q build-octree " + dir.file("s") + " --tolerance 8 --range 10,200");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(contains(r.output, "lossy, tolerance 8, largest error")) << r.output;
  EXPECT_TRUE(contains(r.output, "values clamped into [10, 200]")) << r.output;
  r = brickyard("-q build-octree " + dir.file("s") + " --range 5,1");
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_TRUE(contains(r.output, "--range")) << r.output;
  r = brickyard("-q build-octree " + dir.file("nothing"));
  EXPECT_NE(r.exit_code, 0);
  EXPECT_TRUE(contains(r.output, "no such store")) << r.output;

  std::ofstream(dir.file("scene.json")) << R"({"dataset": "s", "backend": "octree_cgt", "image": {"width": 32, "height": 32},
      "camera": {"eye": [1.6, -1.1, 1.4], "target": [0.5, 0.5, 0.5]}, "mode": "iso", "values": "normalized",
      "isosurfaces": [{"value": 0.4}]})";
  r = brickyard("-q render " + dir.file("scene.json") + " -o " + dir.file("o.png"));
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(std::filesystem::exists(dir.file("o.png")));
}

struct BadImport {
  const char* name;
  const char* setup;  // raw file content kind
  const char* args;
  const char* message;
};

class CliImportRejects : public ::testing::TestWithParam<BadImport> {};

TEST_P(CliImportRejects, WithAClearMessageAndNoCompleteStore) {
  testing::TempDir dir;
  std::ofstream(dir.file("v.raw"), std::ios::binary) << std::string(1000, '\x01');
  std::string args = GetParam().args;
  for (const std::string ph : {"RAW", "OUT", "DIR"}) {
    const std::string value = ph == "RAW" ? dir.file("v.raw") : ph == "OUT" ? dir.file("s") : dir.path().string();
    for (size_t at; (at = args.find(ph)) != std::string::npos;) args.replace(at, ph.size(), value);
  }
  auto r = brickyard(args);
  EXPECT_NE(r.exit_code, 0) << r.output;
  EXPECT_TRUE(contains(r.output, GetParam().message)) << "expected '" << GetParam().message << "' in:\n" << r.output;
  EXPECT_NE(probe_store(dir.file("s")), StoreState::complete);
}

INSTANTIATE_TEST_SUITE_P(
    Import, CliImportRejects,
    ::testing::Values(
        BadImport{"truncated", "", "import RAW --dims 10,10,20 --type u8 --out OUT", "file is truncated: 1000 bytes, but 10x10x20 u8 needs 2000"},
        BadImport{"too_long", "", "import RAW --dims 10,10,5 --type u8 --out OUT", "larger than its dims say"},
        BadImport{"dims_overflow", "", "import RAW --dims 4000000000,4000000000,4000000000 --type u16 --out OUT", "overflow a 64-bit byte count"},
        BadImport{"unknown_type", "", "import RAW --dims 10,10,10 --type u64 --out OUT", "unknown value type 'u64'"},
        BadImport{"no_description", "", "import RAW --out OUT", "needs --dims and --type, or a sidecar"},
        BadImport{"missing_file", "", "import DIR/nothing.raw --dims 4 --type u8 --out OUT", "nothing.raw: cannot open"},
        BadImport{"bad_codec", "", "import RAW --dims 10 --type u8 --codec zstd --out OUT", "unknown codec 'zstd'"},
        BadImport{"bad_brick_size", "", "import RAW --dims 10 --type u8 --brick-size 24 --out OUT", "not a power of two in [8, 128]"},
        BadImport{"bad_range", "", "import RAW --dims 10 --type u8 --range 5,1 --out OUT", "'5,1' is not LO,HI"},
        BadImport{"not_a_vdb", "", "import RAW.vdb --out OUT", "v.raw.vdb"},
        BadImport{"zero_spacing", "", "import RAW --dims 10 --type u8 --spacing 0,0,0 --out OUT", "field '--spacing': spacing (0, 0, 0): every axis needs a positive, finite distance"},
        BadImport{"negative_spacing", "", "import RAW --dims 10 --type u8 --spacing 1,-1,1 --out OUT", "field '--spacing': spacing (1, -1, 1)"},
        BadImport{"full_map", "", "import field:fbm --size 96 --type f32 --map-size 256KiB --no-map-growth --out OUT", "store is full"}),
    [](const auto& param_info) { return std::string(param_info.param.name); });

TEST(CliStore, NonFiniteVoxelsAreRejectedOrRepaired) {
  testing::TempDir dir;
  std::vector<float> v(8 * 8 * 8, 1.0f);
  v[3 + 8 * (2 + 8 * 1)] = std::numeric_limits<float>::quiet_NaN();  // (3, 2, 1)
  v[100] = std::numeric_limits<float>::infinity();
  v[200] = 5.0f;
  v[300] = -2.0f;
  write_floats(dir.file("n.raw"), v);
  const std::string base = "import " + dir.file("n.raw") + " --dims 8 --type f32 --brick-size 8 ";
  auto r = brickyard(base + "--out " + dir.file("s"));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_TRUE(contains(r.output, "2 non-finite voxels (NaN or infinity), the first at (3, 2, 1)")) << r.output;
  EXPECT_FALSE(std::filesystem::exists(dir.file("s")));  // rejected before anything was written

  ASSERT_EQ(brickyard(base + "--nonfinite zero --out " + dir.file("z")).exit_code, 0);
  ASSERT_EQ(brickyard("-q export " + dir.file("z") + " --out " + dir.file("z.raw")).exit_code, 0);
  std::vector<float> z(v.size());
  std::ifstream(dir.file("z.raw"), std::ios::binary).read(reinterpret_cast<char*>(z.data()), std::streamsize(z.size() * 4));
  EXPECT_EQ(z[3 + 8 * (2 + 8 * 1)], 0.0f);
  EXPECT_EQ(z[100], 0.0f);
  EXPECT_EQ(z[200], 5.0f);

  ASSERT_EQ(brickyard(base + "--nonfinite clamp --out " + dir.file("c")).exit_code, 0);
  ASSERT_EQ(brickyard("-q export " + dir.file("c") + " --out " + dir.file("c.raw")).exit_code, 0);
  std::ifstream(dir.file("c.raw"), std::ios::binary).read(reinterpret_cast<char*>(z.data()), std::streamsize(z.size() * 4));
  EXPECT_EQ(z[100], 5.0f);  // +inf -> the largest finite value
  EXPECT_EQ(z[3 + 8 * (2 + 8 * 1)], 0.0f);
}

TEST(CliStore, DirectoriesThatAreNotStoresAndNewerFormatsAreRefused) {
  testing::TempDir dir;
  std::filesystem::create_directories(dir.file("plain"));
  auto r = brickyard("info " + dir.file("plain"));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_TRUE(contains(r.output, "plain: not a brickyard store (no data.mdb)")) << r.output;
  r = brickyard("verify " + dir.file("missing"));
  EXPECT_TRUE(contains(r.output, "missing: no such store")) << r.output;

  ASSERT_EQ(brickyard("-q import field:sphere --size 16 --type u8 --out " + dir.file("s")).exit_code, 0);
  {
    lmdb::Env env(dir.file("s"), {});
    auto db = env.open_database(kManifestDb, false);
    std::string text;
    {
      lmdb::ReadTxn txn(env);
      auto v = txn.get(db, lmdb::as_bytes("manifest"));
      text.assign(reinterpret_cast<const char*>(v->data()), v->size());
    }
    text.replace(text.find("\"format_version\": 1"), 19, "\"format_version\": 99");
    lmdb::BatchWriter w(env);
    w.put(db, lmdb::as_bytes("manifest"), lmdb::as_bytes(text));
    w.erase(db, lmdb::as_bytes("manifest.xxh3"));  // as a build that checks no checksum wrote it
    w.commit();
  }
  r = brickyard("info " + dir.file("s"));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_TRUE(contains(r.output, "store format version 99 is newer than this build reads (3)")) << r.output;
}

TEST(CliStore, VerifyNamesACorruptedBrick) {
  testing::TempDir dir;
  ASSERT_EQ(brickyard("-q import field:fbm --size 40 --type u8 --brick-size 16 --out " + dir.file("s")).exit_code, 0);
  // Flip bytes inside one brick's payload, in LMDB's data file, behind the library's back.
  const std::string header = testing::corrupt_first_brick(dir.file("s/data.mdb"), 40, 8);
  ASSERT_EQ(header.size(), 28u);
  BrickHeader h{};
  std::memcpy(&h, header.data(), header.size());
  auto r = brickyard("verify " + dir.file("s"));
  EXPECT_EQ(r.exit_code, 1) << r.output;
  const std::string key = BrickKey{h.level, h.x, h.y, h.z}.to_string();
  EXPECT_TRUE(contains(r.output, "BAD " + key + ": ")) << key << " not named in:\n" << r.output;
  EXPECT_TRUE(contains(r.output, "1 problems")) << r.output;
}

TEST(CliStore, AFlippedBitInTheManifestOrATableIsACorruptStoreNamedAsSuch) {
  // Before, the tables and the manifest had no checksum: a flipped bit in a node's range
  // skipped its brick, or drew a constant that is not there, with nothing said.
  testing::TempDir dir;
  const std::string clean = dir.file("clean");
  ASSERT_EQ(brickyard("-q import field:fbm --size 40 --type f32 --brick-size 16 --octree --out " + clean).exit_code, 0);
  struct Case {
    std::string database;
    std::vector<std::byte> key;
    std::string named;
  };
  const std::string manifest = "manifest";
  const std::vector<Case> cases = {
      {"manifest", std::vector<std::byte>(reinterpret_cast<const std::byte*>(manifest.data()),
                                          reinterpret_cast<const std::byte*>(manifest.data() + manifest.size())),
       "the manifest fails its checksum"},
      {"nodes", testing::big_endian_key(uint64_t(2) << 32), "node table chunk 0 of level 2 fails its checksum"},  // level 2, chunk 0
      {"octree", testing::big_endian_key(uint64_t(0xff) << 56), "octree page table chunk 0 fails its checksum"},
  };
  for (const Case& c : cases)
    for (uint64_t bit : {uint64_t(5), uint64_t(123), uint64_t(1) << 40}) {  // the last: the record's last byte
      const std::string store = dir.file(fmt::format("{}_{}", c.database, bit));
      std::filesystem::copy(clean, store);
      ASSERT_GT(testing::flip_record_bit(store, c.database, c.key, bit), 0u);
      for (const std::string command : {"info", "verify"}) {
        const auto r = brickyard(command + " " + store);
        EXPECT_EQ(r.exit_code, 1) << command << " " << store << "\n" << r.output;
        EXPECT_TRUE(contains(r.output, store + ": ")) << r.output;
        EXPECT_TRUE(contains(r.output, c.named)) << c.named << " not in:\n" << r.output;
      }
    }
}

TEST(CliStore, KilledImportLeavesAnIncompleteStoreAndTheRerunEqualsACleanBuild) {
  testing::TempDir dir;
  const std::string store = dir.file("s");
  const std::vector<std::string> args = {kExe, "-q", "import", "field:fbm", "--size", "256", "--type", "u8",
                                         "--brick-size", "16", "--out", store};
  std::vector<char*> argv;
  for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  pid_t pid = 0;
  ASSERT_EQ(posix_spawn(&pid, kExe.c_str(), nullptr, nullptr, argv.data(), environ), 0);
  // Kill it as soon as the store exists and holds something: mid-build.
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(30);
  std::error_code ec;
  while (std::chrono::steady_clock::now() < deadline &&
         !(std::filesystem::exists(store + "/data.mdb", ec) && std::filesystem::file_size(store + "/data.mdb", ec) > 64 * 1024))
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  ::kill(pid, SIGKILL);
  int status = 0;
  ::waitpid(pid, &status, 0);
  ASSERT_TRUE(WIFSIGNALED(status)) << "the import finished before it could be interrupted";

  auto r = brickyard("info " + store);
  EXPECT_TRUE(contains(r.output, "INCOMPLETE")) << r.output;
  r = brickyard("verify " + store);
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_TRUE(contains(r.output, "INCOMPLETE")) << r.output;
  r = brickyard("export " + store + " --out " + dir.file("x.raw"));
  EXPECT_TRUE(contains(r.output, "the store is incomplete")) << r.output;

  std::string rerun;
  for (size_t i = 1; i < args.size(); ++i) rerun += args[i] + " ";
  r = brickyard(rerun);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(contains(r.output, "interrupted earlier build was discarded and rebuilt")) << r.output;
  ASSERT_EQ(brickyard("-q import field:fbm --size 256 --type u8 --brick-size 16 --out " + dir.file("clean")).exit_code, 0);
  EXPECT_TRUE(testing::all_records(Store(store)) == testing::all_records(Store(dir.file("clean"))));
}

const char* const kBesideTheStore[] = {".s.lock", ".s.rebuilding", ".s.replaced"};

TEST(CliStore, ASecondWriterIsRefusedNamingTheFirstAndItsBuildIsNotDiscarded) {
  testing::TempDir dir;
  const std::string store = dir.file("s");
  {
    testing::StopsHalfway source("fbm", 40);
    BuildOptions o;
    o.brick_size = 16;
    EXPECT_THROW(build_store(source, store, o), Error);
  }
  ASSERT_EQ(probe_store(store), StoreState::incomplete);
  const std::string import = "import field:fbm --size 40 --type u8 --brick-size 16 --out " + store;
  const std::string pid = std::to_string(::getpid());
  {
    const StoreWriteLock live(store);  // the incomplete store is a build in progress: its writer holds it
    auto r = brickyard(import);
    EXPECT_EQ(r.exit_code, 1) << r.output;
    EXPECT_TRUE(contains(r.output, store + ": another writer (pid " + pid + ") holds this store")) << r.output;
    EXPECT_FALSE(contains(r.output, "wrote")) << r.output;
    EXPECT_FALSE(contains(r.output, "discarded")) << r.output;
    EXPECT_EQ(probe_store(store), StoreState::incomplete);
    r = brickyard("info " + store);
    EXPECT_EQ(r.exit_code, 1) << r.output;  // described, and not usable: a script must not go on to render it
    EXPECT_TRUE(contains(r.output, "INCOMPLETE (being built by process " + pid + ")")) << r.output;
    EXPECT_TRUE(contains(r.output, "it cannot be used until that build finishes")) << r.output;
    r = brickyard("verify " + store);
    EXPECT_TRUE(contains(r.output, "INCOMPLETE (being built by process " + pid + ")")) << r.output;
  }
  auto r = brickyard("info " + store);
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_TRUE(contains(r.output, "INCOMPLETE (build interrupted)")) << r.output;
  EXPECT_TRUE(contains(r.output, "run the import again to finish it")) << r.output;
  r = brickyard("info --json " + store);
  EXPECT_EQ(r.exit_code, 1) << r.output;
  r = brickyard("-q " + import);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(contains(r.output, "interrupted earlier build was discarded and rebuilt")) << r.output;

  // build-octree writes the store too.
  {
    const StoreWriteLock live(store);
    r = brickyard("-q build-octree " + store);
    EXPECT_EQ(r.exit_code, 1) << r.output;
    EXPECT_TRUE(contains(r.output, "another writer (pid " + pid + ") holds this store")) << r.output;
  }
  EXPECT_EQ(brickyard("-q build-octree " + store).exit_code, 0);
  for (const char* sibling : kBesideTheStore) EXPECT_FALSE(std::filesystem::exists(dir.file(sibling))) << sibling;
}

TEST(CliStore, AFailedForcedRebuildLeavesTheOldStoreAndACompleteOneReplacesIt) {
  testing::TempDir dir;
  const std::string store = dir.file("s");
  ASSERT_EQ(brickyard("-q import field:sphere --size 16 --type u8 --brick-size 8 --out " + store).exit_code, 0);
  const auto records = testing::all_records(Store(store));
  const std::string manifest = Store(store).manifest().to_json();

  // Bad input found during the build (the f32 pre-pass finds the NaN), after --force has
  // claimed the store: the old one must survive it.
  std::vector<float> v(8 * 8 * 8, 1.0f);
  v[5] = std::numeric_limits<float>::quiet_NaN();
  write_floats(dir.file("nan.raw"), v);
  auto r = brickyard("import " + dir.file("nan.raw") + " --dims 8 --type f32 --brick-size 8 --force --out " + store);
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_TRUE(contains(r.output, "non-finite voxels")) << r.output;
  // And bad input found before it.
  std::ofstream(dir.file("short.raw"), std::ios::binary) << std::string(100, '\x01');
  r = brickyard("import " + dir.file("short.raw") + " --dims 8 --type u8 --force --out " + store);
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_EQ(probe_store(store), StoreState::complete);
  EXPECT_TRUE(testing::all_records(Store(store)) == records);
  EXPECT_EQ(Store(store).manifest().to_json(), manifest);
  EXPECT_EQ(brickyard("verify " + store).exit_code, 0);
  for (const char* sibling : kBesideTheStore) EXPECT_FALSE(std::filesystem::exists(dir.file(sibling))) << sibling;

  r = brickyard("-q import field:fbm --size 16 --type u8 --brick-size 8 --force --out " + store);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  ASSERT_EQ(brickyard("-q import field:fbm --size 16 --type u8 --brick-size 8 --out " + dir.file("clean")).exit_code, 0);
  EXPECT_TRUE(testing::all_records(Store(store)) == testing::all_records(Store(dir.file("clean"))));
  EXPECT_TRUE(contains(Store(store).manifest().source, "fbm")) << Store(store).manifest().source;
  for (const char* sibling : kBesideTheStore) EXPECT_FALSE(std::filesystem::exists(dir.file(sibling))) << sibling;
}

TEST(CliStore, ImportsThatCannotFitAreRefusedBeforeTheyStart) {
  testing::TempDir dir;
  const std::string out = dir.file("s");
  // What is free is capped (never raised) by the environment, so the answers do not depend on
  // this machine; none of these may allocate what it asks for.
  auto import = [&](const std::string& env, const std::string& args) {
    const auto start = std::chrono::steady_clock::now();
    auto r = testing::run_command(env + " " + kExe + " import " + args + " --out " + out);
    EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(), 20.0)
        << "refused only after it started: " << args;
    return r;
  };
  auto r = import("BRICKYARD_AVAILABLE_MEMORY=1GiB BRICKYARD_AVAILABLE_DISK=1GiB", "field:fbm --size 100000 --type f32");
  EXPECT_EQ(r.exit_code, kExitOutOfResources) << r.output;
  for (const char* part : {"import of 100000x100000x100000 f32 needs up to", "of disk (every brick at LZ4's worst case",
                           "but 1 GiB is free there", "of memory", "but 1 GiB is available", "--brick-size"})
    EXPECT_TRUE(contains(r.output, part)) << part << " missing from\n" << r.output;
  EXPECT_FALSE(contains(r.output, "bad_alloc")) << r.output;

  r = import("BRICKYARD_AVAILABLE_DISK=1GiB", "field:fbm --size 8192 --type u8");
  EXPECT_EQ(r.exit_code, kExitOutOfResources) << r.output;
  for (const std::string& part : {out + ": import of 8192x8192x8192 u8 needs up to", std::string("of disk"),
                                 std::string("but 1 GiB is free there"), std::string("--no-disk-check")})
    EXPECT_TRUE(contains(r.output, part)) << part << " missing from\n" << r.output;

  // Past the disk check, memory still holds it back.
  r = import("BRICKYARD_AVAILABLE_MEMORY=1GiB", "field:fbm --size 8192 --type u8 --no-disk-check");
  EXPECT_EQ(r.exit_code, kExitOutOfResources) << r.output;
  for (const char* part : {"import of 8192x8192x8192 u8 needs about", "of memory", "but 1 GiB is available",
                           "a smaller --brick-size"})
    EXPECT_TRUE(contains(r.output, part)) << part << " missing from\n" << r.output;
  EXPECT_FALSE(contains(r.output, "of disk")) << r.output;

  EXPECT_FALSE(std::filesystem::exists(out));
  for (const char* sibling : kBesideTheStore) EXPECT_FALSE(std::filesystem::exists(dir.file(sibling))) << sibling;
}

}  // namespace
}  // namespace brickyard

namespace brickyard {
namespace {

TEST(CliStore, ASidecarMustDescribeItsFileExactly) {
  testing::TempDir dir;
  const std::string raw = dir.file("v.raw");
  ASSERT_EQ(brickyard("-q generate sphere --size 16 --type u8 --out " + raw).exit_code, 0);
  ASSERT_EQ(brickyard("-q import " + raw + " --out " + dir.file("ok")).exit_code, 0);
  {
    std::fstream f(raw, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(100);
    f.put('\x7f');
  }
  auto r = brickyard("-q import " + raw + " --out " + dir.file("changed"));
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_TRUE(contains(r.output, raw + ": field 'xxh3_64': the file's XXH3-64 is")) << r.output;
  EXPECT_TRUE(contains(r.output, "the file changed since the sidecar was written")) << r.output;
  EXPECT_FALSE(std::filesystem::exists(dir.file("changed")));
  // Described by flags instead, the file imports as it is now.
  r = brickyard("-q import " + raw + " --dims 16 --type u8 --out " + dir.file("as_is"));
  EXPECT_EQ(r.exit_code, 0) << r.output;

  std::string sidecar = testing::read_file(raw + ".json");
  sidecar.insert(sidecar.find('{') + 1, "\"spacng\": [1, 1, 1], ");
  std::ofstream(raw + ".json") << sidecar;
  r = brickyard("-q import " + raw + " --out " + dir.file("typo"));
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_TRUE(contains(r.output, raw + ".json: field 'spacng': unknown key")) << r.output;
}

TEST(CliStore, ExportRefusesLevelsThatDoNotExistAndNamesItDoesNotWrite) {
  testing::TempDir dir;
  ASSERT_EQ(brickyard("-q import field:sphere --size 32 --type u8 --brick-size 16 --out " + dir.file("s")).exit_code, 0);
  auto r = brickyard("-q export " + dir.file("s") + " --level -1 --out " + dir.file("x.raw"));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_TRUE(contains(r.output, "field '--level': level -1 does not exist (the store has levels 0 to")) << r.output;
  r = brickyard("-q export " + dir.file("s") + " --level 9 --out " + dir.file("x.raw"));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  r = brickyard("-q export " + dir.file("s") + " --out " + dir.file("x.png"));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_TRUE(contains(r.output, "field '--out': a grid exports to raw bytes (.raw, .bin or .dat")) << r.output;
  EXPECT_TRUE(contains(r.output, "'.png' is neither")) << r.output;
  EXPECT_FALSE(std::filesystem::exists(dir.file("x.png")));
  EXPECT_FALSE(std::filesystem::exists(dir.file("x.raw")));
  r = brickyard("-q export " + dir.file("s") + " --level 0 --out " + dir.file("x.bin"));
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(std::filesystem::exists(dir.file("x.bin.json")));
}

}  // namespace
}  // namespace brickyard
