#pragma once
/// @file shading.h
/// @brief Blinn-Phong shading shared by every back end and the reference, so that image
/// differences come from sampling and reconstruction, never from two lighting models.

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>

#include "renderers/common/renderer.h"

namespace brickyard {

class ShadingModel {
 public:
  ShadingModel(const Shading& s, const VolumeGeometry& g)
      : s_(s),
        light_position_(g.from_normalised(s.light_position)),
        light_direction_(normalize(s.light_direction)),
        shininess_power_(s.shininess == std::rint(s.shininess) && s.shininess >= 1 && s.shininess <= 4096 ? unsigned(s.shininess) : 0) {}

  bool lit() const { return s_.lit(); }
  /// @brief to_light() at the point t along a primary ray (origin at the eye, unit direction).
  /// The headlight lies exactly back along the ray: no difference of two nearly equal absolute
  /// positions, which loses every bit at deep zoom.
  Vec3d to_light_along(const Rayd& primary, double t, double& distance) const {
    if (s_.light != LightKind::headlight) return to_light(primary.at(t), primary.org, distance);
    distance = t;
    return t > 0 ? -primary.dir : Vec3d(0, 0, 1);
  }
  /// @brief Unit vector from p towards the light, and the distance to it (infinite for
  /// directional lights). The headlight sits at the eye.
  Vec3d to_light(const Vec3d& p, const Vec3d& eye, double& distance) const {
    switch (s_.light) {
      case LightKind::headlight: {
        const Vec3d d = eye - p;
        distance = length(d);
        return distance > 0 ? d / distance : Vec3d(0, 0, 1);
      }
      case LightKind::point: {
        const Vec3d d = light_position_ - p;
        distance = length(d);
        return distance > 0 ? d / distance : Vec3d(0, 0, 1);
      }
      case LightKind::directional:
        distance = std::numeric_limits<double>::infinity();
        return -light_direction_;
      case LightKind::none: break;
    }
    distance = 0;
    return Vec3d(0.0);
  }

  /// @brief The light a surface point receives: shade() is base * (ambient + diffuse *
  /// `diffuse`) * light colour + light colour * specular * `specular`, so that lighting
  /// computed at two points can be averaged before it is applied (a ray segment shaded from
  /// both of its ends).
  struct Lighting {
    float diffuse = 0, specular = 0;
    /// @brief This lighting with weight w, o with weight 1 - w.
    Lighting mix(const Lighting& o, float w) const {
      return {w * diffuse + (1 - w) * o.diffuse, w * specular + (1 - w) * o.specular};
    }
  };
  /// @param n unit normal facing the viewer; `view` unit vector towards the eye, `light` unit
  /// vector towards the light.
  Lighting lighting(const Vec3d& n, const Vec3d& view, const Vec3d& light, bool shadowed) const {
    return lighting_with_half(n, light, half_vector(view, light), shadowed);
  }
  /// @brief Blinn's half vector between the directions towards the eye and the light.
  static Vec3d half_vector(const Vec3d& view, const Vec3d& light) { return normalize(light + view); }
  /// @brief Whether the direction to the light is the same at every t > 0 along a primary ray
  /// (to_light_along()); then the half vector is too, and lighting_with_half() saves a
  /// normalisation per sample.
  bool light_fixed_along_rays() const { return s_.light == LightKind::headlight || s_.light == LightKind::directional; }
  /// @brief lighting() with the half vector `half` (half_vector()) given.
  Lighting lighting_with_half(const Vec3d& n, const Vec3d& light, const Vec3d& half, bool shadowed) const {
    return shadowed ? Lighting{} : lighting_of_gradient(n, 1.0, light, half);
  }
  /// @brief lighting_with_half() for the normal g * inv_length (inv_length = 1 / |g|), without
  /// forming it (two-sided: which way it faces does not matter).
  Lighting lighting_of_gradient(const Vec3d& g, double inv_length, const Vec3d& light, const Vec3d& half) const {
    Lighting l;
    l.diffuse = float(std::fabs(dot(g, light)) * inv_length);
    const double nh = std::fabs(dot(g, half)) * inv_length;
    if (nh > 0) l.specular = float(shininess_power_ ? pow_uint(nh, shininess_power_) : std::pow(nh, double(s_.shininess)));
    return l;
  }
  /// @brief lighting_of_gradient() for kLanes gradients g (per axis, then lane) side by side,
  /// four lanes of doubles to a vector (GCC's vector extension: AVX where the target has it;
  /// GCC 12 left the same loops on arrays scalar), each normal's inverse length taken from its
  /// gradient, with lighting_of_gradient()'s arithmetic. A lane whose squared length is 0 or
  /// not finite gets no meaningful result (a division by zero, in IEEE arithmetic): the caller's.
  template <int kLanes>
  void lighting_of_gradients(const double (&g)[3][kLanes], const Vec3d& light, const Vec3d& half, float (&diffuse)[kLanes],
                             float (&specular)[kLanes]) const {
    using Doubles = double __attribute__((vector_size(32)));
    using Longs = int64_t __attribute__((vector_size(32)));
    using Floats = float __attribute__((vector_size(16)));
    constexpr int kWidth = 4;
    static_assert(kLanes % kWidth == 0, "whole vectors of lanes");
    const Longs magnitude = Longs{} + std::numeric_limits<int64_t>::max();  // every bit but the sign: fabs
    for (int h = 0; h < kLanes; h += kWidth) {
      Doubles x, y, z;  // (copied into locals: no vector passes through a call, whose ABI differs without AVX)
      std::memcpy(&x, &g[0][h], sizeof x), std::memcpy(&y, &g[1][h], sizeof y), std::memcpy(&z, &g[2][h], sizeof z);
      const Doubles length2 = x * x + y * y + z * z;  // dot(g, g)
      Doubles root;
#if defined(__AVX__) && defined(__GNUC__)
      root = __builtin_ia32_sqrtpd256(length2);
#else
      for (int k = 0; k < kWidth; ++k) root[k] = std::sqrt(length2[k]);
#endif
      const Doubles inv_length = 1 / root;
      const Doubles nl = x * light.x + y * light.y + z * light.z, nh0 = x * half.x + y * half.y + z * half.z;
      const Doubles d = (Doubles)((Longs)nl & magnitude) * inv_length;
      Doubles nh = (Doubles)((Longs)nh0 & magnitude) * inv_length;
      Doubles power = Doubles{} + 1.0;
      if (shininess_power_) {
        for (unsigned n = shininess_power_; n; n >>= 1) {  // pow_uint, the lanes side by side
          if (n & 1) power *= nh;
          nh *= nh;
        }
      } else {
        for (int k = 0; k < kWidth; ++k) power[k] = nh[k] > 0 ? std::pow(nh[k], double(s_.shininess)) : 0.0;
      }
      const Floats df = __builtin_convertvector(d, Floats), sf = __builtin_convertvector(power > 0 ? power : Doubles{}, Floats);
      std::memcpy(&diffuse[h], &df, sizeof df), std::memcpy(&specular[h], &sf, sizeof sf);
    }
  }
  Vec3f apply(const Vec3f& base, const Lighting& l) const {
    if (!lit()) return base;
    const Vec3f lc = s_.light_color;
    Vec3f out = base * (s_.ambient + s_.diffuse * l.diffuse) * lc + lc * (s_.specular * l.specular);
    out.x = std::min(out.x, 1.0f), out.y = std::min(out.y, 1.0f), out.z = std::min(out.z, 1.0f);
    return out;
  }

  /// @brief Shaded colour of a surface point of colour `base` with unit normal n facing the
  /// viewer, unit vector `view` towards the eye, unit `light` towards the light. Two-sided.
  Vec3f shade(const Vec3f& base, const Vec3d& n, const Vec3d& view, const Vec3d& light, bool shadowed) const {
    if (!lit()) return base;
    return apply(base, lighting(n, view, light, shadowed));
  }

 private:
  const Shading& s_;
  Vec3d light_position_, light_direction_;
  unsigned shininess_power_;  // the shininess when it is a whole number (then no pow), else 0
};

/// @brief The unit normal of a field gradient g (world units), facing against the ray
/// direction; the ray's reverse where the gradient vanishes or is NaN. A gradient that
/// overflowed (single-precision samplers, values near the largest float) points along its
/// infinite components.
inline Vec3d facing_normal(const Vec3d& gradient, const Vec3d& ray_dir) {
  Vec3d g = gradient;
  double len = length(g);
  if (std::isinf(len)) [[unlikely]] {  // an infinite component, or finite ones whose squares overflow
    const bool overflowed = std::isinf(g.x) || std::isinf(g.y) || std::isinf(g.z);
    const double largest = std::max({std::fabs(g.x), std::fabs(g.y), std::fabs(g.z)});
    for (int a = 0; a < 3; ++a)
      g[a] = !overflowed ? g[a] / largest : std::isinf(g[a]) ? std::copysign(1.0, g[a]) : std::isnan(g[a]) ? g[a] : 0.0;
    len = length(g);
  }
  if (!(len > 0) || !std::isfinite(len)) return -ray_dir;
  const Vec3d n = g / len;
  return dot(n, ray_dir) > 0 ? -n : n;
}

}  // namespace brickyard
