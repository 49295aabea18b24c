#include "renderers/common/scene.h"

#include <filesystem>
#include <sstream>

#include <fmt/format.h>

#include "cache/policy.h"
#include "core/camera_json.h"
#include "core/json_reader.h"
#include "core/units.h"

namespace brickyard {

std::string_view to_string(RenderMode m) {
  switch (m) {
    case RenderMode::iso: return "iso";
    case RenderMode::dvr: return "dvr";
    case RenderMode::mip: return "mip";
  }
  return "?";
}

std::string_view to_string(LightKind k) {
  switch (k) {
    case LightKind::none: return "none";
    case LightKind::headlight: return "headlight";
    case LightKind::point: return "point";
    case LightKind::directional: return "directional";
  }
  return "?";
}

std::string_view to_string(NormalMethod m) {
  switch (m) {
    case NormalMethod::analytic: return "analytic";
    case NormalMethod::central: return "central";
    case NormalMethod::forward: return "forward";
  }
  return "?";
}

bool Scene::value_range_visible(double lo, double hi) const {
  switch (mode) {
    case RenderMode::iso:
      for (const Isosurface& s : isosurfaces)
        if (s.value >= lo && s.value <= hi) return true;
      return false;
    case RenderMode::dvr: return transfer_function.visible(lo, hi);
    case RenderMode::mip: return true;
  }
  return true;
}

namespace {

Vec3f colour(JsonObjectReader& r, std::string_view key, Vec3f fallback) {
  const Vec3d c = r.vec3(key, Vec3d(fallback));
  for (int a = 0; a < 3; ++a)
    if (c[a] < 0 || c[a] > 1) throw r.error(key, "colour components must be in [0, 1]");
  return Vec3f(c);
}

/// A cache budget: a size or a number of bytes, 0 included. Whether it holds a page of the
/// store is the session's to say, which knows the page's size and names this key.
uint64_t bytes(JsonObjectReader& r, std::string_view key, uint64_t fallback) {
  const nlohmann::json* j = r.get(key);
  if (!j) return fallback;
  if (j->is_number_unsigned()) return j->get<uint64_t>();
  if (!j->is_string()) throw r.error(key, "expected a size such as \"256MiB\" or a number of bytes");
  try {
    return parse_bytes(j->get<std::string>(), r.path(key), /*allow_zero=*/true);
  } catch (Error& e) {
    throw e.with_file(r.file());
  }
}

/// A replacement policy a live cache can run (not `opt`, which needs the future: replay only).
std::string policy(JsonObjectReader& r, std::string_view key, const std::string& fallback) {
  const std::string name = r.string(key, fallback);
  std::string known;
  for (const std::string& p : policy_names()) {
    if (p == "opt") continue;
    if (p == name) return name;
    known += fmt::format("{}'{}'", known.empty() ? "" : ", ", p);
  }
  throw r.error(key, fmt::format("'{}' is not a policy a live cache can run (known: {})", name, known));
}

void read_backend(JsonObjectReader& top, Scene& s) {
  const nlohmann::json* b = top.get("backend");
  if (!b) return;
  if (b->is_string()) {
    s.backend = b->get<std::string>();
    return;
  }
  JsonObjectReader r = top.object("backend");
  s.backend = r.string("name");
  if (r.has("params")) {
    const nlohmann::json& params = r.require("params");
    JsonObjectReader pr(params, r.file(), r.path("params"));
    for (auto it = params.begin(); it != params.end(); ++it) s.backend_params[it.key()] = pr.required_number(it.key());
  }
  r.finish();
}

void read_camera_or_path(JsonObjectReader& top, Scene& s, const std::filesystem::path& base) {
  const bool has_camera = top.has("camera"), has_path = top.has("camera_path");
  if (has_camera == has_path) throw top.error(has_camera ? "camera_path" : "camera", "give exactly one of 'camera' and 'camera_path'");
  if (has_camera) {
    s.camera.keyframes = {read_camera(top.object("camera"), 45.0)};
    s.camera.frames = 1;
    return;
  }
  s.has_path = true;
  const nlohmann::json& p = top.require("camera_path");
  if (p.is_string()) {  // a camera-path file, as `brickyard flight` reads
    const std::filesystem::path file = base / p.get<std::string>();
    try {
      s.camera = CameraPath::load(file.string());
    } catch (Error& e) {
      // Errors inside the path file name its own key ("camera_path.keyframes"); keep that.
      if (e.field().empty()) e.with_field("camera_path");
      throw;
    }
    return;
  }
  s.camera.frames = 60;
  read_camera_path(top.object("camera_path"), s.camera);
}

void read_transfer_function(JsonObjectReader& top, Scene& s) {
  if (!top.has("transfer_function")) return;
  JsonObjectReader r = top.object("transfer_function");
  const nlohmann::json& pts = r.require("points");
  if (!pts.is_array() || pts.empty()) throw r.error("points", "expected a non-empty array of {value, color, opacity}");
  std::vector<TfPoint> points;
  double previous = -INFINITY;
  for (size_t i = 0; i < pts.size(); ++i) {
    JsonObjectReader pr(pts[i], r.file(), r.path(fmt::format("points[{}]", i)));
    TfPoint p;
    p.value = pr.required_number("value");
    if (p.value < previous) throw pr.error("value", "points must be in increasing order of value");
    previous = p.value;
    p.color = colour(pr, "color", Vec3f(1.0f));
    p.opacity = float(pr.required_number("opacity", 0.0, 1.0));
    pr.finish();
    points.push_back(p);
  }
  r.finish();
  s.transfer_function = TransferFunction(std::move(points));
}

void read_shading(JsonObjectReader& top, Scene& s) {
  if (!top.has("shading")) return;
  JsonObjectReader r = top.object("shading");
  Shading& sh = s.shading;
  const std::string light = r.choice("light", "headlight", {"none", "headlight", "point", "directional"});
  sh.light = light == "none" ? LightKind::none
             : light == "headlight" ? LightKind::headlight
             : light == "point" ? LightKind::point : LightKind::directional;
  sh.light_position = r.vec3("light_position", sh.light_position);
  sh.light_direction = r.vec3("light_direction", sh.light_direction);
  if (length(sh.light_direction) == 0) throw r.error("light_direction", "must not be zero");
  sh.light_color = colour(r, "light_color", sh.light_color);
  const std::string normals = r.choice("normals", "analytic", {"analytic", "central", "forward"});
  sh.normals = normals == "analytic" ? NormalMethod::analytic
               : normals == "central" ? NormalMethod::central : NormalMethod::forward;
  sh.shadows = r.boolean("shadows", false);
  sh.ambient = float(r.number("ambient", sh.ambient, 0, 1));
  sh.diffuse = float(r.number("diffuse", sh.diffuse, 0, 1));
  sh.specular = float(r.number("specular", sh.specular, 0, 1));
  sh.shininess = float(r.number("shininess", sh.shininess, 1, 10000));
  r.finish();
}

Scene read_scene(const nlohmann::json& j, const std::string& file) {
  JsonObjectReader top(j, file);
  Scene s;
  s.file = file;
  const std::filesystem::path base = file.empty() ? std::filesystem::path(".") : std::filesystem::path(file).parent_path();
  const std::string dataset = top.string("dataset");
  if (dataset.empty()) throw top.error("dataset", "must name a store directory");
  s.dataset = std::filesystem::path(dataset).is_absolute() ? dataset : (base / dataset).lexically_normal().string();
  read_backend(top, s);
  if (top.has("image")) {
    JsonObjectReader r = top.object("image");
    s.width = int(r.integer("width", s.width, 1, 16384));
    s.height = int(r.integer("height", s.height, 1, 16384));
    r.finish();
  }
  read_camera_or_path(top, s, base);
  s.camera.width = s.width;
  s.camera.height = s.height;

  s.normalized_values = top.choice("values", "stored", {"stored", "normalized"}) == "normalized";
  const std::string mode = top.choice("mode", "iso", {"iso", "dvr", "mip"});
  s.mode = mode == "iso" ? RenderMode::iso : mode == "dvr" ? RenderMode::dvr : RenderMode::mip;
  if (const nlohmann::json* iso = top.get("isosurfaces")) {
    if (!iso->is_array() || iso->empty() || iso->size() > 4)
      throw top.error("isosurfaces", "expected an array of 1 to 4 {value, color}");
    for (size_t i = 0; i < iso->size(); ++i) {
      JsonObjectReader r((*iso)[i], file, fmt::format("isosurfaces[{}]", i));
      Isosurface surface;
      surface.value = r.required_number("value");
      surface.color = colour(r, "color", surface.color);
      r.finish();
      s.isosurfaces.push_back(surface);
    }
  }
  read_transfer_function(top, s);
  if (s.mode == RenderMode::iso && s.isosurfaces.empty()) throw top.error("isosurfaces", "iso mode needs at least one isosurface");
  if (s.mode == RenderMode::dvr && s.transfer_function.empty())
    throw top.error("transfer_function", "dvr mode needs a transfer function");
  s.sampling_rate = top.number("sampling_rate", 1.0, 1e-3, 1e3);
  s.time_step = int(top.integer("time_step", 0, 0, 1 << 20));
  if (top.has("time_series")) {
    if (top.has("time_step")) throw top.error("time_series", "give time_step or time_series (its first step), not both");
    JsonObjectReader r = top.object("time_series");
    s.time_step = int(r.integer("first", 0, 0, 1 << 20));
    s.time_count = int(r.integer("count", 1, 1, 1 << 20));
    r.finish();
  }
  read_shading(top, s);
  if (s.shading.shadows && s.mode != RenderMode::iso)
    throw top.error("shading.shadows", "shadows are cast in iso mode only");
  if (top.has("clip")) {
    JsonObjectReader r = top.object("clip");
    Box3d clip{r.vec3("lo"), r.vec3("hi")};
    if (clip.empty()) throw r.error("hi", "the clip box is empty (lo > hi in some axis)");
    r.finish();
    s.clip = clip;
  }
  s.background = colour(top, "background", s.background);
  if (top.has("quality")) {
    JsonObjectReader r = top.object("quality");
    s.quality.lod_ratio = r.number("lod_ratio", s.quality.lod_ratio, 1e-3, 1e3);
    s.quality.step_factor = r.number("step_factor", s.quality.step_factor, 1e-3, 1e3);
    s.quality.termination_opacity = r.number("termination_opacity", s.quality.termination_opacity, 0.0, 1.0);
    r.finish();
  }
  if (top.has("cache")) {
    JsonObjectReader r = top.object("cache");
    s.cache.l1_bytes = bytes(r, "l1", s.cache.l1_bytes);
    s.cache.l2_bytes = bytes(r, "l2", s.cache.l2_bytes);
    s.cache.l1_policy = policy(r, "l1_policy", s.cache.l1_policy);
    s.cache.l2_policy = policy(r, "l2_policy", s.cache.l2_policy);
    s.cache.loader_threads = int(r.integer("loader_threads", s.cache.loader_threads, 1, 64));
    r.finish();
  }
  top.finish({"$schema", "description"});
  return s;
}

}  // namespace

void normalize_values(Scene& scene, double lo, double hi) {
  if (!scene.normalized_values) return;
  auto map = [&](double v) { return lo + v * (hi - lo); };
  for (Isosurface& surface : scene.isosurfaces) surface.value = map(surface.value);
  if (!scene.transfer_function.empty()) {
    std::vector<TfPoint> points = scene.transfer_function.points();
    for (TfPoint& p : points) p.value = map(p.value);
    scene.transfer_function = TransferFunction(std::move(points));
  }
  scene.normalized_values = false;
}

Scene parse_scene(const std::string& json_text, const std::string& file) {
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(json_text, nullptr, true, /*ignore_comments=*/true);
  } catch (const nlohmann::json::exception& e) {  // parse_error, and out_of_range for 1e400
    throw Error(Errc::format, fmt::format("not valid JSON: {}", e.what())).with_file(file);
  }
  return read_scene(j, file);
}

Scene load_scene(const std::string& path) { return read_scene(read_json_file(path), path); }

}  // namespace brickyard
