#include "core/camera.h"

#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "core/error.h"

namespace brickyard {

void Camera::basis(Vec3d& forward, Vec3d& right, Vec3d& true_up) const {
  forward = normalize(target - eye);
  right = normalize(cross(forward, up));
  if (length(right) == 0) right = normalize(cross(forward, std::abs(forward.z) < 0.9 ? Vec3d(0, 0, 1) : Vec3d(1, 0, 0)));
  true_up = cross(right, forward);
}

Rayd Camera::ray(double px, double py, int width, int height) const {
  Vec3d f, r, u;
  basis(f, r, u);
  const double t = std::tan(fov_degrees * kPi / 360.0);
  const double aspect = double(width) / double(height);
  const double sx = (2.0 * px / width - 1.0) * t * aspect;
  const double sy = (1.0 - 2.0 * py / height) * t;
  return {eye, normalize(f + r * sx + u * sy)};
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
  const Vec3d e = world.extent();
  c.eye = world.lo + eye * e;
  c.target = world.lo + target * e;
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

namespace {
Vec3d vec3(const nlohmann::json& j, const char* key, const std::string& path, const std::string& where) {
  auto it = j.find(key);
  if (it == j.end()) throw Error(Errc::format, "missing key").with_file(path).with_field(where + key);
  if (!it->is_array() || it->size() != 3 || !(*it)[0].is_number() || !(*it)[1].is_number() || !(*it)[2].is_number())
    throw Error(Errc::format, "expected [x, y, z]").with_file(path).with_field(where + key);
  return {(*it)[0].get<double>(), (*it)[1].get<double>(), (*it)[2].get<double>()};
}
}  // namespace

CameraPath CameraPath::load(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw Error(Errc::io, fmt::format("cannot open: {}", std::strerror(errno))).with_file(path);
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(in, nullptr, true, true);  // comments allowed in scene files
  } catch (const nlohmann::json::parse_error& e) {
    throw Error(Errc::format, fmt::format("not valid JSON: {}", e.what())).with_file(path);
  }
  CameraPath p;
  if (auto it = j.find("frames"); it != j.end()) {
    if (!it->is_number_integer() || it->get<int>() < 1) throw Error(Errc::format, "expected a positive integer").with_file(path).with_field("frames");
    p.frames = it->get<int>();
  }
  if (auto it = j.find("image"); it != j.end()) {
    p.width = it->value("width", 640);
    p.height = it->value("height", 480);
    if (p.width < 1 || p.height < 1) throw Error(Errc::format, "image size must be positive").with_file(path).with_field("image");
  }
  auto read_camera = [&](const nlohmann::json& c, const std::string& where, double fov) {
    Camera cam;
    cam.eye = vec3(c, "eye", path, where);
    cam.target = vec3(c, "target", path, where);
    cam.up = c.contains("up") ? vec3(c, "up", path, where) : Vec3d(0, 0, 1);
    cam.fov_degrees = c.value("fov_degrees", fov);
    if (!(cam.fov_degrees > 0 && cam.fov_degrees < 180))
      throw Error(Errc::format, "field of view must be in (0, 180) degrees").with_file(path).with_field(where + "fov_degrees");
    if (length(cam.target - cam.eye) == 0) throw Error(Errc::format, "eye and target coincide").with_file(path).with_field(where + "eye");
    return cam;
  };
  if (auto it = j.find("camera_path"); it != j.end()) {
    const double fov = it->value("fov_degrees", 45.0);
    auto kf = it->find("keyframes");
    if (kf == it->end() || !kf->is_array() || kf->empty())
      throw Error(Errc::format, "needs a non-empty array").with_file(path).with_field("camera_path.keyframes");
    for (size_t i = 0; i < kf->size(); ++i) p.keyframes.push_back(read_camera((*kf)[i], fmt::format("camera_path.keyframes[{}].", i), fov));
  } else if (auto c = j.find("camera"); c != j.end()) {
    p.keyframes.push_back(read_camera(*c, "camera.", 45.0));
  } else {
    throw Error(Errc::format, "needs a 'camera' or a 'camera_path'").with_file(path);
  }
  return p;
}

}  // namespace brickyard
