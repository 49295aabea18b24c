#include "cache/flight.h"

#include <algorithm>
#include <cmath>

#include "core/timing.h"

namespace brickyard {

std::vector<FlightFrame> fly(BrickCache& cache, const CameraPath& path, const FlightOptions& options,
                             const std::function<void(const FlightFrame&)>& on_frame) {
  const GridView& grid = cache.grid();
  const GridLayout& layout = grid.layout();
  const NodeTable& nodes = grid.nodes();
  const Box3d world = grid.world_box();
  const int frames = options.frames > 0 ? options.frames : path.frames;
  std::vector<FlightFrame> out;

  struct Chosen {
    BrickKey key;
    double distance;
    float priority;
  };
  std::vector<Chosen> chosen;
  std::vector<BrickKey> stack;
  uint64_t uploads_before = cache.stats().uploads;
  for (int f = 0; f < frames; ++f) {
    Stopwatch watch;
    CameraPath scaled = path;
    scaled.frames = frames;
    const Camera cam = scaled.at(f).in_box(world);
    FlightFrame report;
    report.frame = f;
    cache.frame_begin();

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
      if (pixels <= options.lod_ratio || int(k.level) == layout.finest()) {
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
    const FrameReport r = cache.frame_end();
    report.requests = r.requests;
    if (options.wait_for_loads) cache.wait_idle();
    const uint64_t uploads = cache.stats().uploads;
    report.uploads = uploads - uploads_before;
    uploads_before = uploads;
    report.seconds = watch.seconds();
    out.push_back(report);
    if (on_frame) on_frame(report);
  }
  return out;
}

}  // namespace brickyard
