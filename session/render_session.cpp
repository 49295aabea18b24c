#include "session/render_session.h"

#include <algorithm>
#include <vector>

#include <fmt/format.h>

namespace brickyard {

CacheConfig cache_config(const Scene& scene) {
  CacheConfig c;
  c.l1_bytes = scene.cache.l1_bytes;
  c.l2_bytes = scene.cache.l2_bytes;
  c.l1_policy = scene.cache.l1_policy;
  c.l2_policy = scene.cache.l2_policy;
  c.loader_threads = scene.cache.loader_threads;
  return c;
}

CacheConfig share_l1_budget(CacheConfig c, size_t brick_bytes, const BackendInfo& info, const BackendParams& params) {
  const uint64_t staging = info.l1_staging_slots ? info.l1_staging_slots(params) : 0;
  const uint64_t budget_slots = c.l1_slots ? c.l1_slots : c.l1_bytes / brick_bytes;
  if (staging == 0 || budget_slots == 0) return c;  // not shared; a budget under one brick is the cache's error
  c.l1_slots = uint32_t(l1_staging_share(staging, budget_slots));
  c.l1_bytes = uint64_t(c.l1_slots) * brick_bytes;
  c.backend_pool_bytes = (budget_slots - c.l1_slots) * brick_bytes;
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
  const BackendRegistry& registry = o.registry ? *o.registry : backends();
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
  const BackendInfo& info = entry_->info;
  if (std::find(info.modes.begin(), info.modes.end(), scene_.mode) == info.modes.end())
    throw Error(Errc::invalid_argument, fmt::format("back end '{}' does not render {} mode", info.name, to_string(scene_.mode)))
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
  store_ = std::make_unique<Store>(scene_.dataset);
  const Dataset& dataset = store_->dataset();
  if (std::find(info.kinds.begin(), info.kinds.end(), dataset.kind()) == info.kinds.end())
    throw Error(Errc::unsupported, fmt::format("back end '{}' does not render {} datasets", info.name, to_string(dataset.kind())))
        .with_file(dataset.info().name);
  if (!info.accepts(dataset.kind(), scene_.mode))
    throw Error(Errc::invalid_argument, fmt::format("back end '{}' does not render {} mode on {} datasets", info.name,
                                                    to_string(scene_.mode), to_string(dataset.kind())))
        .with_file(scene_.file)
        .with_field("mode");
  if (scene_.time_step + scene_.time_count > dataset.info().time_steps) {
    const std::string steps = scene_.time_count == 1 ? fmt::format("time step {}", scene_.time_step)
                                                     : fmt::format("time steps {} to {}", scene_.time_step,
                                                                   scene_.time_step + scene_.time_count - 1);
    throw Error(Errc::invalid_argument, fmt::format("{} of a dataset with {} (0 to {})", steps, dataset.info().time_steps,
                                                    dataset.info().time_steps - 1))
        .with_file(scene_.file)
        .with_field(scene_.time_count == 1 ? "time_step" : "time_series");
  }
  normalize_values(scene_, dataset.info().min_value, dataset.info().max_value);
  if (dataset.has_grid()) step_ = scene_.time_step;
  build_cache();
}

RenderSession::~RenderSession() {
  renderer_.reset();  // handles into the cache go before the cache
  context_.reset();
  bricks_.reset();
  pages_.reset();
}

void RenderSession::build_cache() {
  renderer_.reset();
  bricks_.reset();
  pages_.reset();
  const Dataset& dataset = store_->dataset(step_);
  CacheConfig config = options_.cache ? *options_.cache : cache_config(scene_);
  const auto& reads = entry_->info.records;
  for (const PageKindInfo& k : store_->page_kinds())
    if (std::find(reads.begin(), reads.end(), k.kind) == reads.end() && !config.kinds.count(k.kind))
      config.kinds[k.kind] = KindBudget{1, k.page_bytes, k.page_bytes};
  if (dataset.has_grid()) config = share_l1_budget(config, dataset.grid().shape().bytes(), entry_->info, params_);
  try {
    pages_ = std::make_unique<PageCache>(store_->step_pages(step_), config);
  } catch (const Error& e) {
    // A budget the scene gave that cannot hold one page is the scene's key to fix; a
    // configuration the caller gave (Options::cache) stays the caller's.
    const bool l1 = e.field() == "l1_bytes", l2 = e.field() == "l2_bytes";
    if (options_.cache || !(l1 || l2)) throw;
    throw Error(e.code(), e.message()).with_file(scene_.file).with_field(l1 ? "cache.l1" : "cache.l2");
  }
  if (dataset.has_grid()) bricks_ = std::make_unique<BrickCache>(*pages_, dataset.grid());
  if (context_) context_->rebind_cache(*pages_, bricks_.get());
  else context_ = std::make_unique<RenderContext>(scene_, dataset, *pages_, bricks_.get());
  renderer_ = entry_->create(*context_, params_);
}

void RenderSession::reset_cache() { build_cache(); }

void RenderSession::follow_step(int step) {
  if (store_->dataset().has_grid() && step != step_) show_step(step);
}

void RenderSession::show_step(int step) {
  (void)store_->dataset(step);  // throws for a step the dataset does not have, before anything goes
  renderer_.reset();
  context_.reset();
  step_ = step;
  build_cache();
}

bool RenderSession::converged() const { return renderer_->converged(); }

int RenderSession::settle(int frame, const FrameOutputs& outputs, int max_frames, Settle how) {
  return settle(setup(frame, outputs), max_frames, how);
}

int RenderSession::settle(const FrameSetup& frame_setup, int max_frames, Settle how) {
  FrameBuffers scratch;
  int n = 0;
  // A complete frame also converges when a pass could not be served (passes exhausted, a pool
  // too small); the frames shown next are not completed: settle until they converge too.
  if (how == Settle::complete) n = complete(frame_setup, scratch, max_frames);
  while (n < max_frames) {
    render(frame_setup, scratch);
    ++n;
    pages_->wait_idle();  // the loader serves this frame's requests before the next one
    if (renderer_->converged()) return n;
  }
  return max_frames;
}

int RenderSession::complete(const FrameSetup& frame_setup, FrameBuffers& out, int max_frames) {
  follow_step(frame_setup.time_step);  // before the guard below holds the back end
  struct CompleteFrames {  // off again however this ends
    Renderer& renderer;
    explicit CompleteFrames(Renderer& r) : renderer(r) { renderer.set_complete_frames(true); }
    ~CompleteFrames() { renderer.set_complete_frames(false); }
  } guard(*renderer_);
  for (int n = 1; n <= max_frames; ++n) {
    render(frame_setup, out);
    pages_->wait_idle();
    if (renderer_->converged()) return n;
  }
  return max_frames;
}

Camera RenderSession::camera(int frame) const {
  return scene_.camera.at(std::clamp(frame, 0, scene_.frames() - 1)).in_box(context_->geometry().world);
}

FrameSetup RenderSession::setup(int frame, const FrameOutputs& outputs) const {
  FrameSetup setup;
  setup.camera = camera(frame);
  setup.width = scene_.width;
  setup.height = scene_.height;
  setup.frame = frame;
  setup.time_step = scene_.step_of(frame);
  setup.outputs = outputs;
  return setup;
}

FrameStats RenderSession::render(int frame, FrameBuffers& out, const FrameOutputs& outputs) {
  return render(setup(frame, outputs), out);
}

FrameStats RenderSession::render(const FrameSetup& frame_setup, FrameBuffers& out) {
  follow_step(frame_setup.time_step);
  return render_frame(*renderer_, *context_, frame_setup, out);
}

}  // namespace brickyard
