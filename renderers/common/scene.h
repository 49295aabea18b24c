#pragma once
/// @file scene.h
/// @brief A scene: what to draw (dataset, mode, isovalues or transfer function), how (back end
/// and its parameters, shading, quality knobs, cache budgets) and from where (a camera or a
/// camera path). Read from JSON (comments allowed) by load_scene(); the format is documented
/// in the README and in scenes/example.json. Every key is checked: an unknown key or a wrong
/// type is an error naming the key and the file.
///
/// Positions (camera, lights, clip box) are in coordinates normalised to the volume's
/// bounding box, [0, 1]^3, like camera paths, so one scene fits any dataset. Values
/// (isovalues, transfer-function points) are in the store's units, those `brickyard info`
/// prints, or, with "values": "normalized", fractions of the store's value range [min, max]
/// (mapped when the store is opened: normalize_values()).

#include <algorithm>
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "core/camera.h"
#include "core/math.h"
#include "renderers/common/transfer_function.h"

namespace brickyard {

enum class RenderMode : uint8_t { iso, dvr, mip };
std::string_view to_string(RenderMode m);

struct Isosurface {
  double value = 0;
  Vec3f color{0.9f, 0.9f, 0.9f};
};

enum class LightKind : uint8_t { none, headlight, point, directional };
enum class NormalMethod : uint8_t { analytic, central, forward };
std::string_view to_string(LightKind k);
std::string_view to_string(NormalMethod m);

struct Shading {
  LightKind light = LightKind::headlight;
  Vec3d light_position{0.5, -1.0, 1.5};  ///< point light, normalised coordinates
  Vec3d light_direction{0.3, 1.0, -0.6}; ///< directional light: the direction light travels
  Vec3f light_color{1.0f};
  NormalMethod normals = NormalMethod::analytic;
  bool shadows = false;
  float ambient = 0.15f, diffuse = 0.75f, specular = 0.25f, shininess = 32.0f;

  bool lit() const { return light != LightKind::none; }
  /// @brief Shadow rays are cast only when asked for and there is a light to cast them to.
  bool casts_shadows() const { return shadows && lit(); }
};

struct Quality {
  double lod_ratio = 1.0;            ///< target voxel-to-pixel ratio of level-of-detail back ends
  double step_factor = 1.0;          ///< multiplies a back end's base sampling step
  double termination_opacity = 0.99; ///< early ray termination
};

struct CacheBudget {
  uint64_t l1_bytes = uint64_t(256) << 20;
  uint64_t l2_bytes = uint64_t(1) << 30;
  std::string l1_policy = "lru", l2_policy = "lru";
  int loader_threads = 2;
};

struct Scene {
  std::string file;             ///< the scene file ("" for scenes built in code)
  std::string dataset;          ///< store directory, resolved relative to the scene file
  std::string backend = "raymarch";
  std::map<std::string, double> backend_params;
  int width = 512, height = 512;
  CameraPath camera;            ///< one keyframe for a still camera; width/height mirror the image
  bool has_path = false;        ///< a camera path (several frames) rather than one camera
  RenderMode mode = RenderMode::iso;
  std::vector<Isosurface> isosurfaces;  ///< 1 to 4 for iso mode
  TransferFunction transfer_function;   ///< DVR and MIP colour
  double sampling_rate = 1.0;           ///< DVR: samples per voxel relative to the back end's default
  int time_step = 0;                    ///< the dataset's time step to draw (checked when it opens)
  int time_count = 1;                   ///< "time_series": frames cycle through this many steps from time_step
  Shading shading;
  std::optional<Box3d> clip;            ///< normalised coordinates
  Vec3f background{0.0f};
  Quality quality;
  CacheBudget cache;
  bool normalized_values = false;       ///< values are fractions of the store's range until mapped

  int frames() const { return has_path ? camera.frames : time_count; }
  /// @brief The time step frame f draws: a time series cycles from time_step through
  /// time_count steps (a camera path longer than the series starts it again).
  int step_of(int frame) const { return time_step + (time_count > 1 ? std::max(frame, 0) % time_count : 0); }
  /// @brief Whether any value in [lo, hi] can contribute to the image (isovalue inside,
  /// non-zero opacity by the transfer function's summed-area table; MIP: everything).
  bool value_range_visible(double lo, double hi) const;
};

/// @brief Maps normalised values (isovalues, transfer-function points) onto [lo, hi], the
/// store's value range; does nothing for scenes in stored units.
void normalize_values(Scene& scene, double lo, double hi);

/// @brief Reads and validates a scene file. Errors name the file and the key.
Scene load_scene(const std::string& path);
/// @brief Parses scene JSON text; `file` names it in errors and anchors relative paths.
Scene parse_scene(const std::string& json_text, const std::string& file);

}  // namespace brickyard
