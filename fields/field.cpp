#include "fields/field.h"

#include <cmath>

#include <fmt/format.h>

#include "core/error.h"
#include "fields/field_types.h"

namespace brickyard {

Vec3d Field::gradient(const Vec3d& p) const {
  // Step relative to the domain: small enough for the finest detail of the noise fields,
  // large enough that rounding does not dominate (h ~ cbrt(eps) * extent).
  const Vec3d h = domain().extent() * 1e-6;
  Vec3d g;
  for (int a = 0; a < 3; ++a) {
    Vec3d d{};
    d[a] = h[a];
    g[a] = (value(p + d) - value(p - d)) / (2.0 * h[a]);
  }
  return g;
}

double FieldParamReader::get(std::string_view name, double default_value, std::string_view doc) {
  double v = default_value;
  if (auto it = given_.find(name); it != given_.end()) v = it->second;
  if (!std::isfinite(v))
    throw Error(Errc::invalid_argument, fmt::format("parameter '{}' of field '{}' must be finite", name, field_))
        .with_field(name);
  declared_.push_back({std::string(name), v, std::string(doc)});
  return v;
}

int64_t FieldParamReader::get_int(std::string_view name, int64_t default_value, int64_t lo, int64_t hi,
                                  std::string_view doc) {
  double v = get(name, static_cast<double>(default_value), doc);
  if (v != std::floor(v) || v < static_cast<double>(lo) || v > static_cast<double>(hi))
    throw Error(Errc::invalid_argument,
                fmt::format("parameter '{}' of field '{}' must be an integer in [{}, {}], not {}", name, field_, lo, hi, v))
        .with_field(name);
  return static_cast<int64_t>(v);
}

void FieldParamReader::finish() const {
  for (const auto& [name, value] : given_) {
    bool known = false;
    for (const auto& p : declared_) known = known || p.name == name;
    if (known) continue;
    std::vector<std::string> names;
    for (const auto& p : declared_) names.push_back(p.name);
    throw Error(Errc::invalid_argument, fmt::format("field '{}' has no parameter '{}' (its parameters: {})", field_,
                                                    name, names.empty() ? "none" : fmt::format("{}", fmt::join(names, ", "))))
        .with_field(name);
  }
}

namespace {
struct Entry {
  const char* name;
  const char* description;
  std::unique_ptr<Field> (*make)(FieldParamReader&);
};

// Explicit registration: adding a field is one line here (no static initialisers).
const Entry kFields[] = {
    {"marschner-lobb", "Marschner-Lobb reconstruction test signal on [-1,1]^3 (alpha 0.25, f_M 6)",
     make_marschner_lobb},
    {"sphere", "signed distance to a sphere (negative inside)", make_sphere_sdf},
    {"torus", "signed distance to a torus around the z axis (negative inside)", make_torus_sdf},
    {"gyroid", "smooth triply periodic gyroid with analytic gradient everywhere", make_gyroid},
    {"fbm", "fractal Brownian motion of gradient noise: turbulent, high entropy", make_fbm},
    {"menger", "Menger sponge occupancy (1 solid, 0 empty): large empty regions, self-similar", make_menger},
    {"sparse-blobs", "clusters of smooth blobs in an exactly constant (0) background", make_sparse_blobs},
    {"linear", "a linear function a . p + b: planar isosurfaces, exact on any mesh or grid", make_linear},
    {"wavelet", "VTK's wavelet (vtkRTAnalyticSource) on [-1/2,1/2]^3: f32 grids equal VTK's bit for bit", make_wavelet},
    {"shepp-logan", "3D Shepp-Logan head phantom in Hounsfield-like units (air -1000, brain 20, skull 1000) on [-1,1]^3: "
     "CT-shaped, integer-valued (i16 stores it exactly)", make_shepp_logan},
};
}  // namespace

std::vector<FieldInfo> field_catalog() {
  std::vector<FieldInfo> out;
  for (const auto& e : kFields) {
    FieldParamValues none;
    FieldParamReader reader(e.name, none);
    auto field = e.make(reader);
    out.push_back({e.name, e.description, field->params()});
  }
  return out;
}

std::vector<std::string> field_names() {
  std::vector<std::string> out;
  for (const auto& e : kFields) out.emplace_back(e.name);
  return out;
}

std::unique_ptr<Field> make_field(std::string_view name, const FieldParamValues& params) {
  for (const auto& e : kFields) {
    if (name != e.name) continue;
    FieldParamReader reader(name, params);
    auto field = e.make(reader);
    reader.finish();
    return field;
  }
  throw Error(Errc::invalid_argument,
              fmt::format("unknown field '{}' (known fields: {})", name, fmt::join(field_names(), ", ")));
}

}  // namespace brickyard
