#include "cache/flight.h"

#include <algorithm>
#include <cmath>

#include "core/timing.h"

namespace brickyard {
namespace {

/// The frame loop both flights share: the camera of each frame in world coordinates, a frame
/// of the cache around `look_up(camera, report)`, which looks up the frame's pages, then the
/// loader's turn and the frame's figures.
template <typename LookUp>
std::vector<FlightFrame> fly_frames(PageCache& cache, RecordKind kind, const Box3d& world, const CameraPath& path,
                                    const FlightOptions& options, const std::function<void(const FlightFrame&)>& on_frame,
                                    LookUp&& look_up) {
  const int frames = options.frames > 0 ? options.frames : path.frames;
  std::vector<FlightFrame> out;
  uint64_t uploads_before = cache.stats(kind).uploads;
  for (int f = 0; f < frames; ++f) {
    Stopwatch watch;
    CameraPath scaled = path;
    scaled.frames = frames;
    FlightFrame report;
    report.frame = f;
    cache.frame_begin();
    look_up(scaled.at(f).in_box(world), report);
    const FrameReport r = cache.frame_end();
    report.requests = r.requests;
    if (options.wait_for_loads) cache.wait_idle();
    const uint64_t uploads = cache.stats(kind).uploads;
    report.uploads = uploads - uploads_before;
    uploads_before = uploads;
    report.seconds = watch.seconds();
    out.push_back(report);
    if (on_frame) on_frame(report);
  }
  return out;
}

}  // namespace

std::vector<FlightFrame> fly(BrickCache& cache, const CameraPath& path, const FlightOptions& options,
                             const std::function<void(const FlightFrame&)>& on_frame) {
  const GridView& grid = cache.grid();
  const GridLayout& layout = grid.layout();
  const NodeTable& nodes = grid.nodes();
  const int coarsest = layout.coarsest_resolving();
  struct Chosen {
    BrickKey key;
    double distance;
    float priority;
  };
  std::vector<Chosen> chosen;
  std::vector<BrickKey> stack;
  return fly_frames(cache.pages(), RecordKind::brick, grid.world_box(), path, options, on_frame,
                    [&](const Camera& cam, FlightFrame& report) {
    // Step 1: refine from the root: visible, non-constant nodes whose voxels look too large.
    chosen.clear();
    stack.assign(1, BrickKey{0, 0, 0, 0});
    while (!stack.empty()) {
      const BrickKey k = stack.back();
      stack.pop_back();
      ++report.nodes_visited;
      const Box3d box = grid.brick_world_box(k);
      if (!cam.may_see(box, path.width, path.height)) continue;
      const NodeRecord& n = nodes.at(k);
      if (n.is_constant()) continue;  // renderers integrate constant nodes analytically
      const double d = distance(box, cam.eye);
      const double pixels = grid.brick_voxel_pixels(cam, k, box, path.height);
      // As the renderers refine: never stopping at a level that has collapsed an axis.
      if ((pixels <= options.lod_ratio && int(k.level) >= coarsest) || int(k.level) == layout.finest()) {
        chosen.push_back({k, d, float(pixels)});
        continue;
      }
      for (int c = 0; c < 8; ++c) {
        const BrickKey child = k.child(c);
        if (layout.contains(child)) stack.push_back(child);
      }
    }
    // Step 2: front to back, as a ray caster meets them.
    std::sort(chosen.begin(), chosen.end(), [](const Chosen& a, const Chosen& b) { return a.distance < b.distance; });
    for (const Chosen& c : chosen) {
      BrickHandle h = cache.lookup(c.key, c.priority);
      report.hits += h.ready();
    }
    report.bricks_used = chosen.size();
  });
}

std::vector<FlightFrame> fly_clusters(PageCache& cache, const TetView& tets, const Box3d& world, const CameraPath& path,
                                      const FlightOptions& options, const std::function<void(const FlightFrame&)>& on_frame) {
  const auto clusters = tets.clusters();
  std::vector<std::pair<double, uint64_t>> chosen;
  return fly_frames(cache, RecordKind::tet_cluster, world, path, options, on_frame, [&](const Camera& cam, FlightFrame& report) {
    chosen.clear();
    for (size_t c = 0; c < clusters.size(); ++c) {
      ++report.nodes_visited;
      const TetStepRange r = tets.range(c, options.time_step);
      if (double(r.max) < options.values_lo || double(r.min) > options.values_hi) continue;
      const Box3d box = clusters[c].bounds();
      if (!cam.may_see(box, path.width, path.height)) continue;
      chosen.emplace_back(distance(box, cam.eye), c);
    }
    std::sort(chosen.begin(), chosen.end());
    for (size_t i = 0; i < chosen.size(); ++i) {
      // Nearer clusters first: the priority falls with the order a ray caster meets them.
      const PageHandle h = cache.lookup({RecordKind::tet_cluster, chosen[i].second}, float(chosen.size() - i));
      report.hits += h.resident();
    }
    report.bricks_used = chosen.size();
  });
}

}  // namespace brickyard
