// embree_frame: the Embree 3 side of bench/peers. Reads the triangles that VTK's flying edges
// extracted, builds Embree's BVH over them (timed: rtcCommitScene), and renders primary-ray
// frames through brickyard's pinhole camera (timed: the first frame, then steady frames).
// Writes each pixel's hit distance (float32, +inf for a miss, row 0 at the top) so that the
// driver can check that both sides saw the same camera, and its figures as one JSON object.
//
// Not part of the library: bench/peers/peers.sh compiles it on its own with g++ and Embree
// from Debian. Its camera is brickyard's, replicated: Camera::in_box (core/camera.cpp) maps
// the normalised camera into the world box, ImageRays builds the ray of pixel (x + 0.5, y + 0.5)
// in double precision, and only then is the ray rounded to Embree's floats.
//
// Usage: embree_frame --mesh FILE --box LOX,LOY,LOZ,HIX,HIY,HIZ --eye X,Y,Z --target X,Y,Z
//                     [--up X,Y,Z] [--fov DEG] [--width W] [--height H] [--threads N]
//                     [--frames N] [--builds N] [--quality low|medium|high]
//                     [--depth FILE.f32] [--json FILE]

#include <embree3/rtcore.h>
#include <pmmintrin.h>
#include <xmmintrin.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

namespace {

struct V3 {
  double x = 0, y = 0, z = 0;
  double operator[](int a) const { return a == 0 ? x : a == 1 ? y : z; }
  double& operator[](int a) { return a == 0 ? x : a == 1 ? y : z; }
};
V3 operator+(V3 a, V3 b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
V3 operator-(V3 a, V3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
V3 operator*(V3 a, double s) { return {a.x * s, a.y * s, a.z * s}; }
V3 operator/(V3 a, double s) { return {a.x / s, a.y / s, a.z / s}; }
double dot(V3 a, V3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
V3 cross(V3 a, V3 b) { return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x}; }
double length(V3 v) { return std::sqrt(dot(v, v)); }
V3 normalize(V3 v) {
  const double l = length(v);
  return l > 0 ? v / l : V3{};
}

constexpr double kPi = 3.14159265358979323846;  // core/math.h

/// brickyard's Camera, and its in_box() and ImageRays, formula for formula.
struct Camera {
  V3 eye, target, up{0, 0, 1};
  double fov_degrees = 45;

  Camera in_box(V3 lo, V3 hi) const {
    Camera c = *this;
    const V3 e = hi - lo;
    const double emax = std::max({e.x, e.y, e.z});
    const double fallback = emax > 0 ? emax : 1.0;
    for (int a = 0; a < 3; ++a) {
      const double scale = e[a] > 0 ? e[a] : fallback;
      const double base = e[a] > 0 ? lo[a] : lo[a] - 0.5 * scale;
      c.eye[a] = base + eye[a] * scale;
      c.target[a] = base + target[a] * scale;
    }
    return c;
  }
};

class ImageRays {
 public:
  ImageRays(const Camera& c, int width, int height)
      : eye_(c.eye), tan_half_fov_(std::tan(c.fov_degrees * kPi / 360.0)), aspect_(double(width) / double(height)),
        width_(width), height_(height) {
    forward_ = normalize(c.target - c.eye);
    right_ = normalize(cross(forward_, c.up));
    if (length(right_) == 0)
      right_ = normalize(cross(forward_, std::abs(forward_.z) < 0.9 ? V3{0, 0, 1} : V3{1, 0, 0}));
    up_ = cross(right_, forward_);
  }
  V3 eye() const { return eye_; }
  V3 dir(double px, double py) const {
    const double sx = (2.0 * px / width_ - 1.0) * tan_half_fov_ * aspect_;
    const double sy = (1.0 - 2.0 * py / height_) * tan_half_fov_;
    return normalize(forward_ + right_ * sx + up_ * sy);
  }

 private:
  V3 eye_, forward_, right_, up_;
  double tan_half_fov_, aspect_;
  int width_, height_;
};

struct Options {
  std::string mesh, depth, json;
  V3 lo, hi;
  bool have_box = false, have_eye = false, have_target = false;
  Camera camera;
  int width = 512, height = 512, threads = 2, frames = 7, builds = 3;
  std::string quality = "medium";
};

[[noreturn]] void usage_error(const std::string& message) {
  std::fprintf(stderr, "embree_frame: %s\n", message.c_str());
  std::exit(2);
}

std::vector<double> numbers(const std::string& option, const std::string& text, size_t count) {
  std::vector<double> v;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ',')) {
    char* end = nullptr;
    const double d = std::strtod(item.c_str(), &end);
    if (item.empty() || *end != '\0' || !std::isfinite(d))
      usage_error(option + ": '" + text + "' is not " + std::to_string(count) + " comma-separated numbers");
    v.push_back(d);
  }
  if (v.size() != count) usage_error(option + ": '" + text + "' is not " + std::to_string(count) + " comma-separated numbers");
  return v;
}

int integer(const std::string& option, const std::string& text, int lo, int hi) {
  char* end = nullptr;
  const long v = std::strtol(text.c_str(), &end, 10);
  if (text.empty() || *end != '\0' || v < lo || v > hi)
    usage_error(option + ": '" + text + "' is not an integer in [" + std::to_string(lo) + ", " + std::to_string(hi) + "]");
  return int(v);
}

Options parse(int argc, char** argv) {
  Options o;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "-h" || a == "--help") {
      std::printf("usage: embree_frame --mesh FILE --box LO,HI(6 numbers) --eye X,Y,Z --target X,Y,Z [--up X,Y,Z]\n"
                  "       [--fov DEG] [--width W] [--height H] [--threads N] [--frames N] [--builds N] [--quality low|medium|high]\n"
                  "       [--depth FILE.f32] [--json FILE]\n");
      std::exit(0);
    }
    if (i + 1 >= argc) usage_error(a + " needs a value (or is not an option; --help lists them)");
    const std::string v = argv[++i];
    auto v3 = [&](V3& out) {
      const auto n = numbers(a, v, 3);
      out = {n[0], n[1], n[2]};
    };
    if (a == "--mesh") o.mesh = v;
    else if (a == "--depth") o.depth = v;
    else if (a == "--json") o.json = v;
    else if (a == "--box") {
      const auto n = numbers(a, v, 6);
      o.lo = {n[0], n[1], n[2]};
      o.hi = {n[3], n[4], n[5]};
      o.have_box = true;
    } else if (a == "--eye") v3(o.camera.eye), o.have_eye = true;
    else if (a == "--target") v3(o.camera.target), o.have_target = true;
    else if (a == "--up") v3(o.camera.up);
    else if (a == "--fov") {
      o.camera.fov_degrees = numbers(a, v, 1)[0];
      if (!(o.camera.fov_degrees >= 1e-3 && o.camera.fov_degrees <= 179)) usage_error("--fov: '" + v + "' is outside [0.001, 179]");
    } else if (a == "--width") o.width = integer(a, v, 1, 16384);
    else if (a == "--height") o.height = integer(a, v, 1, 16384);
    else if (a == "--threads") o.threads = integer(a, v, 1, 1024);
    else if (a == "--frames") o.frames = integer(a, v, 1, 10000);
    else if (a == "--builds") o.builds = integer(a, v, 1, 1000);
    else if (a == "--quality") {
      if (v != "low" && v != "medium" && v != "high") usage_error("--quality: '" + v + "' is not low, medium or high");
      o.quality = v;
    }
    else usage_error("unknown option '" + a + "' (--help lists them)");
  }
  if (o.mesh.empty()) usage_error("--mesh is required");
  if (!o.have_box) usage_error("--box is required");
  if (!o.have_eye || !o.have_target) usage_error("--eye and --target are required");
  return o;
}

/// The mesh file that peers.py writes: "BYMESH01", uint32 vertex count, uint32 triangle count,
/// then float32 x,y,z per vertex and uint32 a,b,c per triangle, little-endian.
struct Mesh {
  std::vector<float> vertices;
  std::vector<uint32_t> triangles;
};

Mesh read_mesh(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error(path + ": cannot open: " + std::strerror(errno));
  char magic[8];
  uint32_t nv = 0, nt = 0;
  in.read(magic, 8);
  in.read(reinterpret_cast<char*>(&nv), 4);
  in.read(reinterpret_cast<char*>(&nt), 4);
  if (!in || std::memcmp(magic, "BYMESH01", 8) != 0) throw std::runtime_error(path + ": not a BYMESH01 mesh file");
  Mesh m;
  m.vertices.resize(size_t(nv) * 3);
  m.triangles.resize(size_t(nt) * 3);
  in.read(reinterpret_cast<char*>(m.vertices.data()), std::streamsize(m.vertices.size() * 4));
  in.read(reinterpret_cast<char*>(m.triangles.data()), std::streamsize(m.triangles.size() * 4));
  if (!in) throw std::runtime_error(path + ": truncated");
  for (uint32_t i : m.triangles)
    if (i >= nv) throw std::runtime_error(path + ": a triangle names vertex " + std::to_string(i) + " of " + std::to_string(nv));
  return m;
}

using Clock = std::chrono::steady_clock;
double ms_since(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

void on_embree_error(void*, RTCError code, const char* message) {
  std::fprintf(stderr, "embree_frame: Embree error %d: %s\n", int(code), message ? message : "");
  std::exit(1);
}

/// Embree asks every thread that traces rays for flush-to-zero and denormals-are-zero.
void flush_denormals() {
  _MM_SET_FLUSH_ZERO_MODE(_MM_FLUSH_ZERO_ON);
  _MM_SET_DENORMALS_ZERO_MODE(_MM_DENORMALS_ZERO_ON);
}

/// One primary-ray frame: tiles of 16x16 handed out through an atomic counter to `threads`
/// std::threads, one rtcIntersect1 per pixel, and a headlight Lambert term from the geometric
/// normal so that a hit costs what a shaded pixel needs. Returns milliseconds, wall clock.
struct FrameResult {
  double ms = 0;
  uint64_t hits = 0;
};

FrameResult render(RTCScene scene, const ImageRays& rays, int width, int height, int threads, std::vector<float>& depth,
                   std::vector<float>& shade) {
  constexpr int kTile = 16;
  const int tiles_x = (width + kTile - 1) / kTile, tiles_y = (height + kTile - 1) / kTile;
  std::atomic<int> next{0};
  std::atomic<uint64_t> hits{0};
  const V3 eye = rays.eye();
  auto work = [&] {
    flush_denormals();
    RTCIntersectContext context;
    rtcInitIntersectContext(&context);
    uint64_t local_hits = 0;
    for (int t; (t = next.fetch_add(1, std::memory_order_relaxed)) < tiles_x * tiles_y;) {
      const int x0 = (t % tiles_x) * kTile, y0 = (t / tiles_x) * kTile;
      for (int y = y0; y < std::min(y0 + kTile, height); ++y)
        for (int x = x0; x < std::min(x0 + kTile, width); ++x) {
          const V3 d = rays.dir(x + 0.5, y + 0.5);
          RTCRayHit rh;
          rh.ray.org_x = float(eye.x);
          rh.ray.org_y = float(eye.y);
          rh.ray.org_z = float(eye.z);
          rh.ray.dir_x = float(d.x);
          rh.ray.dir_y = float(d.y);
          rh.ray.dir_z = float(d.z);
          rh.ray.tnear = 0.0f;
          rh.ray.tfar = std::numeric_limits<float>::infinity();
          rh.ray.time = 0.0f;
          rh.ray.mask = 0xFFFFFFFFu;
          rh.ray.id = 0;
          rh.ray.flags = 0;
          rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
          rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
          rtcIntersect1(scene, &context, &rh);
          const size_t i = size_t(y) * size_t(width) + size_t(x);
          if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) {
            depth[i] = std::numeric_limits<float>::infinity();
            shade[i] = 0;
            continue;
          }
          ++local_hits;
          depth[i] = rh.ray.tfar;
          const V3 n{rh.hit.Ng_x, rh.hit.Ng_y, rh.hit.Ng_z};
          shade[i] = float(std::abs(dot(normalize(n), d)));  // headlight, two-sided
        }
    }
    hits.fetch_add(local_hits, std::memory_order_relaxed);
  };
  const auto t0 = Clock::now();
  std::vector<std::thread> pool;
  for (int i = 1; i < threads; ++i) pool.emplace_back(work);
  work();
  for (std::thread& t : pool) t.join();
  return {ms_since(t0), hits.load()};
}

double median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

/// A scene holding the mesh as one triangle geometry, committed; `commit_ms` is the time
/// rtcCommitScene took (the BVH build). Copying the triangles into Embree's buffers is not timed.
RTCScene build_scene(RTCDevice device, const Mesh& mesh, RTCBuildQuality quality, double& commit_ms) {
  const size_t nv = mesh.vertices.size() / 3, nt = mesh.triangles.size() / 3;
  RTCScene scene = rtcNewScene(device);
  rtcSetSceneBuildQuality(scene, quality);
  if (nt > 0) {
    RTCGeometry geom = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
    rtcSetGeometryBuildQuality(geom, quality);
    auto* v = static_cast<float*>(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), nv));
    auto* t = static_cast<uint32_t*>(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(uint32_t), nt));
    std::memcpy(v, mesh.vertices.data(), mesh.vertices.size() * sizeof(float));
    std::memcpy(t, mesh.triangles.data(), mesh.triangles.size() * sizeof(uint32_t));
    rtcCommitGeometry(geom);
    rtcAttachGeometry(scene, geom);
    rtcReleaseGeometry(geom);
  }
  const auto t0 = Clock::now();
  rtcCommitScene(scene);
  commit_ms = ms_since(t0);
  return scene;
}

}  // namespace

int main(int argc, char** argv) {
  const Options o = parse(argc, argv);
  flush_denormals();
  try {
    const Mesh mesh = read_mesh(o.mesh);
    const size_t nv = mesh.vertices.size() / 3, nt = mesh.triangles.size() / 3;

    // Device: Embree's own build threads (TBB) limited to o.threads.
    const std::string config = "threads=" + std::to_string(o.threads) + ",set_affinity=0" + std::string(std::getenv("PEERS_EMBREE_VERBOSE") ? ",verbose=2" : "");
    RTCDevice device = rtcNewDevice(config.c_str());
    if (!device) throw std::runtime_error("rtcNewDevice failed: " + std::to_string(int(rtcGetDeviceError(nullptr))));
    rtcSetDeviceErrorFunction(device, on_embree_error, nullptr);

    const RTCBuildQuality quality = o.quality == "low"      ? RTC_BUILD_QUALITY_LOW
                                    : o.quality == "high"   ? RTC_BUILD_QUALITY_HIGH
                                                            : RTC_BUILD_QUALITY_MEDIUM;
    // Warm-up: a one-triangle scene, so that the device's lazy start (its TBB threads, ISA
    // dispatch) is not counted as the build of the first BVH, as in an application that runs.
    {
      const Mesh one{{0, 0, 0, 1, 0, 0, 0, 1, 0}, {0, 1, 2}};
      double ms = 0;
      rtcReleaseScene(build_scene(device, one, quality, ms));
    }
    // BVH builds: rtcCommitScene over the triangles at the build quality asked (medium is Embree's default), a new
    // scene each time (an isovalue change brings a new mesh); the last one renders.
    std::vector<double> builds;
    RTCScene scene = nullptr;
    for (int b = 0; b < o.builds; ++b) {
      if (scene) rtcReleaseScene(scene);
      double ms = 0;
      scene = build_scene(device, mesh, quality, ms);
      builds.push_back(ms);
    }
    const double build_ms = median(builds);

    // Frames: the first after the build, then steady ones.
    const Camera world = o.camera.in_box(o.lo, o.hi);
    const ImageRays rays(world, o.width, o.height);
    std::vector<float> depth(size_t(o.width) * size_t(o.height)), shade(depth.size());
    const FrameResult first = render(scene, rays, o.width, o.height, o.threads, depth, shade);
    std::vector<double> steady;
    FrameResult last = first;
    for (int f = 1; f < o.frames; ++f) {
      last = render(scene, rays, o.width, o.height, o.threads, depth, shade);
      steady.push_back(last.ms);
    }

    if (!o.depth.empty()) {
      std::ofstream out(o.depth, std::ios::binary);
      out.write(reinterpret_cast<const char*>(depth.data()), std::streamsize(depth.size() * sizeof(float)));
      if (!out) throw std::runtime_error(o.depth + ": cannot write");
    }

    const double steady_ms = steady.empty() ? first.ms : median(steady);
    const double rays_per_s = steady_ms > 0 ? double(o.width) * o.height / (steady_ms * 1e-3) : 0;
    char buf[2048];
    std::snprintf(buf, sizeof buf,
                  "{\n  \"embree_version\": \"%d.%d.%d\",\n  \"threads\": %d,\n  \"vertices\": %zu,\n  \"triangles\": %zu,\n"
                  "  \"width\": %d,\n  \"height\": %d,\n  \"build_quality\": \"%s\",\n  \"builds\": %zu,\n"
                  "  \"build_first_ms\": %.6f,\n  \"build_ms\": %.6f,\n"
                  "  \"first_frame_ms\": %.6f,\n  \"steady_frames\": %zu,\n  \"steady_frame_ms\": %.6f,\n"
                  "  \"rays_per_second\": %.1f,\n  \"hits\": %llu,\n"
                  "  \"eye_world\": [%.17g, %.17g, %.17g],\n  \"target_world\": [%.17g, %.17g, %.17g]\n}\n",
                  RTC_VERSION_MAJOR, RTC_VERSION_MINOR, RTC_VERSION_PATCH, o.threads, nv, nt, o.width, o.height, o.quality.c_str(), builds.size(), builds.front(), build_ms,
                  first.ms, steady.size(), steady_ms, rays_per_s, static_cast<unsigned long long>(last.hits), world.eye.x,
                  world.eye.y, world.eye.z, world.target.x, world.target.y, world.target.z);
    if (!o.json.empty()) {
      std::ofstream out(o.json);
      out << buf;
      if (!out) throw std::runtime_error(o.json + ": cannot write");
    }
    std::fputs(buf, stdout);

    rtcReleaseScene(scene);
    rtcReleaseDevice(device);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "embree_frame: %s\n", e.what());
    return 1;
  }
  return 0;
}
