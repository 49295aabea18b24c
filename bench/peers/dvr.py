#!/usr/bin/python3
"""The Python side of bench/peers/dvr.sh: VTK's volume ray casters next to brickyard's DVR, on the
same voxels, transfer function, camera and image (docs/peers.md, "Volume rendering").

Subcommands:
  check     read a brickyard DVR scene and say whether this script can translate it (standard
            library only: runs before anything is installed); prints the scene's dataset
  scene     write the scene that brickyard renders beside the peers: the given one with its
            image size overridden and its dataset (and camera-path file) made absolute
  render    one peer: load the raw volume, translate the scene for one VTK mapper and sample
            distance, time the first and the steady frames, write its PNG and its figures
  collect   the peers' figures into peers.json (the form `brickyard bench --peers` reads) and
            the summary table; with --reference, each image's RMSE against brickyard's
  selftest  check the translation on tiny synthetic volumes: a slab's composited opacity, and
            the framing of the volume's box against brickyard's pinhole camera

render and selftest need python3-vtk9 and python3-numpy and an X display (Debian's VTK 9.1 has
only X render windows: dvr.sh runs them under xvfb-run). The translation, scene to VTK, is
translate(); the camera model it mirrors is brickyard's core/camera.{h,cpp}.
"""

import argparse
import json
import math
import os
import resource
import statistics
import struct
import sys
import time
import zlib

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import peers as common  # noqa: E402  (bench/peers/peers.py: fail, read_sidecar, world_box, read_png)

common.ME = "peers-dvr"
fail = common.fail

VALUE_TYPES = {"u8": "u1", "i8": "i1", "u16": "<u2", "i16": "<i2", "f32": "<f4"}


def usage_error(message):
    fail(message, 2)


# --- the scene ------------------------------------------------------------------------------


def strip_comments(text):
    """JSON with // and /* */ comments (nlohmann::json's ignore_comments, which brickyard's scene
    reader uses) as plain JSON: comments outside strings become spaces, newlines stay."""
    out, i, n = [], 0, len(text)
    while i < n:
        c = text[i]
        if c == '"':
            j = i + 1
            while j < n and text[j] != '"':
                j += 2 if text[j] == "\\" else 1
            out.append(text[i:j + 1])
            i = j + 1
        elif text.startswith("//", i):
            j = text.find("\n", i)
            i = n if j < 0 else j
        elif text.startswith("/*", i):
            j = text.find("*/", i + 2)
            if j < 0:
                raise ValueError("a /* comment is not closed")
            out.append("".join(ch if ch == "\n" else " " for ch in text[i:j + 2]))
            i = j + 2
        else:
            out.append(c)
            i += 1
    return "".join(out)


def read_json_with_comments(path, who):
    try:
        with open(path) as f:
            text = f.read()
    except OSError as e:
        usage_error(f"{who} {path}: {e.strerror}")
    try:
        return json.loads(strip_comments(text))
    except ValueError as e:
        usage_error(f"{who} {path}: not JSON: {e}")


class SceneError(Exception):
    pass


def _number(obj, key, default=None, lo=-math.inf, hi=math.inf, where=""):
    v = obj.get(key, default)
    if v is None:
        raise SceneError(f"'{where}{key}' is missing")
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise SceneError(f"'{where}{key}': {json.dumps(v)} is not a number")
    if not lo <= v <= hi:
        raise SceneError(f"'{where}{key}': {v} is outside [{lo:g}, {hi:g}]")
    return float(v)


def _vec3(obj, key, default=None, where="", colour=False):
    v = obj.get(key, default)
    if v is None:
        raise SceneError(f"'{where}{key}' is missing")
    if not (isinstance(v, list) and len(v) == 3 and all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                                        and math.isfinite(x) for x in v)):
        raise SceneError(f"'{where}{key}': {json.dumps(v)} is not [x, y, z]")
    if colour and not all(0 <= x <= 1 for x in v):
        raise SceneError(f"'{where}{key}': colour components must be in [0, 1]")
    return [float(x) for x in v]


def _camera(c, fallback_fov, where):
    if not isinstance(c, dict):
        raise SceneError(f"'{where}' is not an object")
    cam = {"eye": _vec3(c, "eye", where=where + "."), "target": _vec3(c, "target", where=where + "."),
           "up": _vec3(c, "up", [0, 0, 1], where=where + "."),
           "fov": _number(c, "fov_degrees", fallback_fov, 1e-3, 179.0, where + ".")}
    view = [cam["target"][a] - cam["eye"][a] for a in range(3)]
    if _length(view) == 0:
        raise SceneError(f"'{where}.target': eye and target coincide")
    if _length(_cross(view, cam["up"])) <= 1e-6 * _length(view) * _length(cam["up"]):
        raise SceneError(f"'{where}.up': up is parallel to the viewing direction")
    return cam


def parse_scene(path):
    """The parts of a brickyard DVR scene (renderers/common/scene.cpp) that the peers render,
    with scene.cpp's defaults. Raises SceneError naming the key for what is wrong or what VTK's
    mappers cannot be given; keys that change nothing for the peers are left to brickyard."""
    j = read_json_with_comments(path, "--scene")
    if not isinstance(j, dict):
        raise SceneError("not a JSON object")
    base = os.path.dirname(os.path.abspath(path))
    s = {"file": os.path.abspath(path), "json": j}
    mode = j.get("mode", "iso")
    if mode != "dvr":
        raise SceneError(f"'mode' is {json.dumps(mode)}{' (the default)' if 'mode' not in j else ''}; "
                         "the volume-rendering peers need a dvr scene")
    dataset = j.get("dataset")
    s["dataset"] = os.path.normpath(os.path.join(base, dataset)) if isinstance(dataset, str) and dataset else ""
    image = j.get("image", {})
    if not isinstance(image, dict):
        raise SceneError("'image' is not an object")
    s["width"] = int(_number(image, "width", 512, 1, 16384, "image."))
    s["height"] = int(_number(image, "height", 512, 1, 16384, "image."))
    # The camera: a still one, or frame 0 of a path, which is its first keyframe exactly
    # (CameraPath::at(0): Catmull-Rom at t = 0, up normalised, the keyframe's fov).
    if ("camera" in j) == ("camera_path" in j):
        raise SceneError("give exactly one of 'camera' and 'camera_path'")
    if "camera" in j:
        s["camera"] = _camera(j["camera"], 45.0, "camera")
    else:
        p = j["camera_path"]
        where = "camera_path"
        if isinstance(p, str):
            file = os.path.join(base, p)
            pj = read_json_with_comments(file, "camera_path file")
            if "camera" in pj:
                p, where = {"keyframes": [pj["camera"]]}, f"{file}: camera"
            else:
                p, where = pj.get("camera_path"), f"{file}: camera_path"
        if not isinstance(p, dict) or not isinstance(p.get("keyframes"), list) or not p["keyframes"]:
            raise SceneError(f"'{where}.keyframes' is not a non-empty array of cameras")
        fov = _number(p, "fov_degrees", 45.0, 1e-3, 179.0, where + ".")
        s["camera"] = _camera(p["keyframes"][0], fov, where + ".keyframes[0]")
    values = j.get("values", "stored")
    if values not in ("stored", "normalized"):
        raise SceneError(f"'values': {json.dumps(values)} is not \"stored\" or \"normalized\"")
    s["normalized"] = values == "normalized"
    tf = j.get("transfer_function")
    if not isinstance(tf, dict) or not isinstance(tf.get("points"), list) or not tf["points"]:
        raise SceneError("'transfer_function.points': dvr mode needs a transfer function of {value, color, opacity} points")
    points, previous = [], -math.inf
    for i, p in enumerate(tf["points"]):
        where = f"transfer_function.points[{i}]."
        if not isinstance(p, dict):
            raise SceneError(f"'{where[:-1]}' is not an object")
        v = _number(p, "value", where=where)
        if v < previous:
            raise SceneError(f"'{where}value': points must be in increasing order of value")
        previous = v
        points.append({"value": v, "color": _vec3(p, "color", [1, 1, 1], where, colour=True),
                       "opacity": _number(p, "opacity", None, 0, 1, where)})
    s["points"] = points
    sh = j.get("shading", {})
    if not isinstance(sh, dict):
        raise SceneError("'shading' is not an object")
    light = sh.get("light", "headlight")
    if light == "point":
        raise SceneError("'shading.light': a point light is not translated: VTK's fixed-point ray caster treats every "
                         "light as directional (vtkEncodedGradientShader); use headlight, directional or none")
    if light not in ("none", "headlight", "directional"):
        raise SceneError(f"'shading.light': {json.dumps(light)} is not none, headlight, point or directional")
    if sh.get("shadows", False):
        raise SceneError("'shading.shadows': shadows are cast in iso mode only")
    direction = _vec3(sh, "light_direction", [0.3, 1.0, -0.6], "shading.")
    if _length(direction) == 0:
        raise SceneError("'shading.light_direction' must not be zero")
    s["shading"] = {
        "light": light, "light_direction": direction,
        "light_color": _vec3(sh, "light_color", [1, 1, 1], "shading.", colour=True),
        "ambient": _number(sh, "ambient", 0.15, 0, 1, "shading."), "diffuse": _number(sh, "diffuse", 0.75, 0, 1, "shading."),
        "specular": _number(sh, "specular", 0.25, 0, 1, "shading."),
        "shininess": _number(sh, "shininess", 32.0, 1, 10000, "shading."),
        "normals": sh.get("normals", "analytic"),
    }
    s["background"] = _vec3(j, "background", [0, 0, 0], colour=True)
    clip = j.get("clip")
    s["clip"] = None
    if clip is not None:
        if not isinstance(clip, dict):
            raise SceneError("'clip' is not an object")
        lo, hi = _vec3(clip, "lo", where="clip."), _vec3(clip, "hi", where="clip.")
        if any(lo[a] > hi[a] for a in range(3)):
            raise SceneError("'clip.hi': the clip box is empty (lo > hi in some axis)")
        s["clip"] = [lo, hi]
    q = j.get("quality", {})
    s["termination_opacity"] = _number(q if isinstance(q, dict) else {}, "termination_opacity", 0.99, 0, 1, "quality.")
    s["sampling_rate"] = _number(j, "sampling_rate", 1.0, 1e-3, 1e3)
    if j.get("time_step", 0) != 0 or "time_series" in j:
        raise SceneError("'time_step'/'time_series': the peers render time step 0 only (brickyard export writes one volume)")
    return s


def load_scene_or_exit(path):
    try:
        return parse_scene(path)
    except SceneError as e:
        usage_error(f"--scene {path}: {e}")


# --- brickyard's camera (core/camera.h, core/camera.cpp) -------------------------------------


def _sub(a, b):
    return [a[i] - b[i] for i in range(3)]


def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def _length(a):
    return math.sqrt(_dot(a, a))


def _normalize(a):
    n = _length(a)
    return [x / n for x in a] if n > 0 else [0.0, 0.0, 0.0]


def camera_in_box(cam, lo, hi):
    """Camera::in_box: the camera's normalised eye and target mapped into the world box [lo, hi]
    (a flat axis takes the largest extent, centred on the box); up and fov unchanged."""
    e = [hi[a] - lo[a] for a in range(3)]
    fallback = max(e) if max(e) > 0 else 1.0
    out = dict(cam)
    for key in ("eye", "target"):
        out[key] = [(lo[a] if e[a] > 0 else lo[a] - 0.5 * fallback) + cam[key][a] * (e[a] if e[a] > 0 else fallback)
                    for a in range(3)]
    return out


class PinholeCamera:
    """ImageRays (core/camera.h): Camera::basis (forward to the target, right = forward x up,
    true up = right x forward), vertical field of view, pixel centres at +0.5, row 0 at the top."""

    def __init__(self, cam, width, height):
        self.eye = cam["eye"]
        self.forward = _normalize(_sub(cam["target"], cam["eye"]))
        self.right = _normalize(_cross(self.forward, cam["up"]))
        if _length(self.right) == 0:
            self.right = _normalize(_cross(self.forward, [0, 0, 1] if abs(self.forward[2]) < 0.9 else [1, 0, 0]))
        self.up = _cross(self.right, self.forward)
        self.tan_half_fov = math.tan(cam["fov"] * math.pi / 360.0)
        self.aspect = width / height
        self.width, self.height = width, height

    def ray(self, px, py):
        """ImageRays::ray: the unit direction of the ray through (px, py)."""
        sx = (2.0 * px / self.width - 1.0) * self.tan_half_fov * self.aspect
        sy = (1.0 - 2.0 * py / self.height) * self.tan_half_fov
        return _normalize([self.forward[a] + self.right[a] * sx + self.up[a] * sy for a in range(3)])

    def pixel_of(self, p):
        """ImageRays::pixel_of: the pixel coordinates whose ray passes through p (None behind the eye)."""
        q = _sub(p, self.eye)
        z = _dot(q, self.forward)
        if not z > 0:
            return None
        px = (_dot(q, self.right) / (z * self.tan_half_fov * self.aspect) + 1.0) * 0.5 * self.width
        py = (1.0 - _dot(q, self.up) / (z * self.tan_half_fov)) * 0.5 * self.height
        return px, py


# --- the translation: a brickyard DVR scene as a VTK volume rendering ------------------------


def voxel_unit(side):
    """The world length of one voxel of path, which brickyard's TF opacity is per (the step and
    the opacity correction are in voxel coordinates, renderers/reference/reference.cpp): the
    spacing, exactly, for isotropic voxels; the geometric mean of the spacings otherwise (VTK's
    unit distance and sample distance are world lengths, the same in every direction)."""
    s = [float(x) for x in side["spacing"]]
    if max(s) - min(s) <= 1e-9 * max(s):
        return s[0], True
    return (s[0] * s[1] * s[2]) ** (1.0 / 3.0), False


def tf_in_stored_units(scene, value_range):
    """The transfer function's points in the store's units: "normalized" values are fractions of
    the store's value range [min, max] (normalize_values in scene.cpp)."""
    lo, hi = value_range
    return [dict(p, value=lo + p["value"] * (hi - lo)) if scene["normalized"] else dict(p) for p in scene["points"]]


def image_data(values, side):
    """A vtkImageData over `values` (numpy, x fastest, no copy) with the sidecar's dims, spacing
    and origin: sample (i, j, k) at origin + spacing * (i, j, k), as brickyard places it."""
    from vtkmodules.vtkCommonDataModel import vtkImageData
    from vtkmodules.util.numpy_support import numpy_to_vtk

    image = vtkImageData()
    image.SetDimensions(*[int(d) for d in side["dims"]])
    image.SetSpacing(*[float(s) for s in side["spacing"]])
    image.SetOrigin(*[float(o) for o in side["origin"]])
    scalars = numpy_to_vtk(values, deep=False)
    scalars.SetName("values")
    image.GetPointData().SetScalars(scalars)
    image._values = values  # keep the buffer alive as long as the image
    return image


def read_volume(raw):
    """The raw file and its sidecar as a vtkImageData, and the seconds it took (the file read and
    wrapped without a copy; the modules are loaded before the clock starts)."""
    import numpy as np
    from vtkmodules.vtkCommonDataModel import vtkImageData  # noqa: F401
    from vtkmodules.util.numpy_support import numpy_to_vtk  # noqa: F401

    side = common.read_sidecar(raw, tuple(VALUE_TYPES))
    dims = [int(d) for d in side["dims"]]
    dtype = np.dtype(VALUE_TYPES[side["type"]])
    t0 = time.perf_counter()
    values = np.fromfile(raw, dtype=dtype)
    if values.size != dims[0] * dims[1] * dims[2]:
        fail(f"{raw}: {values.size * dtype.itemsize} bytes, the sidecar's {dims} {side['type']} needs "
             f"{dims[0] * dims[1] * dims[2] * dtype.itemsize}")
    image = image_data(values, side)
    return image, side, time.perf_counter() - t0


MAPPERS = {
    "fixed-point": "vtkFixedPointVolumeRayCastMapper",
    "gpu": "vtkGPUVolumeRayCastMapper",
}


def translate(scene, side, value_range, mapper_name, sample_voxels, threads, width, height, fault=""):
    """The scene as VTK objects: a render window (offscreen, no multisampling) with a renderer
    whose camera, background and light are the scene's, and a volume (mapper, property) that is
    not added yet, so that the caller can create the GL context first. Returns (window,
    renderer, volume, record), record holding every translated number for the figures.

    `fault` breaks one thing on purpose, so that the selftest can show that it catches it:
    "unit-distance" (opacity per world unit instead of per voxel)."""
    from vtkmodules.vtkCommonCore import vtkMultiThreader
    from vtkmodules.vtkRenderingCore import (vtkColorTransferFunction, vtkLight, vtkRenderer, vtkRenderWindow,
                                             vtkVolume, vtkVolumeProperty)
    from vtkmodules.vtkCommonDataModel import vtkPiecewiseFunction
    import vtkmodules.vtkRenderingOpenGL2  # noqa: F401  (the OpenGL render window)
    import vtkmodules.vtkRenderingVolumeOpenGL2  # noqa: F401  (the GPU mapper's OpenGL implementation)
    from vtkmodules.vtkRenderingVolume import vtkFixedPointVolumeRayCastMapper, vtkGPUVolumeRayCastMapper

    lo, hi = common.world_box(side)
    unit, isotropic = voxel_unit(side)
    if fault == "unit-distance":
        unit_distance = 1.0
    else:
        unit_distance = unit
    sample_world = sample_voxels * unit

    # Transfer function: piecewise linear in colour and opacity, clamped to the end points
    # outside them (TransferFunction::eval); VTK replaces a point at an equal value, where
    # brickyard makes a step, so a repeated value moves up by a millionth of the range.
    points = tf_in_stored_units(scene, value_range)
    span = (points[-1]["value"] - points[0]["value"]) or abs(points[0]["value"]) or 1.0
    colour, opacity = vtkColorTransferFunction(), vtkPiecewiseFunction()
    colour.ClampingOn()
    opacity.ClampingOn()
    previous = -math.inf
    for p in points:
        v = p["value"] if p["value"] > previous else previous + 1e-6 * span
        previous = v
        colour.AddRGBPoint(v, *p["color"])
        opacity.AddPoint(v, p["opacity"])

    prop = vtkVolumeProperty()
    prop.SetColor(colour)
    prop.SetScalarOpacity(opacity)
    prop.SetInterpolationTypeToLinear()
    # brickyard's opacity is per voxel of path: a = 1 - (1 - a_tf)^(step in voxels). VTK's is per
    # ScalarOpacityUnitDistance (world) of path, corrected as 1 - (1 - a)^(sample distance / unit).
    prop.SetScalarOpacityUnitDistance(unit_distance)
    sh = scene["shading"]
    lit = sh["light"] != "none"
    prop.SetShade(1 if lit else 0)
    prop.SetAmbient(sh["ambient"])
    prop.SetDiffuse(sh["diffuse"])
    prop.SetSpecular(sh["specular"])
    prop.SetSpecularPower(sh["shininess"])

    if mapper_name == "fixed-point":
        mapper = vtkFixedPointVolumeRayCastMapper()
        mapper.SetNumberOfThreads(threads)
        # Both distances, so that no render is an "interactive" one at another step.
        mapper.SetInteractiveSampleDistance(sample_world)
    elif mapper_name == "gpu":
        mapper = vtkGPUVolumeRayCastMapper()
        mapper.UseJitteringOff()
    else:
        fail(f"no mapper '{mapper_name}' (known: {', '.join(MAPPERS)})", 2)
    vtkMultiThreader.SetGlobalMaximumNumberOfThreads(threads)
    mapper.AutoAdjustSampleDistancesOff()
    mapper.LockSampleDistanceToInputSpacingOff()
    mapper.SetSampleDistance(sample_world)
    mapper.SetImageSampleDistance(1.0)
    mapper.SetBlendModeToComposite()
    crop = None
    if scene["clip"]:
        # The clip box (normalised) in world coordinates; VTK's cropping planes are the volume's.
        c_lo, c_hi = scene["clip"]
        crop = []
        for a in range(3):
            crop += [max(lo[a], lo[a] + c_lo[a] * (hi[a] - lo[a])), min(hi[a], lo[a] + c_hi[a] * (hi[a] - lo[a]))]
        mapper.CroppingOn()
        mapper.SetCroppingRegionPlanes(*crop)
        mapper.SetCroppingRegionFlagsToSubVolume()

    volume = vtkVolume()
    volume.SetMapper(mapper)
    volume.SetProperty(prop)

    window = vtkRenderWindow()
    window.SetOffScreenRendering(1)
    window.SetMultiSamples(0)
    window.SetSize(width, height)
    renderer = vtkRenderer()
    window.AddRenderer(renderer)
    renderer.SetBackground(*scene["background"])
    # One light, the scene's, and no other: brickyard's Blinn-Phong (renderers/common/shading.h)
    # is two-sided, its light colour scales the ambient term too.
    renderer.AutomaticLightCreationOff()
    renderer.RemoveAllLights()
    renderer.TwoSidedLightingOn()
    if lit:
        light = vtkLight()
        if sh["light"] == "headlight":
            light.SetLightTypeToHeadlight()
        else:  # directional: the direction the light travels
            light.SetLightTypeToSceneLight()
            light.PositionalOff()
            light.SetFocalPoint(0, 0, 0)
            light.SetPosition(*[-x for x in _normalize(sh["light_direction"])])
        light.SetIntensity(1.0)
        light.SetAmbientColor(*sh["light_color"])  # vtkLight's is black by default
        light.SetDiffuseColor(*sh["light_color"])
        light.SetSpecularColor(*sh["light_color"])
        renderer.AddLight(light)

    cam = camera_in_box(scene["camera"], lo, hi)
    vc = renderer.GetActiveCamera()
    vc.SetPosition(*cam["eye"])
    vc.SetFocalPoint(*cam["target"])
    vc.SetViewUp(*cam["up"])
    vc.OrthogonalizeViewUp()  # brickyard's true up: right x forward
    vc.SetViewAngle(cam["fov"])  # vertical, over the whole image height, as brickyard's
    vc.UseHorizontalViewAngleOff()

    record = {
        "mapper": MAPPERS[mapper_name],
        "sample_distance_voxels": sample_voxels,
        "sample_distance_world": sample_world,
        "scalar_opacity_unit_distance": unit_distance,
        "isotropic_voxels": isotropic,
        "threads": threads,
        "world_box": [lo, hi],
        "camera_world": cam,
        "transfer_function_stored": points,
        "value_range": list(value_range),
        "shade": lit,
        "light": sh["light"],
        "background": scene["background"],
        "cropping_planes": crop,
    }
    return window, renderer, volume, record


def finish(window):
    """Waits until the frame is drawn (the GPU mapper's commands are asynchronous)."""
    window.WaitForCompletion()


def capture(window, fault=""):
    """The window's RGB pixels as a numpy array, row 0 at the top (VTK's row 0 is the bottom)."""
    from vtkmodules.vtkRenderingCore import vtkWindowToImageFilter
    from vtkmodules.util.numpy_support import vtk_to_numpy
    import numpy as np

    grab = vtkWindowToImageFilter()
    grab.SetInput(window)
    grab.SetInputBufferTypeToRGB()
    grab.ReadFrontBufferOff()
    grab.ShouldRerenderOff()
    grab.Update()
    img = grab.GetOutput()
    w, h, _ = img.GetDimensions()
    rows = vtk_to_numpy(img.GetPointData().GetScalars()).reshape(h, w, 3)
    return np.ascontiguousarray(rows if fault == "flip" else rows[::-1])


def write_png(path, rgb):
    """An 8-bit RGB PNG of rgb (numpy, rows top first), with no gamma chunk: the values are the
    linear colours times 255, rounded, as brickyard writes (renderers/common/frame.cpp to_rgba8)."""
    h, w, _ = rgb.shape
    rows = b"".join(b"\x00" + rgb[y].tobytes() for y in range(h))

    def chunk(tag, data):
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)

    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
                + chunk(b"IDAT", zlib.compress(rows, 6)) + chunk(b"IEND", b""))


# --- check, scene -----------------------------------------------------------------------------


def cmd_check(a):
    s = load_scene_or_exit(a.scene)
    print(s["dataset"])


def cmd_scene(a):
    s = load_scene_or_exit(a.scene)
    j = dict(s["json"])
    j["dataset"] = os.path.abspath(a.store)
    j["image"] = dict(j.get("image", {}), width=a.width or s["width"], height=a.height or s["height"])
    if isinstance(j.get("camera_path"), str):
        j["camera_path"] = os.path.join(os.path.dirname(s["file"]), j["camera_path"])
    with open(a.out, "w") as f:
        json.dump(j, f, indent=2)
        f.write("\n")


def store_manifest(path):
    m = common.load_json(os.path.dirname(path) or ".", os.path.basename(path))
    if m.get("kind", "structured") != "structured":
        fail(f"{path}: a {m.get('kind')} store; the volume-rendering peers need a grid", 2)
    return m


# --- render: one peer -------------------------------------------------------------------------


def cmd_render(a):
    os.environ["LP_NUM_THREADS"] = str(a.threads)  # Mesa llvmpipe's threads, for the GPU mapper
    from vtkmodules.vtkCommonCore import vtkVersion

    scene = load_scene_or_exit(a.scene)
    manifest = store_manifest(a.manifest)
    value_range = [float(v) for v in manifest["value_range"]]
    common.init_smp("", a.threads)
    rss_before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024  # Python and VTK loaded
    image, side, read_s = read_volume(a.raw)
    if [int(d) for d in side["dims"]] != [int(d) for d in manifest["dims"]]:
        fail(f"{a.raw} is {side['dims']}, the store {manifest['dims']}: not the store's finest level")
    width, height = scene["width"], scene["height"]
    window, renderer, volume, record = translate(scene, side, value_range, a.mapper, a.sample_distance, a.threads,
                                                 width, height)
    volume.GetMapper().SetInputData(image)
    # The GL context, apart: an empty frame before the volume is added.
    t0 = time.perf_counter()
    window.Render()
    finish(window)
    context_s = time.perf_counter() - t0
    renderer.AddVolume(volume)
    renderer.ResetCameraClippingRange()
    times = []
    for _ in range(a.frames):
        t0 = time.perf_counter()
        window.Render()
        finish(window)
        times.append(time.perf_counter() - t0)
    rgb = capture(window)
    write_png(a.png, rgb)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024  # KiB on Linux

    gl = ""
    try:
        caps = window.ReportCapabilities()
        gl = next((line.split(":", 1)[1].strip() for line in caps.splitlines() if "renderer string" in line), "")
    except Exception:  # noqa: BLE001  (a report only)
        pass
    version = vtkVersion.GetVTKVersion()
    name = f"vtk-{a.mapper}"
    desc = f"VTK {version} {MAPPERS[a.mapper]}, {a.threads} thread{'s' if a.threads > 1 else ''}"
    if a.mapper == "gpu":
        desc += f", OpenGL on {gl or 'Mesa'} under Xvfb"
    out = {
        "name": name,
        "quality": f"sample={a.sample_distance:g}",
        "quality_value": a.sample_distance,
        "threads": a.threads,
        "first_frame_s": times[0],
        "steady_s": times[1:],
        "image": os.path.basename(a.png),
        "read_s": read_s,
        "peak_rss_bytes": peak,
        "description": desc,
        "context_s": context_s,
        "rss_before_read_bytes": rss_before,
        "vtk_version": version,
        "gl_renderer": gl,
        "dims": [int(d) for d in side["dims"]],
        "value_type": side["type"],
        "width": width,
        "height": height,
        "translation": record,
    }
    with open(a.json, "w") as f:
        json.dump(out, f, indent=2)
        f.write("\n")
    steady = statistics.median(times[1:]) if len(times) > 1 else float("nan")
    print(f"peers-dvr: {name} sample {a.sample_distance:g} voxels: read {read_s * 1e3:.0f} ms, first frame "
          f"{times[0] * 1e3:.1f} ms, steady {steady * 1e3:.1f} ms (median of {len(times) - 1}), peak RSS "
          f"{peak / 2**20:.0f} MiB", file=sys.stderr)


# --- collect: peers.json and the table ---------------------------------------------------------

PEER_KEYS = ("name", "quality", "quality_value", "threads", "first_frame_s", "steady_s", "image", "read_s",
             "peak_rss_bytes", "description")


def rmse(a, b):
    import numpy as np
    d = a[:, :, :3].astype(np.float64) - b[:, :, :3].astype(np.float64)
    return float(np.sqrt((d * d).mean()) / 255.0)


def cmd_collect(a):
    peers = []
    for path in a.peer:
        p = common.load_json(os.path.dirname(path) or ".", os.path.basename(path))
        peers.append(p)
    with open(os.path.join(a.out, "peers.json"), "w") as f:
        json.dump({"peers": [{k: p[k] for k in PEER_KEYS} for p in peers]}, f, indent=2)
        f.write("\n")
    ref = None
    if a.reference:
        ref = common.read_png(a.reference)
    print()
    print(f"peers-dvr: {a.title}")
    head = f"  {'peer':<16} {'quality':<12} {'read ms':>8} {'first ms':>9} {'steady ms':>10} {'peak MiB':>9}"
    if ref is not None:
        head += f" {'RMSE':>8}"
    print(head)
    for p in peers:
        row = (f"  {p['name']:<16} {p['quality']:<12} {p['read_s'] * 1e3:>8.1f} {p['first_frame_s'] * 1e3:>9.1f} "
               f"{(statistics.median(p['steady_s']) if p['steady_s'] else float('nan')) * 1e3:>10.1f} "
               f"{p['peak_rss_bytes'] / 2**20:>9.0f}")
        if ref is not None:
            img = common.read_png(os.path.join(a.out, p["image"]))
            row += f" {rmse(img, ref):>8.4f}" if img.shape[:2] == ref.shape[:2] else f" {'size?':>8}"
        print(row)
    if ref is not None:
        print(f"  RMSE: of the RGB in [0, 1] against {a.reference} (brickyard's reference back end)")
    print(f"  figures: {os.path.join(a.out, 'peers.json')} and the peers' own files beside it")


# --- selftest ---------------------------------------------------------------------------------


def synthetic(values, spacing, origin):
    import numpy as np
    v = np.ascontiguousarray(values.astype("<f4").transpose(2, 1, 0).reshape(-1))  # x fastest
    side = {"dims": list(values.shape), "type": "f32", "spacing": [spacing] * 3, "origin": list(origin)}
    return v, side


def synthetic_scene(camera, points, background, width, height):
    return {"width": width, "height": height, "camera": camera, "normalized": False, "points": points,
            "shading": {"light": "none", "light_direction": [0.3, 1, -0.6], "light_color": [1, 1, 1],
                        "ambient": 0.15, "diffuse": 0.75, "specular": 0.25, "shininess": 32.0, "normals": "analytic"},
            "background": background, "clip": None, "termination_opacity": 0.99, "sampling_rate": 1.0}


def render_vtk(scene, values, side, value_range, mapper, sample_voxels, fault):
    from vtkmodules.util.numpy_support import numpy_to_vtk  # noqa: F401
    image = image_data(values, side)
    window, renderer, volume, _ = translate(scene, side, value_range, mapper, sample_voxels, 1, scene["width"],
                                            scene["height"], fault)
    volume.GetMapper().SetInputData(image)
    renderer.AddVolume(volume)
    renderer.ResetCameraClippingRange()
    window.Render()
    finish(window)
    rgb = capture(window, fault)
    window.Finalize()
    return rgb


def render_brickyard(brickyard, work, name, scene, values, side, step, normalized_points=None):
    """The same synthetic volume and scene rendered by brickyard's reference back end: raw file,
    store, scene JSON, `brickyard render`; the PNG as numpy (rows top first)."""
    import subprocess
    raw = os.path.join(work, name + ".raw")
    values.tofile(raw)
    store = os.path.join(work, name + ".store")
    dims = ",".join(str(d) for d in side["dims"])
    spacing = ",".join(repr(float(s)) for s in side["spacing"])
    origin = ",".join(repr(float(o)) for o in side["origin"])
    cmds = [[brickyard, "-q", "import", raw, "--dims", dims, "--type", "f32", "--spacing", spacing, "--origin", origin,
             "--out", store]]
    cam = scene["camera"]
    sj = {
        "dataset": store, "backend": "reference", "image": {"width": scene["width"], "height": scene["height"]},
        "camera": {"eye": cam["eye"], "target": cam["target"], "up": cam["up"], "fov_degrees": cam["fov"]},
        "mode": "dvr", "values": "normalized" if normalized_points else "stored",
        "transfer_function": {"points": [{"value": p["value"], "color": p["color"], "opacity": p["opacity"]}
                                         for p in (normalized_points or scene["points"])]},
        "shading": {"light": "none"}, "background": scene["background"],
    }
    scene_path = os.path.join(work, name + ".json")
    with open(scene_path, "w") as f:
        json.dump(sj, f)
    png = os.path.join(work, name + ".png")
    cmds.append([brickyard, "-q", "render", scene_path, "-o", png, "--set", f"step={step!r}"])
    for c in cmds:
        r = subprocess.run(c, capture_output=True, text=True)
        if r.returncode != 0:
            fail(f"{' '.join(c)}: exit {r.returncode}: {r.stderr.strip()}")
    return common.read_png(png)[:, :, :3]


def slab_case(thickness, a):
    """A slab `thickness` voxels thick (the volume's z extent), seen from 40 voxels away, 10
    degrees off its normal: a volume of 30 inside a ring of 10 and 50, the transfer function in
    normalised values (0: none, 0.5: opacity a, 1: none), so that the store's range has to be
    mapped for the interior's 30 to get opacity a.

    Not exactly face-on: the fixed-point mapper counts a ray's steps from each axis's
    fixed-point direction, and a component near zero, rounded, ends a nearly axis-parallel ray
    up to 1/8 voxel early (with a step of 1/64 voxel; VTK's artefact, docs/peers.md)."""
    import numpy as np
    nx, ny, nz = 14, 12, thickness + 1
    v = np.full((nx, ny, nz), 30.0)
    v[0, :, :] = v[:, 0, :] = 10.0
    v[-1, :, :] = v[:, -1, :] = 50.0
    spacing, origin = 0.25, (-1.0, 2.0, 0.5)
    values, side = synthetic(v, spacing, origin)
    colour, background = [1.0, 0.5, 0.0], [0.0, 0.25, 1.0]
    normalized = [{"value": 0.0, "color": colour, "opacity": 0.0}, {"value": 0.5, "color": colour, "opacity": a},
                  {"value": 1.0, "color": colour, "opacity": 0.0}]
    theta, phi = math.radians(10.0), math.radians(35.0)
    view = [math.sin(theta) * math.cos(phi), math.sin(theta) * math.sin(phi), math.cos(theta)]
    extent = [spacing * (n - 1) for n in (nx, ny, nz)]
    eye = [0.5 + 40.0 * spacing * view[k] / extent[k] for k in range(3)]  # normalised coordinates
    camera = {"eye": eye, "target": [0.5, 0.5, 0.5], "up": [0.0, 1.0, 0.0], "fov": 6.0}
    scene = synthetic_scene(camera, normalized, background, 40, 30)
    scene["normalized"] = True
    return values, side, scene, (10.0, 50.0), normalized


def slab_expected(scene, side, a):
    """Per pixel: the colour brickyard's model gives (c a_L + background (1 - a_L), a_L = 1 - (1 -
    a)^L, L the ray's path through the slab in voxels) for rays that stay over the slab's
    interior (away from its ring), else None."""
    lo, hi = common.world_box(side)
    s = float(side["spacing"][0])
    cam = camera_in_box(scene["camera"], lo, hi)
    pin = PinholeCamera(cam, scene["width"], scene["height"])
    c, bg = scene["points"][1]["color"], scene["background"]
    exp = {}
    for y in range(scene["height"]):
        for x in range(scene["width"]):
            d = pin.ray(x + 0.5, y + 0.5)
            t_top, t_bottom = (hi[2] - cam["eye"][2]) / d[2], (lo[2] - cam["eye"][2]) / d[2]
            inside = True
            for t in (t_top, t_bottom):
                for ax in (0, 1):
                    p = cam["eye"][ax] + t * d[ax]
                    inside &= lo[ax] + 1.5 * s <= p <= hi[ax] - 1.5 * s
            if not inside:
                continue
            length = (t_bottom - t_top) / s
            alpha = 1 - (1 - a) ** length
            exp[(x, y)] = ([c[k] * alpha + bg[k] * (1 - alpha) for k in range(3)], length)
    return exp


def check_slab(rgb, exp, tol):
    worst, worst_at, n = 0.0, None, 0
    for (x, y), (colour, _) in exp.items():
        for k in range(3):
            e = abs(rgb[y, x, k] / 255.0 - colour[k])
            if e > worst:
                worst, worst_at = e, (x, y, k)
        n += 1
    return worst <= tol and n > 0, worst, worst_at, n


def convex_hull(points):
    pts = sorted(set(points))
    if len(pts) < 3:
        return pts

    def turn(o, a, b):
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
    lower, upper = [], []
    for p in pts:
        while len(lower) >= 2 and turn(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    for p in reversed(pts):
        while len(upper) >= 2 and turn(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    return lower[:-1] + upper[:-1]  # counter-clockwise (in x right, y down: clockwise on screen)


def hull_distance(hull, p):
    """Signed distance of p to the convex polygon's edge lines, the least of them: positive
    inside (the distance to the boundary), negative outside (at most the distance)."""
    best = math.inf
    for i in range(len(hull)):
        a, b = hull[i], hull[(i + 1) % len(hull)]
        ex, ey = b[0] - a[0], b[1] - a[1]
        n = math.hypot(ex, ey)
        best = min(best, (ex * (p[1] - a[1]) - ey * (p[0] - a[0])) / n)
    return best


def framing_case():
    """A 24x16x10 box of value 1 (green, opaque) with a 3-voxel block of value 2 (red) at its
    corner (x hi, y lo, z hi), seen from scenes/bench-dvr.json's camera in a 96x72 image."""
    import numpy as np
    v = np.ones((24, 16, 10))
    v[-3:, :3, -3:] = 2.0
    values, side = synthetic(v, 0.5, (3.0, -2.0, 1.0))
    points = [{"value": 1.0, "color": [0.0, 1.0, 0.0], "opacity": 1.0}, {"value": 2.0, "color": [1.0, 0.0, 0.0], "opacity": 1.0}]
    camera = {"eye": [1.6, -1.1, 1.4], "target": [0.5, 0.5, 0.45], "up": [0.0, 0.0, 1.0], "fov": 35.0}
    return values, side, synthetic_scene(camera, points, [0.0, 0.0, 0.0], 96, 72), (1.0, 2.0)


def check_framing(rgb, scene, side):
    """The box's silhouette against the hull of its corners projected by brickyard's camera:
    pixel centres more than 1 pixel inside are covered, more than 1 pixel outside are background;
    and the red marker and the green box are where the projection puts them (a flipped image
    puts them elsewhere)."""
    lo, hi = common.world_box(side)
    s = float(side["spacing"][0])
    cam = camera_in_box(scene["camera"], lo, hi)
    pin = PinholeCamera(cam, scene["width"], scene["height"])
    corners = [pin.pixel_of([(lo, hi)[(i >> a) & 1][a] for a in range(3)]) for i in range(8)]
    hull = convex_hull(corners)
    if hull_distance(hull, (sum(c[0] for c in hull) / len(hull), sum(c[1] for c in hull) / len(hull))) < 0:
        hull = hull[::-1]
    bad, worst = 0, 0.0
    for y in range(scene["height"]):
        for x in range(scene["width"]):
            d = hull_distance(hull, (x + 0.5, y + 0.5))
            covered = int(rgb[y, x, :3].max()) > 127
            if (d > 1.0 and not covered) or (d < -1.0 and covered):
                bad += 1
                worst = max(worst, abs(d))
    markers = []
    for name, p, want in (("red marker", [hi[0] - s, lo[1] + s, hi[2]], 0), ("green box", [lo[0] + 3 * s, lo[1] + s, hi[2]], 1)):
        px, py = pin.pixel_of(p)
        xi, yi = int(px), int(py)
        ok = 0 <= xi < scene["width"] and 0 <= yi < scene["height"]
        got = [int(v) for v in rgb[yi, xi, :3]] if ok else None
        ok = ok and got[want] > 127 and got[1 - want] < 64
        markers.append((name, (round(px, 2), round(py, 2)), got, ok))
    return bad == 0 and all(m[3] for m in markers), bad, worst, markers, corners


def cmd_selftest(a):
    import tempfile
    os.environ["LP_NUM_THREADS"] = "1"
    mappers = a.mappers.split(",")
    for m in mappers:
        if m not in MAPPERS:
            fail(f"--mappers: no mapper '{m}' (known: {', '.join(MAPPERS)})", 2)
    h = 1.0 / 64.0  # samples per voxel: VTK's count over a path of L voxels is L / h, give or take one
    results = []  # (check, passed, detail)
    cases = []
    for thickness, alpha in ((1, 0.4), (4, 0.4)):
        values, side, scene, value_range, normalized = slab_case(thickness, alpha)
        cases.append((thickness, alpha, values, side, scene, value_range, normalized))
    framing = framing_case()

    def record(name, ok, detail):
        results.append((name, ok, detail))
        print(f"  {'ok  ' if ok else 'FAIL'} {name}: {detail}")

    print(f"peers-dvr selftest: mappers {', '.join(mappers)}{', fault ' + a.fault if a.fault else ''}")
    for mapper in mappers:
        for thickness, alpha, values, side, scene, value_range, _ in cases:
            exp = slab_expected(scene, side, alpha)
            rgb = render_vtk(scene, values, side, value_range, mapper, h, a.fault)
            # The tolerance: a path h longer or shorter (one sample more or fewer than L / h),
            # and for the fixed-point mapper 0.02 voxel shorter (its ClipRayAgainstVolume keeps
            # rays 0.01 voxel inside each face), changes the opacity by at most 1 - (1 - a)^that,
            # times |colour - background| <= 1; 2/255 more for 8-bit and 15-bit rounding.
            lost = h + (0.02 if mapper == "fixed-point" else 0.0)
            tol = 1 - (1 - alpha) ** lost + 2 / 255
            ok, worst, at, n = check_slab(rgb, exp, tol)
            want = 1 - (1 - alpha) ** thickness
            record(f"{mapper}: {thickness}-voxel slab, opacity {alpha:g} per voxel",
                   ok, f"composited opacity 1-(1-{alpha:g})^{thickness} = {want:.4f} on its normal, per pixel "
                   f"1-(1-{alpha:g})^L along the ray; worst colour error "
                   f"{worst:.4f} (tolerance {tol:.4f}) over {n} pixels" + (f" at pixel {at[:2]} channel {at[2]}" if not ok and at else ""))
        values, side, scene, value_range = framing
        rgb = render_vtk(scene, values, side, value_range, mapper, 0.125, a.fault)
        ok, bad, worst, markers, _ = check_framing(rgb, scene, side)
        detail = f"{bad} pixels off the projected box by more than 1 pixel" + (f" (worst {worst:.1f})" if bad else "")
        detail += "; " + ", ".join(f"{m[0]} at {m[1]}: {m[2]}" for m in markers)
        record(f"{mapper}: box silhouette and markers where brickyard's camera projects them", ok, detail)
    if a.brickyard:
        # The expectations are brickyard's: its reference back end renders the same volumes.
        with tempfile.TemporaryDirectory(prefix="peers-dvr-selftest-") as work:
            for thickness, alpha, values, side, scene, value_range, normalized in cases:
                exp = slab_expected(scene, side, alpha)
                rgb = render_brickyard(a.brickyard, work, f"slab{thickness}", scene, values, side, h, normalized)
                tol = 1 - (1 - alpha) ** h + 2 / 255
                ok, worst, at, n = check_slab(rgb, exp, tol)
                record(f"brickyard reference: {thickness}-voxel slab", ok,
                       f"worst colour error {worst:.4f} (tolerance {tol:.4f}) over {n} pixels")
            values, side, scene, value_range = framing
            rgb = render_brickyard(a.brickyard, work, "framing", scene, values, side, 0.125)
            ok, bad, worst, markers, _ = check_framing(rgb, scene, side)
            record("brickyard reference: box silhouette and markers", ok,
                   f"{bad} pixels off by more than 1 pixel; " + ", ".join(f"{m[0]} at {m[1]}: {m[2]}" for m in markers))
    failed = [r for r in results if not r[1]]
    if failed:
        print(f"peers-dvr selftest: {len(failed)} of {len(results)} checks failed")
        sys.exit(1)
    print(f"peers-dvr selftest: all {len(results)} checks passed")


# --- main -------------------------------------------------------------------------------------


def main():
    p = argparse.ArgumentParser(prog="dvr.py", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="cmd", required=True)

    s = sub.add_parser("check")
    s.add_argument("--scene", required=True)

    s = sub.add_parser("scene")
    s.add_argument("--scene", required=True)
    s.add_argument("--store", required=True)
    s.add_argument("--width", type=int, default=0)
    s.add_argument("--height", type=int, default=0)
    s.add_argument("--out", required=True)

    s = sub.add_parser("render")
    s.add_argument("--scene", required=True)
    s.add_argument("--raw", required=True)
    s.add_argument("--manifest", required=True, help="`brickyard info --json` of the store")
    s.add_argument("--mapper", choices=sorted(MAPPERS), required=True)
    s.add_argument("--sample-distance", type=float, required=True, help="voxels")
    s.add_argument("--threads", type=int, default=2)
    s.add_argument("--frames", type=int, default=8)
    s.add_argument("--png", required=True)
    s.add_argument("--json", required=True)

    s = sub.add_parser("collect")
    s.add_argument("--out", required=True)
    s.add_argument("--peer", action="append", default=[])
    s.add_argument("--reference", default="")
    s.add_argument("--title", default="")

    s = sub.add_parser("selftest")
    s.add_argument("--mappers", default="fixed-point,gpu")
    s.add_argument("--brickyard", default="", help="also check brickyard's reference images of the same volumes")
    s.add_argument("--fault", choices=("", "unit-distance", "flip"), default="",
                   help="break the translation on purpose: the selftest must then fail")

    a = p.parse_args()
    {"check": cmd_check, "scene": cmd_scene, "render": cmd_render, "collect": cmd_collect,
     "selftest": cmd_selftest}[a.cmd](a)


if __name__ == "__main__":
    main()
