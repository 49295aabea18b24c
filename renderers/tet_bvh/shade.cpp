// tet_bvh's packet shading: the layers a packet peels, the shadow packets of its hits, Blinn-
// Phong with the reference's rules, and which pixels a pass finishes.

#include <algorithm>
#include <cmath>
#include <limits>

#include "renderers/tet_bvh/renderer.h"

namespace brickyard::tet_bvh {
namespace {
constexpr double kInf = std::numeric_limits<double>::infinity();
}

void TetBvhRenderer::shadows(const Packet& p, const bool* lit, bool* shadowed, bool* certain, RayCounters& counters) const {
  const double offset = 1e-6 * geo_.voxel_size;  // leave the surface the ray starts on
  const LightKind light = scene_.shading.light;
  for (int l = 0; l < p.lanes; ++l) shadowed[l] = false, certain[l] = true;
  if (!scene_.shading.casts_shadows() || light == LightKind::headlight) return;  // the eye's light: nothing in front
  if (light == LightKind::point) {
    // One packet from the light to every hit: the shared origin gives it a frustum.
    Packet s;
    s.lanes = p.lanes;
    s.origin = geo_.from_normalised(scene_.shading.light_position);
    s.any_hit = true;
    bool cast[kMaxLanes];
    for (int l = 0; l < p.lanes; ++l) {
      s.active[l] = cast[l] = false;
      s.dx[l] = 0, s.dy[l] = 0, s.dz[l] = 1;
      s.tmin[l] = s.tmax[l] = 0, s.hit_t[l] = kInf, s.hit_surface[l] = -1, s.t_miss[l] = kInf;
      if (!lit[l]) continue;
      const Vec3d hit = p.origin + p.dir(l) * p.hit_t[l];
      Vec3d d = hit - s.origin;
      const double dist = length(d);
      if (!(dist > offset)) continue;
      d = d / dist;
      // The reference's shadow span, from the hit towards the light within the clip box,
      // measured from the light instead.
      Interval<double> span = intersect(Rayd(hit, -d), clip_);
      span.t0 = std::max(span.t0, offset);
      span.t1 = std::min(span.t1, dist);
      if (span.empty()) continue;
      s.dx[l] = d.x, s.dy[l] = d.y, s.dz[l] = d.z;
      s.tmin[l] = dist - span.t1, s.tmax[l] = dist - span.t0;
      s.active[l] = cast[l] = true;
      ++counters.shadow_rays;
    }
    trace(s, counters);
    for (int l = 0; l < p.lanes; ++l) {
      if (!cast[l]) continue;
      shadowed[l] = s.hit_surface[l] >= 0;
      certain[l] = shadowed[l] || s.t_miss[l] == kInf;
    }
    return;
  }
  // Directional light: parallel rays, no shared origin: one ray at a time.
  const Vec3d d = -normalize(scene_.shading.light_direction);
  for (int l = 0; l < p.lanes; ++l) {
    if (!lit[l]) continue;
    const Vec3d hit = p.origin + p.dir(l) * p.hit_t[l];
    Interval<double> span = intersect(Rayd(hit, d), clip_);
    span.t0 = std::max(span.t0, offset);
    if (span.empty()) continue;
    Packet s;
    s.lanes = 1;
    s.origin = hit;
    s.any_hit = true;
    s.dx[0] = d.x, s.dy[0] = d.y, s.dz[0] = d.z;
    s.tmin[0] = span.t0, s.tmax[0] = span.t1;
    s.hit_t[0] = kInf, s.hit_surface[0] = -1, s.t_miss[0] = kInf, s.active[0] = true;
    ++counters.shadow_rays;
    trace(s, counters);
    shadowed[l] = s.hit_surface[0] >= 0;
    certain[l] = shadowed[l] || s.t_miss[0] == kInf;
  }
}

bool TetBvhRenderer::shade_packet(const FrameSetup& setup, Packet& p, const int* px, const int* py, FrameBuffers& out,
                                  RayCounters& counters) const {
  const bool gradients = ctx_.needs_gradients(setup.outputs);
  const int layers = p_.layers;
  const double opacity = layers > 1 ? p_.layer_opacity : 1.0;
  const double peel = 1e-6 * geo_.voxel_size;  // past the layer just found
  Vec3d colour[kMaxLanes];
  double alpha[kMaxLanes], depth[kMaxLanes];
  Vec3d normal[kMaxLanes];
  bool unfinished[kMaxLanes], traced[kMaxLanes], lit[kMaxLanes], shadowed[kMaxLanes], certain[kMaxLanes];
  double resume[kMaxLanes];
  for (int l = 0; l < p.lanes; ++l) {
    colour[l] = Vec3d(0.0), alpha[l] = 0, depth[l] = kInf, normal[l] = Vec3d(0.0);
    unfinished[l] = false, traced[l] = p.active[l], resume[l] = -1;
  }
  for (int layer = 0; layer < layers; ++layer) {
    bool any = false;
    for (int l = 0; l < p.lanes; ++l) {
      p.hit_t[l] = kInf, p.hit_surface[l] = -1, p.t_miss[l] = kInf;
      any = any || p.active[l];
    }
    if (!any) break;
    trace(p, counters);
    for (int l = 0; l < p.lanes; ++l) {
      lit[l] = false;
      if (!p.active[l]) continue;
      if (p.t_miss[l] < kInf && !(p.hit_surface[l] >= 0 && p.hit_t[l] < p.t_miss[l])) {
        // A missing cluster lies before any hit: what is behind it is not known yet. An exact
        // pass resumes where the ray entered it (nothing before is missing or hit).
        unfinished[l] = true;
        if (layer == 0) resume[l] = p.t_miss[l];
      }
      lit[l] = p.hit_surface[l] >= 0 && scene_.shading.lit() && gradients;
    }
    shadows(p, lit, shadowed, certain, counters);
    for (int l = 0; l < p.lanes; ++l) {
      if (!p.active[l]) continue;
      if (p.hit_surface[l] < 0) {
        p.active[l] = false;
        continue;
      }
      if (!certain[l]) {  // the hit stands, its shadow does not: resume just before the hit
        unfinished[l] = true;
        if (layer == 0 && resume[l] < 0) resume[l] = std::max(p.tmin[l], p.hit_t[l] - peel);
      }
      Vec3f c = scene_.isosurfaces[size_t(p.hit_surface[l])].color;
      const Vec3d d = p.dir(l);
      if (gradients) {
        ++counters.gradients;
        const Vec3d n = facing_normal(Vec3d(p.gx[l], p.gy[l], p.gz[l]), d);
        if (layer == 0) normal[l] = n;
        if (shading_.lit()) {
          double light_distance;
          const Vec3d to_light = shading_.to_light(p.origin + d * p.hit_t[l], setup.camera.eye, light_distance);
          c = shading_.shade(c, n, -d, to_light, shadowed[l]);
        }
      }
      if (layer == 0) depth[l] = p.hit_t[l];
      colour[l] += Vec3d(c) * ((1 - alpha[l]) * opacity);
      alpha[l] += (1 - alpha[l]) * opacity;
      p.tmin[l] = p.hit_t[l] + peel;
    }
  }
  bool complete = true;
  for (int l = 0; l < p.lanes; ++l) {
    if (!traced[l]) continue;
    const size_t pix = pixel_slot(px[l], py[l]);
    if (unfinished[l]) {
      complete = false;
      unfinished_.fetch_add(1, std::memory_order_relaxed);
      if (frame_exact_) {
        pixel_done_[pix] = 0;
        if (layers == 1 && resume[l] >= 0) resume_t_[pix] = resume[l];
        else if (passes_ == 0) resume_t_[pix] = -1;  // from the start of its span
        continue;  // drawn when it is finished
      }
    }
    PixelResult r;
    r.color = Vec3f(colour[l] + Vec3d(scene_.background) * (1 - alpha[l]));
    r.alpha = float(alpha[l]);
    r.depth = depth[l];
    r.normal = normal[l];
    write_pixel(out, px[l], py[l], r);
    pixel_done_[pix] = 1;
  }
  return complete;
}

}  // namespace brickyard::tet_bvh
