// Concurrency drill (issue 42, item 4): readers rendering while verify runs on the same store and
// a writer imports into another, and readers opening stores while they are written. Labelled
// threads, so the TSan preset runs it (build-tsan: `ctest --preset tsan -R ConcurrencyDrill`).
//
// - BackEndsRenderWhileVerifyReadsTheStoreAndAnotherIsImported: one Store (LMDB allows one
//   environment per directory per process), a cache and a back end per thread (raymarch,
//   reference, gobbetti, gigavoxels, octree_cgt) flying random cameras with thrash, a thread
//   fetching random pages through a cache of its own and comparing them with the reference
//   decode, a thread verifying every record of the store in process and another running
//   `brickyard verify` on it, and a thread importing (and --force rebuilding) a second store.
//   After the flights, each back end's settled frame from a fresh cache equals the frame it
//   rendered before anything ran beside it, bit for bit.
// - AStoreOpenedWhileItIsWrittenIsAClearErrorOrWholeAndMatching: `brickyard import --octree`,
//   then an `import --force` of another field, then `build-octree`, each in a child process,
//   while this process opens the store over and over: every open is a clear error (no store
//   yet, incomplete) or a complete store whose every record decodes and equals a reference
//   build's, record for record (never a half-written one).
// - AReaderReadsAStoreWholeWhileAnotherIsRebuilt: this process reads one store whole over and
//   over while child processes rebuild another.

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>

#include <atomic>
#include <chrono>
#include <map>
#include <mutex>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include <fmt/format.h>
#include <gtest/gtest.h>

#include "bench/soak.h"
#include "cache/brick_cache.h"
#include "core/error.h"
#include "preprocess/builder.h"
#include "preprocess/octree_builder.h"
#include "preprocess/volume_source.h"
#include "render_test_util.h"
#include "renderers/common/render.h"
#include "storage/store.h"
#include "test_util.h"

extern char** environ;

namespace brickyard {
namespace {

#if defined(__SANITIZE_THREAD__)
constexpr bool kSanitized = true;
#elif defined(__has_feature)
#if __has_feature(thread_sanitizer)
constexpr bool kSanitized = true;
#else
constexpr bool kSanitized = false;
#endif
#else
constexpr bool kSanitized = false;
#endif

using Clock = std::chrono::steady_clock;

// --- child processes ---------------------------------------------------------------------

/// Starts `args` with stdout and stderr into `log`; the child's pid.
pid_t spawn(const std::vector<std::string>& args, const std::string& log) {
  std::vector<char*> argv;
  for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, 1, log.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
  posix_spawn_file_actions_adddup2(&actions, 1, 2);
  pid_t pid = -1;
  const int rc = posix_spawn(&pid, argv[0], &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  return rc == 0 ? pid : -1;
}

/// The exit status of a child that has ended (128 + signal when killed), or -1 while it runs.
int poll_exit(pid_t pid) {
  int status = 0;
  if (::waitpid(pid, &status, WNOHANG) != pid) return -1;
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
}

// --- what a store holds --------------------------------------------------------------------

/// Every record of a grid store, decoded: the node table, the bricks, the octree pages.
struct StoreImage {
  std::string source;
  std::vector<std::vector<NodeRecord>> nodes;
  std::map<uint64_t, std::vector<std::byte>> bricks;
  std::map<uint64_t, std::vector<std::byte>> octree;
  bool has_octree = false;
};

/// Reads and decodes every record of an open store in one read snapshot. Throws the store's
/// Error for a record that does not decode (checksum, header, size).
StoreImage read_whole(const Store& store) {
  StoreImage img;
  img.source = store.manifest().source;
  for (int l = 0; l < store.layout().levels; ++l) img.nodes.push_back(store.nodes().level(l));
  const lmdb::ReadTxn txn = store.begin_read();
  std::vector<std::byte> out(store.format().bytes());
  store.for_each_record(txn, [&](const BrickKey& k, std::span<const std::byte> record) {
    decode_brick(store.format(), k, record, out);
    img.bricks.emplace(k.code(), out);
    return true;
  });
  img.has_octree = store.has_octree();
  if (img.has_octree) {
    std::vector<std::byte> page(store.dataset().octree().page_bytes());
    for (const OctreePageRange& p : store.octree_pages()) {
      store.read_page(txn, {RecordKind::octree_page, p.id}, page);
      img.octree.emplace(p.id, page);
    }
  }
  return img;
}

/// Whether `seen` is `ref`, record for record (its octree too, when `seen` has one).
bool same_records(const StoreImage& seen, const StoreImage& ref, std::string* why) {
  if (seen.source != ref.source) return *why = "another source", false;
  if (seen.nodes != ref.nodes) return *why = "another node table", false;
  if (seen.bricks != ref.bricks) return *why = fmt::format("{} bricks, the reference {}, or other bytes", seen.bricks.size(), ref.bricks.size()), false;
  if (seen.has_octree && seen.octree != ref.octree) return *why = "other octree pages", false;
  return true;
}

// --- a back end on a store shared with other threads ---------------------------------------

/// A cache and a back end over a Store another thread may be reading: what RenderSession
/// composes, without opening the store again (one LMDB environment per directory per process).
class Reader {
 public:
  Reader(const Store& store, const Scene& scene, const std::string& backend, CacheConfig config) : scene_(scene) {
    normalize_values(scene_, store.dataset().info().min_value, store.dataset().info().max_value);
    const BackendEntry& e = backends().find(backend);
    const BackendParams params(e.info, {});
    for (const PageKindInfo& k : store.page_kinds())
      if (std::find(e.info.records.begin(), e.info.records.end(), k.kind) == e.info.records.end())
        config.kinds[k.kind] = KindBudget{1, k.page_bytes, k.page_bytes};
    config = share_l1_budget(config, store.dataset().grid().shape().bytes(), e.info, params);
    pages_ = std::make_unique<PageCache>(store, config);
    bricks_ = std::make_unique<BrickCache>(*pages_, store.dataset().grid());
    context_ = std::make_unique<RenderContext>(scene_, store.dataset(), *pages_, bricks_.get());
    renderer_ = e.create(*context_, params);
  }
  ~Reader() { renderer_.reset(); }

  FrameStats render(const Camera& camera, int frame, FrameBuffers& out) {
    FrameSetup s;
    s.camera = camera;
    s.width = scene_.width;
    s.height = scene_.height;
    s.frame = frame;
    return render_frame(*renderer_, *context_, s, out);
  }
  /// RenderSession::settle(Settle::complete), then the frame as it is shown.
  void render_settled(const Camera& camera, FrameBuffers& out) {
    renderer_->set_complete_frames(true);
    bool completing = true;
    for (int n = 0; n < 500; ++n) {
      render(camera, n, out);
      pages_->wait_idle();
      if (!renderer_->converged()) continue;
      if (!completing) break;
      completing = false;
      renderer_->set_complete_frames(false);
    }
    renderer_->set_complete_frames(false);
    render(camera, 1000, out);
  }
  const Box3d& world() const { return context_->geometry().world; }
  PageCache& pages() { return *pages_; }

 private:
  Scene scene_;
  std::unique_ptr<PageCache> pages_;
  std::unique_ptr<BrickCache> bricks_;
  std::unique_ptr<RenderContext> context_;
  std::unique_ptr<Renderer> renderer_;
};

CacheConfig budgets(uint64_t l1, uint64_t l2) {
  CacheConfig c;
  c.l1_bytes = l1;
  c.l2_bytes = l2;
  return c;
}

Scene iso_scene(const std::string& store, int size) {
  return parse_scene(fmt::format(R"({{"dataset": "{}", "image": {{"width": {}, "height": {}}}, "mode": "iso", "values": "normalized",
      "isosurfaces": [{{"value": 0.5}}], "shading": {{"light": "headlight"}}, "quality": {{"lod_ratio": 0.5}}, "camera": {{"eye": [0.5, -1.5, 0.5], "target": [0.5, 0.5, 0.5]}}}})",
                                 store, size, size),
                     "");
}

bool same_colour(const FrameBuffers& a, const FrameBuffers& b) {
  if (a.width() != b.width() || a.height() != b.height()) return false;
  return std::memcmp(a.color.data(), b.color.data(), sizeof(Rgbaf) * size_t(a.width()) * size_t(a.height())) == 0;
}

void build_field(const std::string& field, int size, const std::string& dir, bool force = false, bool octree = true) {
  BuildOptions o;
  o.brick_size = 16;
  o.force = force;
  o.check_disk = false;
  build_store(*make_field_source(make_field(field), {size, size, size}, ValueType::u8), dir, o);
  if (octree) build_octree(dir, {});
}

class ConcurrencyDrill : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new testing::TempDir();
    build_field("gyroid", 96, dir_->file("a.store"));
  }
  static void TearDownTestSuite() { delete dir_; }
  static testing::TempDir* dir_;
};
testing::TempDir* ConcurrencyDrill::dir_ = nullptr;

TEST_F(ConcurrencyDrill, BackEndsRenderWhileVerifyReadsTheStoreAndAnotherIsImported) {
  const std::string a = dir_->file("a.store"), b = dir_->file("b.store");
  const Store store(a);
  const StoreImage truth = read_whole(store);
  const std::vector<std::string> names = {"raymarch", "reference", "gobbetti", "gigavoxels", "octree_cgt"};
  const int size = kSanitized ? 16 : 32, frames = kSanitized ? 12 : 200;
  const Scene scene = iso_scene(a, size);
  const CacheConfig roomy = budgets(8 << 20, 16 << 20), tight = budgets(256 << 10, 512 << 10);
  Camera view;
  view.eye = {1.7, -1.0, 1.4};
  view.target = {0.5, 0.5, 0.5};
  view.fov_degrees = 35;

  // Step 1: each back end's settled frame with nothing beside it.
  std::map<std::string, FrameBuffers> before;
  for (const std::string& n : names) {
    Reader r(store, scene, n, roomy);
    r.render_settled(view.in_box(r.world()), before[n]);
  }

  // Step 2: everything at once.
  std::atomic<int> flying{int(names.size())};
  std::atomic<int> verified{0}, verify_runs{0}, imports{0}, fetched{0};
  std::mutex failures_mutex;
  std::vector<std::string> failures;
  auto fail = [&](std::string what) {
    std::lock_guard lock(failures_mutex);
    failures.push_back(std::move(what));
  };
  std::map<std::string, FrameBuffers> after;
  for (const std::string& n : names) after[n];
  std::vector<std::thread> threads;
  for (size_t i = 0; i < names.size(); ++i)
    threads.emplace_back([&, i] {
      const std::string& n = names[i];
      try {
        Reader r(store, scene, n, tight);
        soak::SoakOptions o;
        o.near = 0.05;
        SplitMix64 rng(i + 1);
        FrameBuffers fb;
        for (int f = 0; f < frames; ++f) {
          r.render(soak::random_camera(rng, r.world(), o), f, fb);
          if (!testing::all_finite(fb)) fail(fmt::format("{}: frame {} is not finite", n, f));
        }
        if (const auto bad = r.pages().failed_pages(); !bad.empty()) fail(fmt::format("{}: {} pages failed: {}", n, bad.size(), bad[0].error));
        Reader fresh(store, scene, n, roomy);
        fresh.render_settled(view.in_box(fresh.world()), after[n]);
      } catch (const std::exception& e) {
        fail(fmt::format("{}: {}", n, e.what()));
      }
      --flying;
    });
  // Pages fetched through a cache of their own, each compared with the reference decode.
  threads.emplace_back([&] {
    try {
      PageCache cache(store, budgets(256 << 10, 512 << 10));
      SplitMix64 rng(99);
      std::vector<uint64_t> bricks, pages;
      for (const auto& [k, v] : truth.bricks) bricks.push_back(k);
      for (const auto& [k, v] : truth.octree) pages.push_back(k);
      while (flying > 0 || fetched < 100) {
        const bool brick = pages.empty() || rng.uniform() < 0.7;
        const uint64_t id = brick ? bricks[rng.next() % bricks.size()] : pages[rng.next() % pages.size()];
        const PageKey key{brick ? RecordKind::brick : RecordKind::octree_page, id};
        const PageHandle h = cache.fetch(key);
        const std::vector<std::byte>& want = brick ? truth.bricks.at(id) : truth.octree.at(id);
        if (std::memcmp(h.bytes(), want.data(), want.size()) != 0) fail(fmt::format("fetched {} differs from its record", to_string(key)));
        ++fetched;
      }
    } catch (const std::exception& e) {
      fail(fmt::format("fetcher: {}", e.what()));
    }
  });
  // Verify in this process: every record decoded and equal to the first decode.
  threads.emplace_back([&] {
    try {
      while (flying > 0 || verified < 1) {
        std::string why;
        if (!same_records(read_whole(store), truth, &why)) fail("verify in process: " + why);
        ++verified;
      }
    } catch (const std::exception& e) {
      fail(fmt::format("verify in process: {}", e.what()));
    }
  });
  // `brickyard verify` on the same store, from another process.
  threads.emplace_back([&] {
    while (flying > 0 || verify_runs < 1) {
      const testing::CommandResult r = testing::run_command(std::string(BRICKYARD_EXE) + " verify " + a);
      if (r.exit_code != 0 || r.output.find(" 0 problems") == std::string::npos) fail("brickyard verify: " + r.output);
      ++verify_runs;
    }
  });
  // Another store imported, then rebuilt with --force from another field, over and over.
  threads.emplace_back([&] {
    try {
      const char* fields[] = {"fbm", "sparse-blobs"};
      while (flying > 0 || imports < 2) {
        build_field(fields[imports % 2], 64, b, /*force=*/true, /*octree=*/false);
        const Store built(b);
        const StoreImage img = read_whole(built);
        if (img.source.find(fields[imports % 2]) == std::string::npos) fail("import: the store is not the field just built");
        ++imports;
      }
    } catch (const std::exception& e) {
      fail(fmt::format("import: {}", e.what()));
    }
  });
  for (auto& t : threads) t.join();

  for (const std::string& f : failures) ADD_FAILURE() << f;
  EXPECT_GE(verified.load(), 1);
  EXPECT_GE(verify_runs.load(), 1);
  EXPECT_GE(imports.load(), 2);
  EXPECT_GE(fetched.load(), 100);
  for (const std::string& n : names) EXPECT_TRUE(same_colour(before[n], after[n])) << n << ": the settled frame changed";
  std::printf("flights of %d frames; %d verifies in process, %d by brickyard verify, %d imports, %d pages fetched and compared\n", frames,
              verified.load(), verify_runs.load(), imports.load(), fetched.load());
}

/// What the reader saw of a store being written, open by open.
struct Sightings {
  std::map<std::string, int> errors;  // message -> count
  int whole_first = 0, whole_second = 0, without_octree = 0;
  std::vector<std::string> garbage;
  int opens() const {
    int n = whole_first + whole_second;
    for (const auto& [m, c] : errors) n += c;
    return n;
  }
  std::string describe() const {
    std::string s = fmt::format("{} opens: {} whole as the first build, {} as the second ({} without an octree yet)", opens(), whole_first,
                                whole_second, without_octree);
    for (const auto& [m, c] : errors) s += fmt::format("; {} x error: {}", c, m);
    return s;
  }
};

/// Opens `dir` and reads it whole: an error that names it, or every record equal to `first`'s
/// or `second`'s (null: no second).
void sight(const std::string& dir, const StoreImage& first, const StoreImage* second, Sightings& s) {
  StoreImage img;
  try {
    const Store store(dir);
    img = read_whole(store);
  } catch (const Error& e) {
    // A clear error: the store is not there yet, not a store yet, or incomplete. Messages name
    // the store; the count is by message with the path taken out.
    std::string m = e.what();
    for (size_t at; (at = m.find(dir)) != std::string::npos;) m.replace(at, dir.size(), "STORE");
    const bool clear = e.code() == Errc::not_found || e.code() == Errc::format;
    if (!clear) s.garbage.push_back(fmt::format("error of kind {}: {}", to_string(e.code()), m));
    ++s.errors[m];
    return;
  }
  std::string why1, why2;
  if (same_records(img, first, &why1)) ++s.whole_first;
  else if (second && same_records(img, *second, &why2)) ++s.whole_second;
  else s.garbage.push_back(fmt::format("a complete store that is neither build: {}{}", why1, second ? "; " + why2 : ""));
  s.without_octree += !img.has_octree;
}

/// Sights `dir` until the child ends; its exit status.
int sight_until_exit(pid_t pid, const std::string& dir, const StoreImage& first, const StoreImage* second, Sightings& s) {
  for (;;) {
    const int rc = poll_exit(pid);
    if (rc >= 0) return rc;
    sight(dir, first, second, s);
  }
}

TEST_F(ConcurrencyDrill, AStoreOpenedWhileItIsWrittenIsAClearErrorOrWholeAndMatching) {
  const int size = 128;
  const std::string g = dir_->file("ref-gyroid.store"), f = dir_->file("ref-fbm.store"), x = dir_->file("x.store");
  const std::string log = dir_->file("writer.log");
  build_field("gyroid", size, g);
  build_field("fbm", size, f);
  StoreImage gyroid, fbm;
  {
    const Store s1(g), s2(f);
    gyroid = read_whole(s1);
    fbm = read_whole(s2);
  }
  // The reference builds were in process: the same sources and options as the command line's.
  const std::string exe = BRICKYARD_EXE, n = std::to_string(size);
  const std::vector<std::string> common = {"--size", n, "--type", "u8", "--brick-size", "16", "--octree", "--no-disk-check",
                                           "--transaction-size", "64KiB", "--out", x};
  auto import = [&](const std::string& field, bool force) {
    std::vector<std::string> args = {exe, "import", "field:" + field};
    args.insert(args.end(), common.begin(), common.end());
    if (force) args.push_back("--force");
    return spawn(args, log);
  };

  // Phase 1: a fresh import.
  Sightings fresh;
  int rc = sight_until_exit(import("gyroid", false), x, gyroid, nullptr, fresh);
  ASSERT_EQ(rc, 0) << testing::read_file(log);
  sight(x, gyroid, nullptr, fresh);
  EXPECT_GE(fresh.whole_first, 1);
  // Built beside its path and put there with its octree: never a grid without the octree asked for.
  EXPECT_EQ(fresh.without_octree, 0) << fresh.describe();
  for (const std::string& m : fresh.garbage) ADD_FAILURE() << "import: " << m;
  std::printf("import: %s\n", fresh.describe().c_str());

  // Phase 2: rebuilt from another field beside it (--force): the old store until the swap.
  Sightings rebuilt;
  rc = sight_until_exit(import("fbm", true), x, gyroid, &fbm, rebuilt);
  ASSERT_EQ(rc, 0) << testing::read_file(log);
  sight(x, gyroid, &fbm, rebuilt);
  EXPECT_GE(rebuilt.whole_second, 1);
  EXPECT_TRUE(rebuilt.errors.empty()) << "a store rebuilt with --force stays readable: " << rebuilt.describe();
  EXPECT_EQ(rebuilt.without_octree, 0) << rebuilt.describe();
  for (const std::string& m : rebuilt.garbage) ADD_FAILURE() << "import --force: " << m;
  std::printf("import --force: %s\n", rebuilt.describe().c_str());

  // Phase 3: the octree rebuilt in place, twice. The grid is the same throughout; the octree is
  // there whole or not at all.
  Sightings octree;
  for (int i = 0; i < 2; ++i) {
    rc = sight_until_exit(spawn({exe, "build-octree", x}, log), x, fbm, nullptr, octree);
    ASSERT_EQ(rc, 0) << testing::read_file(log);
  }
  for (const std::string& m : octree.garbage) ADD_FAILURE() << "build-octree: " << m;
  std::printf("build-octree: %s\n", octree.describe().c_str());
}

TEST_F(ConcurrencyDrill, AReaderReadsAStoreWholeWhileAnotherIsRebuilt) {
  const std::string a = dir_->file("a.store"), c = dir_->file("c.store"), log = dir_->file("rebuild.log");
  StoreImage truth;
  {
    const Store s(a);
    truth = read_whole(s);
  }
  int reads = 0;
  const char* fields[] = {"fbm", "gyroid", "sparse-blobs", "menger"};
  for (int i = 0; i < 4; ++i) {
    const pid_t pid = spawn({BRICKYARD_EXE, "import", std::string("field:") + fields[i], "--size", "96", "--type", "u8", "--brick-size", "16",
                             "--force", "--no-disk-check", "--transaction-size", "64KiB", "--out", c},
                            log);
    int rc;
    do {
      rc = poll_exit(pid);
      const Store s(a);
      std::string why;
      EXPECT_TRUE(same_records(read_whole(s), truth, &why)) << why;
      ++reads;
    } while (rc < 0);
    ASSERT_EQ(rc, 0) << testing::read_file(log);
  }
  const Store built(c);
  EXPECT_NE(built.manifest().source.find("menger"), std::string::npos);
  EXPECT_GE(reads, 4);
}

}  // namespace
}  // namespace brickyard
