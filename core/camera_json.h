#pragma once
/// @file camera_json.h
/// @brief Cameras and camera paths read strictly from JSON objects (unknown keys and wrong
/// types are errors naming the file and the key). Includes nlohmann/json: .cpp files only.

#include "core/camera.h"
#include "core/json_reader.h"

namespace brickyard {

/// @brief {"eye", "target", "up" (default +z), "fov_degrees" (default fallback_fov)}.
Camera read_camera(JsonObjectReader r, double fallback_fov);
/// @brief {"keyframes": [camera, ...], "fov_degrees": default for the keyframes, "frames"}
/// into p (frames keeps its value when absent).
void read_camera_path(JsonObjectReader r, CameraPath& p);

}  // namespace brickyard
