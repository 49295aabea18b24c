// octree_cgt's single-ray mode, which the paper measures the coherent one against: a
// front-to-back descent of the octree per ray, children in entry order, down to the leaves
// whose cells cells.h solves; and the shading of a hit, for both modes.

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include "renderers/octree_cgt/cells.h"
#include "renderers/octree_cgt/nodes.h"
#include "renderers/octree_cgt/tracer.h"

namespace brickyard::octree_cgt {
namespace {

/// Orders a few entries by their first member (ray entry), in place.
template <typename E, size_t N>
void sort_by_entry(std::array<E, N>& a, int count) {
  for (int i = 1; i < count; ++i)
    for (int j = i; j > 0 && a[size_t(j)].first < a[size_t(j - 1)].first; --j) std::swap(a[size_t(j)], a[size_t(j - 1)]);
}

}  // namespace

template <typename T>
void Tracer<T>::pixel(int x, int y, FrameBuffers& out) {
  ++counters.rays;
  pages.begin_ray();
  const PrimaryRay ray = primary_ray(rays, r.geo, x, y);
  PixelResult px;
  px.color = r.scene.background;
  if (ray.hits()) {
    const Hit h = trace(ray.org, ray.dir, ray.span);
    if (h.surface >= 0) shade(ray, h, px);
  }
  write_pixel(out, x, y, px);
}

template <typename T>
void Tracer<T>::shade(const PrimaryRay& ray, const Hit& h, PixelResult& px) {
  px.depth = h.t;
  px.alpha = 1;
  px.color = r.scene.isosurfaces[size_t(h.surface)].color;
  if (r.p.show_levels) {
    static const Vec3f kLevels[] = {{0.9f, 0.9f, 0.9f}, {0.2f, 0.6f, 1.0f}, {0.3f, 0.9f, 0.3f},
                                    {1.0f, 0.8f, 0.2f}, {1.0f, 0.4f, 0.2f}, {0.9f, 0.2f, 0.8f}};
    px.color = kLevels[std::min<size_t>(size_t(h.level), std::size(kLevels) - 1)];
  }
  if (!r.ctx.needs_gradients(setup.outputs)) return;
  ++counters.gradients;
  const NormalMethod method = r.scene.shading.normals;
  const Vec3d g = method == NormalMethod::analytic ? h.normal_voxel
                                                   : difference_gradient(ray.org + ray.dir * h.t, h.level, method == NormalMethod::central);
  const Vec3d n = facing_normal(g / r.geo.spacing, ray.world.dir);
  if (setup.outputs.normals) px.normal = n;
  if (!r.shading.lit()) return;
  double light_distance;
  const Vec3d l = r.shading.to_light_along(ray.world, h.t, light_distance);
  const bool shadowed = r.scene.shading.casts_shadows() && in_shadow(ray.world.at(h.t), l, light_distance);
  px.color = r.shading.shade(px.color, n, -ray.world.dir, l, shadowed);
}

/// The gradient at p (finest voxel coordinates) by central or forward differences of the
/// level-L interpolant one level-L voxel apart, confined to the volume as the reference's are
/// (cell_accessor.h): the rows and slices beyond a cell's corners are read only here, for
/// scenes that ask for difference normals.
template <typename T>
Vec3d Tracer<T>::difference_gradient(const Vec3d& p, int level, bool central) {
  const Vec3s dims = r.level_dims[size_t(level)];
  const double w = double(int64_t(1) << level);
  const Vec3d q = level ? (p + Vec3d(0.5)) / w - Vec3d(0.5) : p;
  const double lo[3] = {0, 0, 0};
  const double hi[3] = {double(dims.x - 1), double(dims.y - 1), double(dims.z - 1)};
  const auto value = [&](const Vec3d& x) {
    ++counters.samples;
    Vec3s i0;
    double f[3];
    for (int a = 0; a < 3; ++a) {
      const double c = std::clamp(x[a], 0.0, hi[a]);
      i0[a] = std::min<int64_t>(int64_t(std::floor(c)), std::max<int64_t>(dims[a] - 2, 0));
      f[a] = dims[a] > 1 ? c - double(i0[a]) : 0.0;
    }
    double corners[8];
    for (int m = 0; m < 8; ++m)
      corners[m] = voxel_at(level, {std::min(i0.x + (m & 1), dims.x - 1), std::min(i0.y + ((m >> 1) & 1), dims.y - 1),
                                    std::min(i0.z + ((m >> 2) & 1), dims.z - 1)});
    return trilinear(corners, f[0], f[1], f[2]);
  };
  return confined_difference_gradient(q, lo, hi, central, central ? 0.0 : value(q), value) / w;
}

/// Whether the segment from a hit to the light crosses an isosurface, traced through the
/// shadow rays' levels of detail (coarser than the primary rays', as the paper has it: a
/// shadow is a coarser feature than the surface it falls on). It leaves the surface by 1/100
/// voxel, as the reference does, plus the reach of the coarsest cells the shadow ray may meet
/// there, so that a coarse copy of the surface it starts on does not shadow it.
template <typename T>
bool Tracer<T>::in_shadow(const Vec3d& p_world, const Vec3d& l, double light_distance) {
  ++counters.shadow_rays;
  const Vec3d o = r.geo.to_voxel(p_world), d = l / r.geo.spacing;
  double offset = 1e-2;
  if (r.lod) {
    const double distance = std::abs(o[r.major_axis] - r.eye_k);
    for (int depth = 0; depth < r.layout.cap_depth(); ++depth)
      if (distance >= r.shadow_lod_k[size_t(depth)]) {
        offset += 0.5 * double(int64_t(1) << r.layout.level_of_depth(depth));
        break;
      }
  }
  Interval<double> span = brickyard::intersect(Rayd(o, d), r.geo.voxel_clip);
  span.t0 = std::max(span.t0, offset * r.geo.voxel_size);
  span.t1 = std::min(span.t1, light_distance);
  if (span.empty()) return false;
  lod_k = r.shadow_lod_k.data();
  const Hit h = trace(o, d, span);
  lod_k = r.lod_k.data();
  return h.surface >= 0;
}

/// Front-to-back descent from the root over [span.t0, span.t1].
template <typename T>
Hit Tracer<T>::trace(const Vec3d& o, const Vec3d& d, Interval<double> span) {
  Hit best;
  const Vec3d inv{1.0 / d.x, 1.0 / d.y, 1.0 / d.z};
  descend(root(), o, d, inv, span, best);
  return best;
}

/// Returns true when the ray is done (a hit before anything later can be).
template <typename T>
bool Tracer<T>::descend(const Node<T>& n, const Vec3d& o, const Vec3d& d, const Vec3d& inv, Interval<double> span, Hit& best) {
  ++counters.nodes;
  if (n.depth < 0) return false;  // none(): an unreadable root page
  const Interval<double> s = node_span(n, o, inv, span);
  if (s.t0 > s.t1 || s.t0 >= best.t) return false;
  if (!crosses(n.min, n.max)) return false;
  if (n.unread_page) {
    Node<T> read = n;
    read.page = page(n.unread_page);
    if (!read.page) return false;  // unreadable: its subtree is left empty
    read.unread_page = 0;
    return descend(read, o, d, inv, span, best);
  }
  on_path(n);
  if (lod_leaf(n)) {
    single_cells(n, o, d, span, best);
    return best.surface >= 0;
  }
  // Children front to back: order by where the ray enters each.
  std::array<std::pair<double, int>, 8> order;
  int count = 0;
  for (int oct = 0; oct < 8; ++oct) {
    Node<T> c = child(n, oct);
    if (c.depth < 0) continue;
    const Interval<double> cs = node_span(c, o, inv, s);
    if (cs.t0 > cs.t1) continue;
    order[size_t(count++)] = {cs.t0, oct};
  }
  sort_by_entry(order, count);
  for (int i = 0; i < count; ++i) {
    if (order[size_t(i)].first >= best.t) break;
    // No return at a child's hit: with levels of detail a coarser neighbour's cells reach
    // past its region, so a later sibling entered before the hit may hold a nearer one.
    descend(child(n, order[size_t(i)].second), o, d, inv, s, best);
  }
  return false;
}

#define BRICKYARD_OCTREE_CGT_DESCENT(V)                                                       \
  template void Tracer<V>::pixel(int, int, FrameBuffers&);                                    \
  template void Tracer<V>::shade(const PrimaryRay&, const Hit&, PixelResult&);                \
  template Hit Tracer<V>::trace(const Vec3d&, const Vec3d&, Interval<double>);
BRICKYARD_OCTREE_CGT_FOR_VOXELS(BRICKYARD_OCTREE_CGT_DESCENT)
#undef BRICKYARD_OCTREE_CGT_DESCENT

}  // namespace brickyard::octree_cgt
