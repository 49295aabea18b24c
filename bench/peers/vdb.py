#!/usr/bin/python3
"""The Python side of bench/peers/vdb.sh: OpenVDB's own ray tracer, vdb_render, next to brickyard's
back ends on a level set (docs/peers.md, "Level sets: vdb.sh"). Standard library only.

Subcommands:
  scene     write the brickyard scene both sides render: isosurface 0 of the level set, a white
            surface lit by a headlight with diffuse 1 and no ambient or specular term (what
            vdb_render's diffuse shader computes: the colour times max(0, n . -ray)), black
            background, the camera given in the box's normalised coordinates
  render    run vdb_render --frames times with the scene's camera translated (-translate the
            eye, -lookat the target, -up, -fov the horizontal field of view, -res, one sample a
            pixel), its read and ray-tracing times taken from its own -v report, and write
            peers.json (the form `brickyard bench --peers` reads)
  selftest  check the translation: a sphere level set (vdb_tool) must cover exactly the pixels
            whose rays through brickyard's pinhole camera meet the sphere, but within a pixel of
            its silhouette; with the field of view left vertical on purpose it must not
"""

import argparse
import json
import math
import os
import re
import resource
import statistics
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from dvr import PinholeCamera, camera_in_box  # noqa: E402  (brickyard's camera, mirrored)
import peers as common  # noqa: E402  (bench/peers/peers.py: fail, world_box)

common.ME = "peers-vdb"
ME = common.ME
fail = common.fail
world_box = common.world_box  # of a manifest, as of a sidecar: both have dims, spacing, origin


def vec3(text, what):
    try:
        v = [float(x) for x in text.split(",")]
    except ValueError:
        v = []
    if len(v) != 3 or not all(math.isfinite(x) for x in v):
        fail(f"{what}: '{text}' is not X,Y,Z", 2)
    return v


# --- the translation ---------------------------------------------------------------------------


def horizontal_fov(vertical_degrees, width, height):
    """vdb_render's -fov is the horizontal angle (its film's aperture is the width); brickyard's
    is the vertical one, over the whole image height."""
    return math.degrees(2 * math.atan(math.tan(math.radians(vertical_degrees) / 2) * width / height))


def vdb_render_args(cam_world, width, height, threads, fault=""):
    fov = cam_world["fov"] if fault == "vertical-fov" else horizontal_fov(cam_world["fov"], width, height)
    fmt = lambda v: ",".join(f"{x:.9g}" for x in v)  # noqa: E731
    return ["-translate", fmt(cam_world["eye"]), "-lookat", fmt(cam_world["target"]), "-up", fmt(cam_world["up"]),
            "-fov", f"{fov:.9g}", "-res", f"{width}x{height}", "-shader", "diffuse", "-samples", "1", "-isovalue", "0",
            "-cpus", str(threads), "-v"]


def run_vdb_render(vdb, image, args):
    """Runs vdb_render; returns (read seconds, ray-tracing seconds) from its -v report."""
    p = subprocess.run(["vdb_render", vdb, image] + args, capture_output=True, text=True)
    out = p.stdout + p.stderr
    if p.returncode != 0:
        fail(f"vdb_render {vdb} exited {p.returncode}:\n{out}")
    times = re.findall(r"completed in ([0-9.eE+-]+) sec", out)
    if len(times) < 2:
        fail(f"vdb_render printed no read and ray-tracing times:\n{out}")
    return float(times[0]), float(times[-1])


# --- scene ---------------------------------------------------------------------------------


def cmd_scene(a):
    scene = {
        "description": "bench/peers/vdb.sh: the level set's zero isosurface, lit as vdb_render's diffuse shader",
        "dataset": os.path.abspath(a.store),
        "backend": "gigavoxels",
        "image": {"width": a.width, "height": a.height},
        "camera": {"eye": vec3(a.eye, "--eye"), "target": vec3(a.target, "--target"), "up": vec3(a.up, "--up"),
                   "fov_degrees": a.fov},
        "mode": "iso",
        "values": "stored",
        "isosurfaces": [{"value": 0.0, "color": [1, 1, 1]}],
        "shading": {"light": "headlight", "ambient": 0.0, "diffuse": 1.0, "specular": 0.0, "normals": "analytic"},
        "background": [0, 0, 0],
    }
    with open(a.out, "w") as f:
        json.dump(scene, f, indent=2)
        f.write("\n")


def scene_camera_world(scene, manifest):
    c = scene["camera"]
    cam = {"eye": c["eye"], "target": c["target"], "up": c["up"], "fov": c["fov_degrees"]}
    return camera_in_box(cam, *world_box(manifest))


# --- render ---------------------------------------------------------------------------------


def cmd_render(a):
    with open(a.scene) as f:
        scene = json.load(f)
    with open(a.manifest) as f:
        manifest = json.load(f)
    w, h = scene["image"]["width"], scene["image"]["height"]
    cam = scene_camera_world(scene, manifest)
    args = vdb_render_args(cam, w, h, a.threads)
    image = os.path.join(a.out, "vdb_render.png")
    runs = [run_vdb_render(a.vdb, image, args) for _ in range(a.frames)]
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss * 1024
    version = subprocess.run(["vdb_render", "-version"], capture_output=True, text=True).stdout.strip().split()[-1:]
    peer = {
        "name": "vdb_render",
        "quality": "samples=1",
        "quality_value": 1,
        "threads": a.threads,
        # A fresh process each run: the first frame is the first run's read and ray tracing.
        "first_frame_s": runs[0][0] + runs[0][1],
        "steady_s": [r[1] for r in runs[1:]],
        "image": "vdb_render.png",
        "read_s": runs[0][0],
        "peak_rss_bytes": peak,
        "description": f"OpenVDB {' '.join(version) or ''} vdb_render, diffuse shader, one ray a pixel, "
                       f"{a.threads} thread{'s' if a.threads > 1 else ''}: {' '.join(args)}",
    }
    with open(os.path.join(a.out, "peers.json"), "w") as f:
        json.dump({"peers": [peer]}, f, indent=2)
        f.write("\n")
    steady = statistics.median(peer["steady_s"]) if peer["steady_s"] else float("nan")
    print(f"{ME}: vdb_render: read {runs[0][0] * 1e3:.1f} ms, first frame {peer['first_frame_s'] * 1e3:.1f} ms, "
          f"steady {steady * 1e3:.1f} ms (median of {len(peer['steady_s'])}), peak RSS {peak / 2**20:.0f} MiB",
          file=sys.stderr)


# --- selftest -------------------------------------------------------------------------------


def read_ppm(path):
    with open(path, "rb") as f:
        data = f.read()
    m = re.match(rb"P6\s+(\d+)\s+(\d+)\s+(\d+)\s", data)
    if not m:
        fail(f"{path}: not a binary PPM")
    w, h = int(m.group(1)), int(m.group(2))
    pixels = data[m.end():]
    return w, h, [[pixels[3 * (y * w + x):3 * (y * w + x) + 3] for x in range(w)] for y in range(h)]


def cmd_selftest(a):
    centre, radius = [0.2, -0.1, 0.3], 0.6
    failures = 0
    with tempfile.TemporaryDirectory(prefix="peers-vdb-selftest-") as work:
        vdb = os.path.join(work, "sphere.vdb")
        p = subprocess.run(["vdb_tool", "-sphere", "d=96", f"r={radius}", "c=" + ",".join(map(str, centre)), "-write", vdb],
                           capture_output=True, text=True)
        if p.returncode != 0:
            fail(f"vdb_tool could not make a sphere:\n{p.stdout}{p.stderr}")
        for name, w, h, cam in (("wide", 80, 48, {"eye": [1.9, 1.3, 2.2], "target": [0.2, -0.1, 0.3], "up": [0, 1, 0], "fov": 35}),
                                ("tall", 40, 64, {"eye": [-1.5, 0.9, -1.7], "target": [0.35, 0.05, 0.3], "up": [0, 0, 1], "fov": 50})):
            image = os.path.join(work, name + ".ppm")
            run_vdb_render(vdb, image, vdb_render_args(cam, w, h, 1, a.fault))
            pw, ph, rgb = read_ppm(image)
            pin = PinholeCamera(cam, w, h)
            wrong = near = 0
            for y in range(h):
                for x in range(w):
                    d = pin.ray(x + 0.5, y + 0.5)
                    oc = [pin.eye[i] - centre[i] for i in range(3)]
                    b = sum(oc[i] * d[i] for i in range(3))
                    dist = math.sqrt(max(0.0, sum(c * c for c in oc) - b * b))  # ray's distance to the centre
                    hit_expected = dist < radius and b < 0
                    hit = max(rgb[y][x]) > 0
                    # A pixel's width at the sphere's distance: the silhouette may fall either side.
                    pixel = math.sqrt(sum(c * c for c in oc)) * 2 * pin.tan_half_fov / h
                    if hit != hit_expected:
                        if abs(dist - radius) <= 1.5 * pixel:
                            near += 1
                        else:
                            wrong += 1
            ok = wrong == 0 and (pw, ph) == (w, h)
            failures += not ok
            print(f"  {'ok  ' if ok else 'FAIL'} {name} {w}x{h}: {wrong} pixels disagree away from the silhouette, "
                  f"{near} within 1.5 pixels of it")
    if failures:
        print(f"{ME} selftest: {failures} checks failed")
        sys.exit(1)
    print(f"{ME} selftest: all checks passed")


def main():
    p = argparse.ArgumentParser(prog="vdb.py", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="cmd", required=True)
    s = sub.add_parser("scene")
    s.add_argument("--store", required=True)
    s.add_argument("--width", type=int, default=512)
    s.add_argument("--height", type=int, default=512)
    s.add_argument("--eye", default="1.6,-1.1,1.4")
    s.add_argument("--target", default="0.5,0.5,0.5")
    s.add_argument("--up", default="0,0,1")
    s.add_argument("--fov", type=float, default=35)
    s.add_argument("--out", required=True)
    s = sub.add_parser("render")
    s.add_argument("--scene", required=True)
    s.add_argument("--manifest", required=True)
    s.add_argument("--vdb", required=True)
    s.add_argument("--threads", type=int, default=2)
    s.add_argument("--frames", type=int, default=5)
    s.add_argument("--out", required=True)
    s = sub.add_parser("selftest")
    s.add_argument("--fault", choices=("", "vertical-fov"), default="")
    a = p.parse_args()
    {"scene": cmd_scene, "render": cmd_render, "selftest": cmd_selftest}[a.cmd](a)


if __name__ == "__main__":
    main()
