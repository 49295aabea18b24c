#include "renderers/common/render.h"

#include <algorithm>
#include <vector>

#include <fmt/format.h>
#include <tbb/task_arena.h>

#include "core/parallel.h"
#include "core/timing.h"

namespace brickyard {

FrameStats render_frame(Renderer& renderer, const RenderContext& context, const FrameSetup& setup, FrameBuffers& out) {
  BrickCache& cache = context.cache();
  FrameStats stats;
  stats.frame = setup.frame;
  stats.width = setup.width;
  stats.height = setup.height;
  stats.threads = tbb::this_task_arena::max_concurrency();
  const CacheStats before = cache.stats();
  Stopwatch frame_watch;

  out = FrameBuffers(setup.width, setup.height, setup.outputs);
  cache.frame_begin();
  Stopwatch watch;
  renderer.begin_frame(setup);
  stats.add_phase("prepare", watch.seconds());

  const int tiles_x = (setup.width + kTileSize - 1) / kTileSize, tiles_y = (setup.height + kTileSize - 1) / kTileSize;
  std::vector<RayCounters> tile_counters(size_t(tiles_x) * size_t(tiles_y));
  double render_seconds = 0, finish_seconds = 0;
  do {
    watch = Stopwatch();
    parallel_for<int>(0, tiles_x * tiles_y, 1, [&](int begin, int end) {
      for (int t = begin; t < end; ++t) {
        const int tx = t % tiles_x, ty = t / tiles_x;
        const Tile tile{tx * kTileSize, ty * kTileSize, std::min(setup.width, (tx + 1) * kTileSize),
                        std::min(setup.height, (ty + 1) * kTileSize)};
        renderer.render_tile(setup, tile, out, tile_counters[size_t(t)]);
      }
    });
    render_seconds += watch.seconds();
    watch = Stopwatch();
    renderer.end_frame(setup, out);
    finish_seconds += watch.seconds();
  } while (renderer.another_pass());
  for (const RayCounters& c : tile_counters) stats.counters += c;
  stats.add_phase("render", render_seconds);

  watch = Stopwatch();
  const FrameReport report = cache.frame_end();
  stats.add_phase("finish", finish_seconds + watch.seconds());
  stats.seconds = frame_watch.seconds();
  renderer.add_statistics(stats);

  const CacheStats after = cache.stats();
  stats.requests = report.requests;
  stats.uploads = after.uploads - before.uploads;
  stats.stalls = after.stalls - before.stalls;
  stats.bytes_read = after.l3_bytes_read - before.l3_bytes_read;
  stats.bytes_decoded = after.l3_bytes_decoded - before.l3_bytes_decoded;
  return stats;
}

CacheConfig cache_config(const Scene& scene) {
  CacheConfig c;
  c.l1_bytes = scene.cache.l1_bytes;
  c.l2_bytes = scene.cache.l2_bytes;
  c.l1_policy = scene.cache.l1_policy;
  c.l2_policy = scene.cache.l2_policy;
  c.loader_threads = scene.cache.loader_threads;
  return c;
}

CacheConfig share_l1_budget(CacheConfig c, const BrickFormat& format, const BackendInfo& info, const BackendParams& params) {
  const uint64_t staging = info.l1_staging_slots ? info.l1_staging_slots(params) : 0;
  const uint64_t budget_slots = c.l1_slots ? c.l1_slots : c.l1_bytes / format.bytes();
  if (staging == 0 || budget_slots == 0) return c;  // not shared; a budget under one brick is the cache's error
  c.l1_slots = uint32_t(std::clamp<uint64_t>(staging, 1, std::max<uint64_t>(budget_slots / 4, 1)));
  c.l1_bytes = uint64_t(c.l1_slots) * format.bytes();
  c.backend_pool_bytes = (budget_slots - c.l1_slots) * format.bytes();
  c.l1_policy = "lru";  // a brick staged last is copied next: the policy under study is the back end's own pool's
  return c;
}

namespace {
std::map<std::string, double> merged_params(const Scene& scene, const RenderSession::Options& o, const std::string& backend) {
  std::map<std::string, double> p;
  if (backend == scene.backend) p = scene.backend_params;  // a scene's parameters belong to its back end
  for (const auto& [k, v] : o.params) p[k] = v;
  return p;
}

/// The back end a session uses. A name from the scene file is the file's error (Errc::format,
/// naming it); a name from the caller (--backend) stays the caller's (invalid_argument).
const BackendEntry* choose_backend(const Scene& scene, const RenderSession::Options& o) {
  const BackendRegistry& registry = o.registry ? *o.registry : builtin_backends();
  if (!o.backend.empty()) return &registry.find(o.backend);
  try {
    return &registry.find(scene.backend);
  } catch (const Error& e) {
    throw Error(Errc::format, e.message()).with_file(scene.file).with_field("backend");
  }
}

BackendParams resolve_params(const BackendInfo& info, const Scene& scene, const RenderSession::Options& o) {
  const bool from_scene = o.backend.empty() || o.backend == scene.backend;
  try {
    return BackendParams(info, merged_params(scene, o, info.name), from_scene ? scene.file : "");
  } catch (const Error& e) {
    // Parameters the scene gave are the scene file's error; --set ones the caller's.
    const std::string name = e.field().substr(e.field().rfind('.') + 1);
    if (!from_scene || !scene.backend_params.count(name) || o.params.count(name)) throw;
    throw Error(Errc::format, e.message()).with_file(scene.file).with_field(e.field());
  }
}

/// The normal methods a back end computes, as a scene names them.
std::string normal_methods(const BackendInfo& info) {
  std::string names;
  for (NormalMethod m : info.normals) names += (names.empty() ? "" : ", ") + std::string(to_string(m));
  return names;
}
}  // namespace

RenderSession::RenderSession(const Scene& scene, const Options& options)
    : scene_(scene),
      options_(options),
      entry_(choose_backend(scene_, options_)),
      params_(resolve_params(entry_->info, scene_, options_)) {
  if (!entry_->info.accepts(DataKind::structured, scene_.mode))
    throw Error(Errc::invalid_argument, fmt::format("back end '{}' does not render {} mode on structured volumes",
                                                    entry_->info.name, to_string(scene_.mode)))
        .with_file(scene_.file)
        .with_field("mode");
  if (scene_.shading.casts_shadows() && !entry_->info.shadows)
    throw Error(Errc::unsupported, fmt::format("{} casts no shadow rays", entry_->info.name))
        .with_file(scene_.file)
        .with_field("shading.shadows");
  if (std::find(entry_->info.normals.begin(), entry_->info.normals.end(), scene_.shading.normals) == entry_->info.normals.end())
    throw Error(Errc::unsupported, fmt::format("{} does not compute {} normals (it computes: {})", entry_->info.name,
                                               to_string(scene_.shading.normals), normal_methods(entry_->info)))
        .with_file(scene_.file)
        .with_field("shading.normals");
  store_ = std::make_unique<BrickStore>(scene_.dataset);
  normalize_values(scene_, store_->manifest().min_value, store_->manifest().max_value);
  build();
}

RenderSession::~RenderSession() = default;

void RenderSession::build() {
  renderer_.reset();
  context_.reset();
  cache_.reset();
  const CacheConfig asked = options_.cache ? *options_.cache : cache_config(scene_);
  cache_ = std::make_unique<BrickCache>(*store_, share_l1_budget(asked, store_->format(), entry_->info, params_));
  context_ = std::make_unique<RenderContext>(scene_, *cache_);
  renderer_ = entry_->create(*context_, params_);
}

void RenderSession::reset_cache() { build(); }

bool RenderSession::converged() const { return renderer_->converged(); }

int RenderSession::settle(int frame, const FrameOutputs& outputs, int max_frames, Settle how) {
  struct CompleteFrames {  // off again however settle() ends
    Renderer& renderer;
    explicit CompleteFrames(Renderer& r, bool on) : renderer(r) { renderer.set_complete_frames(on); }
    ~CompleteFrames() { renderer.set_complete_frames(false); }
  } complete(*renderer_, how == Settle::complete);
  FrameBuffers scratch;
  bool completing = how == Settle::complete;
  for (int n = 1; n <= max_frames; ++n) {
    render(frame, scratch, outputs);
    cache_->wait_idle();  // the loader serves this frame's requests before the next one
    if (!renderer_->converged()) continue;
    if (!completing) return n;
    // A complete frame also converges when a pass could not be served (passes exhausted, a
    // pool too small); the frames shown next are not completed: settle until they converge too.
    completing = false;
    renderer_->set_complete_frames(false);
  }
  return max_frames;
}

Camera RenderSession::camera(int frame) const {
  return scene_.camera.at(std::clamp(frame, 0, scene_.frames() - 1)).in_box(context_->geometry().world);
}

FrameStats RenderSession::render(int frame, FrameBuffers& out, const FrameOutputs& outputs) {
  FrameSetup setup;
  setup.camera = camera(frame);
  setup.width = scene_.width;
  setup.height = scene_.height;
  setup.frame = frame;
  setup.outputs = outputs;
  return render_frame(*renderer_, *context_, setup, out);
}

}  // namespace brickyard
