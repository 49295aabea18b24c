#include "core/camera.h"

#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "core/camera_json.h"
#include "core/error.h"

namespace brickyard {

void Camera::basis(Vec3d& forward, Vec3d& right, Vec3d& true_up) const {
  forward = normalize(target - eye);
  right = normalize(cross(forward, up));
  if (length(right) == 0) right = normalize(cross(forward, std::abs(forward.z) < 0.9 ? Vec3d(0, 0, 1) : Vec3d(1, 0, 0)));
  true_up = cross(right, forward);
}

Rayd Camera::ray(double px, double py, int width, int height) const { return ImageRays(*this, width, height).ray(px, py); }

ImageRays::ImageRays(const Camera& camera, int width, int height)
    : eye_(camera.eye), tan_half_fov_(std::tan(camera.fov_degrees * kPi / 360.0)), aspect_(double(width) / double(height)),
      width_(width), height_(height) {
  camera.basis(forward_, right_, up_);
}

void ImageRays::directions(int x0, int y0, int w, int h, double* dx, double* dy, double* dz) const {
  const double kx = 2.0 * tan_half_fov_ * aspect_ / width_, ky = 2.0 * tan_half_fov_ / height_;
  for (int j = 0; j < h; ++j) {
    const Vec3d vertical = up_ * (tan_half_fov_ - (y0 + j + 0.5) * ky);
    double* __restrict x = dx + size_t(j) * size_t(w);
    double* __restrict y = dy + size_t(j) * size_t(w);
    double* __restrict z = dz + size_t(j) * size_t(w);
    for (int i = 0; i < w; ++i) {
      const double sx = (x0 + i + 0.5) * kx - tan_half_fov_ * aspect_;
      x[i] = forward_.x + right_.x * sx + vertical.x, y[i] = forward_.y + right_.y * sx + vertical.y,
      z[i] = forward_.z + right_.z * sx + vertical.z;
    }
    for (int i = 0; i < w; ++i) {
      const double inverse = 1.0 / std::sqrt(x[i] * x[i] + y[i] * y[i] + z[i] * z[i]);
      x[i] *= inverse, y[i] *= inverse, z[i] *= inverse;
    }
  }
}

double Camera::projected_pixels(double size, double distance, int height) const {
  const double pixel_angle = 2.0 * std::tan(fov_degrees * kPi / 360.0) / height;
  return size / (std::max(distance, 1e-12) * pixel_angle);
}

bool Camera::may_see(const Box3d& box, int width, int height) const {
  Vec3d f, r, u;
  basis(f, r, u);
  const double ty = std::tan(fov_degrees * kPi / 360.0), tx = ty * double(width) / double(height);
  // Inward normals of the four side planes and the near plane, all through the eye.
  const Vec3d normals[5] = {f, normalize(f * tx + r), normalize(f * tx - r), normalize(f * ty + u), normalize(f * ty - u)};
  for (const Vec3d& n : normals) {
    // The box corner farthest along n: if even it is behind the plane, the box is outside.
    const Vec3d p{n.x >= 0 ? box.hi.x : box.lo.x, n.y >= 0 ? box.hi.y : box.lo.y, n.z >= 0 ? box.hi.z : box.lo.z};
    if (dot(p - eye, n) < 0) return false;
  }
  return true;
}

Camera Camera::in_box(const Box3d& world) const {
  Camera c = *this;
  // A flat axis (a slice, a 1-voxel volume) has no extent to scale by: it takes the largest
  // extent (1 for a point), centred on the box, so eye and target stay apart.
  const Vec3d e = world.extent();
  const double fallback = max_component(e) > 0 ? max_component(e) : 1.0;
  for (int a = 0; a < 3; ++a) {
    const double scale = e[a] > 0 ? e[a] : fallback;
    const double base = e[a] > 0 ? world.lo[a] : world.lo[a] - 0.5 * scale;
    c.eye[a] = base + eye[a] * scale;
    c.target[a] = base + target[a] * scale;
  }
  return c;
}

namespace {
Vec3d catmull_rom(const Vec3d& p0, const Vec3d& p1, const Vec3d& p2, const Vec3d& p3, double t) {
  const double t2 = t * t, t3 = t2 * t;
  return (p1 * 2.0 + (p2 - p0) * t + (p0 * 2.0 - p1 * 5.0 + p2 * 4.0 - p3) * t2 + (p1 * 3.0 - p0 - p2 * 3.0 + p3) * t3) * 0.5;
}
}  // namespace

Camera CameraPath::at(int frame) const {
  if (keyframes.size() == 1 || frames <= 1) return keyframes.front();
  const double s = double(frame) / double(frames - 1) * double(keyframes.size() - 1);
  const size_t i = std::min(size_t(s), keyframes.size() - 2);
  const double t = s - double(i);
  auto k = [&](long j) -> const Camera& { return keyframes[size_t(std::clamp(j, 0L, long(keyframes.size()) - 1))]; };
  const long li = long(i);
  Camera c = k(li);
  c.eye = catmull_rom(k(li - 1).eye, k(li).eye, k(li + 1).eye, k(li + 2).eye, t);
  c.target = catmull_rom(k(li - 1).target, k(li).target, k(li + 1).target, k(li + 2).target, t);
  c.up = normalize(lerp(k(li).up, k(li + 1).up, t));
  c.fov_degrees = k(li).fov_degrees + (k(li + 1).fov_degrees - k(li).fov_degrees) * t;
  return c;
}

Camera read_camera(JsonObjectReader r, double fallback_fov) {
  Camera cam;
  cam.eye = r.vec3("eye");
  cam.target = r.vec3("target");
  cam.up = r.vec3("up", Vec3d(0, 0, 1));
  cam.fov_degrees = r.number("fov_degrees", fallback_fov, 1e-3, 179.0);
  const Vec3d view = cam.target - cam.eye;
  const double distance = length(view);
  if (distance == 0) throw r.error("target", "eye and target coincide");
  // Finite coordinates can still be too far apart for their distance to be a double: then the
  // viewing direction would be zero and every ray degenerate.
  if (!std::isfinite(distance)) throw r.error("target", "eye and target are too far apart (their distance overflows)");
  // The same for up, which the basis normalises after a cross product with the unit forward.
  if (!std::isfinite(length(cam.up))) throw r.error("up", "up is too long (its length overflows)");
  if (length(cam.up) == 0) throw r.error("up", "up is the zero vector");
  // Nearly parallel is as bad as parallel: the image's up would follow rounding error.
  if (length(cross(view, cam.up)) <= 1e-6 * distance * length(cam.up))
    throw r.error("up", fmt::format("up ({:g}, {:g}, {:g}) points {} the viewing direction, so no way is up in the image",
                                    cam.up.x, cam.up.y, cam.up.z, dot(view, cam.up) > 0 ? "along" : "against"));
  r.finish();
  return cam;
}

void read_camera_path(JsonObjectReader r, CameraPath& p) {
  const double fov = r.number("fov_degrees", 45.0, 1e-3, 179.0);
  p.frames = int(r.integer("frames", p.frames, 1, 1000000));
  const nlohmann::json& kf = r.require("keyframes");
  if (!kf.is_array() || kf.empty()) throw r.error("keyframes", "expected a non-empty array of cameras");
  p.keyframes.clear();
  for (size_t i = 0; i < kf.size(); ++i)
    p.keyframes.push_back(read_camera(JsonObjectReader(kf[i], r.file(), r.path(fmt::format("keyframes[{}]", i))), fov));
  r.finish();
}

CameraPath CameraPath::load(const std::string& path) {
  const nlohmann::json j = read_json_file(path);
  JsonObjectReader top(j, path);
  CameraPath p;
  p.frames = int(top.integer("frames", 1, 1, 1000000));
  if (top.has("image")) {
    JsonObjectReader image = top.object("image");
    p.width = int(image.integer("width", p.width, 1, 16384));
    p.height = int(image.integer("height", p.height, 1, 16384));
    image.finish();
  }
  const bool has_camera = top.has("camera"), has_path = top.has("camera_path");
  if (has_camera == has_path) throw top.error(has_camera ? "camera_path" : "camera", "give exactly one of 'camera' and 'camera_path'");
  if (has_path) read_camera_path(top.object("camera_path"), p);
  else p.keyframes = {read_camera(top.object("camera"), 45.0)};
  top.finish({"description"});
  return p;
}

}  // namespace brickyard
