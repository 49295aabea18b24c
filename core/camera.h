#pragma once
/// @file camera.h
/// @brief Pinhole cameras and keyframed camera paths. Paths are written in coordinates
/// normalised to a volume's bounding box ([0,1]^3), so one flight fits any dataset.

#include <string>
#include <vector>

#include "core/math.h"

namespace brickyard {

/// @brief A look-at pinhole camera with a vertical field of view.
struct Camera {
  Vec3d eye{0.5, -1.5, 0.5};
  Vec3d target{0.5, 0.5, 0.5};
  Vec3d up{0, 0, 1};
  double fov_degrees = 45;

  /// @brief Orthonormal basis: forward (towards the target), right, and true up.
  void basis(Vec3d& forward, Vec3d& right, Vec3d& true_up) const;
  /// @brief Primary ray through pixel (px, py) of a width x height image (pixel centres at +0.5,
  /// row 0 at the top); the direction is normalised. For many rays, ImageRays.
  Rayd ray(double px, double py, int width, int height) const;
  /// @brief Size in pixels of an object of world size `size` at distance `distance`.
  double projected_pixels(double size, double distance, int height) const;
  /// @brief Whether a box may be visible: not entirely behind the eye or outside a side plane
  /// of the view frustum (conservative).
  bool may_see(const Box3d& box, int width, int height) const;
  /// @brief Maps a camera from normalised volume coordinates into world coordinates.
  Camera in_box(const Box3d& world) const;
};

/// @brief The primary rays of one width x height image: the camera's basis and field of view
/// computed once, so a ray costs a normalisation. ray() is Camera::ray, to the last bit.
class ImageRays {
 public:
  ImageRays(const Camera& camera, int width, int height);
  Rayd ray(double px, double py) const {
    const double sx = (2.0 * px / width_ - 1.0) * tan_half_fov_ * aspect_;
    const double sy = (1.0 - 2.0 * py / height_) * tan_half_fov_;
    return {eye_, normalize(forward_ + right_ * sx + up_ * sy)};
  }
  /// @brief The directions ray() gives (to rounding) for the pixel centres (x0 + i + 0.5,
  /// y0 + j + 0.5), i < w, j < h, row by row into dx, dy, dz (w * h each), many at once.
  void directions(int x0, int y0, int w, int h, double* dx, double* dy, double* dz) const;
  /// @brief The pixel coordinates (px, py) whose ray passes through p, the inverse of ray();
  /// false when p is not in front of the eye. A segment in front of the eye projects to the
  /// segment between its ends' pixels, so a convex set's pixels lie in its corners' hull.
  bool pixel_of(const Vec3d& p, double& px, double& py) const {
    const Vec3d q = p - eye_;
    const double z = dot(q, forward_);
    if (!(z > 0)) return false;
    px = (dot(q, right_) / (z * tan_half_fov_ * aspect_) + 1.0) * 0.5 * width_;
    py = (1.0 - dot(q, up_) / (z * tan_half_fov_)) * 0.5 * height_;
    return true;
  }

 private:
  Vec3d eye_, forward_, right_, up_;
  double tan_half_fov_, aspect_;
  int width_, height_;
};

/// @brief Keyframes interpolated with Catmull-Rom splines over `frames` frames.
struct CameraPath {
  std::vector<Camera> keyframes;
  int frames = 1;
  int width = 640, height = 480;

  /// @brief Camera of frame f in [0, frames).
  Camera at(int frame) const;
  /// @brief Reads a path from JSON: {"frames": N, "image": {"width": W, "height": H},
  /// "camera_path": {"fov_degrees": F, "keyframes": [{"eye": [x,y,z], "target": [...], "up": [...]}, ...]}}
  /// or a single {"camera": {...}}. Errors name the file and the key.
  static CameraPath load(const std::string& path);
};

}  // namespace brickyard
