#!/usr/bin/python3
"""The Python side of bench/peers (peers.sh drives it; docs/peers.md says what it measures).

Subcommands:
  scene   write the brickyard scene: iso mode, one isovalue, a camera path of N frames that all
          hold the same camera (so every frame is timed and none is settled first)
  vtk     load the raw volume that brickyard generated (numpy.frombuffer -> vtkImageData with
          the sidecar's spacing and origin), run vtkFlyingEdges3D on it with vtkSMPTools limited
          to N threads, and write the triangles for embree_frame
  report  read the three sides' figures, check that Embree and brickyard saw the same camera
          (coverage masks and depth), print the table, write results.json and results.csv

Runs under Debian's /usr/bin/python3, whose python3-vtk9 and python3-numpy peers.sh installs.
"""

import argparse
import csv
import json
import math
import os
import statistics
import sys
import time


def fail(message, code=1):
    print(f"peers: {message}", file=sys.stderr)
    sys.exit(code)


def read_sidecar(raw):
    path = raw + ".json"
    try:
        with open(path) as f:
            side = json.load(f)
    except OSError as e:
        fail(f"{path}: {e.strerror}")
    for key in ("dims", "type", "spacing", "origin"):
        if key not in side:
            fail(f"{path}: no '{key}'")
    if side["type"] != "f32":
        fail(f"{path}: type {side['type']}; bench/peers generates f32 so that both sides see the same values")
    if side.get("endianness", "little") != "little":
        fail(f"{path}: big-endian raw files are not supported here")
    return side


def world_box(side):
    lo = [float(o) for o in side["origin"]]
    hi = [lo[a] + float(side["spacing"][a]) * (int(side["dims"][a]) - 1) for a in range(3)]
    return lo, hi


# --- scene ---------------------------------------------------------------------------------


def cmd_scene(a):
    camera = {"eye": a.eye, "target": a.target, "up": a.up}
    scene = {
        "description": "bench/peers: one isosurface, one camera repeated over every frame",
        "dataset": os.path.abspath(a.store),
        "backend": a.backend,
        "image": {"width": a.width, "height": a.height},
        # A path (not "camera"): the CLI times every frame of a path as rendered, where a still
        # camera would first be settled. One keyframe: CameraPath::at returns it exactly.
        "camera_path": {"frames": a.frames, "fov_degrees": a.fov, "keyframes": [camera]},
        "mode": "iso",
        "values": "stored",
        "isosurfaces": [{"value": a.iso, "color": [0.95, 0.75, 0.35]}],
        "shading": {"light": "headlight", "normals": "analytic"},
        "background": [0.08, 0.09, 0.11],
    }
    with open(a.out, "w") as f:
        json.dump(scene, f, indent=2)
        f.write("\n")


# --- vtk -----------------------------------------------------------------------------------


def cmd_vtk(a):
    import numpy as np
    from vtkmodules.vtkCommonCore import vtkSMPTools, vtkVersion
    from vtkmodules.vtkCommonDataModel import vtkImageData
    from vtkmodules.vtkFiltersCore import vtkFlyingEdges3D
    from vtkmodules.util.numpy_support import numpy_to_vtk, vtk_to_numpy

    side = read_sidecar(a.raw)
    dims = [int(d) for d in side["dims"]]
    t0 = time.perf_counter()
    with open(a.raw, "rb") as f:
        buf = f.read()
    if len(buf) != dims[0] * dims[1] * dims[2] * 4:
        fail(f"{a.raw}: {len(buf)} bytes, the sidecar's {dims} f32 needs {dims[0] * dims[1] * dims[2] * 4}")
    values = np.frombuffer(buf, dtype="<f4")  # x fastest, as VTK's point order
    image = vtkImageData()
    image.SetDimensions(*dims)
    image.SetSpacing(*[float(s) for s in side["spacing"]])
    image.SetOrigin(*[float(o) for o in side["origin"]])
    scalars = numpy_to_vtk(values, deep=False)  # no copy; `values` stays alive below
    scalars.SetName("values")
    image.GetPointData().SetScalars(scalars)
    load_ms = (time.perf_counter() - t0) * 1e3

    smp = vtkSMPTools()
    if a.smp_backend:
        smp.SetBackend(a.smp_backend)
        if smp.GetBackend() != a.smp_backend:
            fail(f"VTK has no SMP back end '{a.smp_backend}' (it uses {smp.GetBackend()})", 2)
    smp.Initialize(a.threads)

    fe = vtkFlyingEdges3D()
    fe.SetInputData(image)
    fe.SetValue(0, a.iso)
    # Positions and triangles only: what Embree's frame needs. Normals would cost VTK more.
    fe.ComputeNormalsOff()
    fe.ComputeGradientsOff()
    fe.ComputeScalarsOff()
    runs = []
    for _ in range(a.repeats):
        fe.Modified()
        t0 = time.perf_counter()
        fe.Update()
        runs.append((time.perf_counter() - t0) * 1e3)
    poly = fe.GetOutput()

    points = vtk_to_numpy(poly.GetPoints().GetData()).astype("<f4", copy=False) if poly.GetNumberOfPoints() else np.zeros((0, 3), "<f4")
    polys = poly.GetPolys()
    if polys.GetNumberOfCells():
        offsets = vtk_to_numpy(polys.GetOffsetsArray())
        if not np.all(np.diff(offsets) == 3):
            fail("vtkFlyingEdges3D produced a polygon that is not a triangle")
        tris = vtk_to_numpy(polys.GetConnectivityArray()).astype("<u4").reshape(-1, 3)
    else:
        tris = np.zeros((0, 3), "<u4")
    with open(a.mesh, "wb") as f:
        f.write(b"BYMESH01")
        f.write(np.array([len(points), len(tris)], "<u4").tobytes())
        f.write(np.ascontiguousarray(points).tobytes())
        f.write(np.ascontiguousarray(tris).tobytes())

    out = {
        "vtk_version": vtkVersion.GetVTKVersion(),
        "smp_backend": smp.GetBackend(),
        "threads": a.threads,
        "estimated_threads": smp.GetEstimatedNumberOfThreads(),
        "isovalue": a.iso,
        "dims": dims,
        "load_ms": load_ms,
        "flying_edges_runs_ms": runs,
        "flying_edges_first_ms": runs[0],
        "flying_edges_ms": statistics.median(runs),
        "points": int(len(points)),
        "triangles": int(len(tris)),
        "compute_normals": False,
    }
    with open(a.json, "w") as f:
        json.dump(out, f, indent=2)
        f.write("\n")
    print(f"peers: vtk: {out['triangles']} triangles, flying edges {out['flying_edges_ms']:.2f} ms "
          f"(median of {len(runs)}; first {runs[0]:.2f} ms) on {a.threads} threads, SMP back end {out['smp_backend']}",
          file=sys.stderr)
    if not len(tris):
        lo, hi = side.get("value_range", [float("nan"), float("nan")])
        fail(f"no surface at isovalue {a.iso:g}: {a.raw} holds values in [{lo:g}, {hi:g}]; choose --iso inside them")


# --- report --------------------------------------------------------------------------------


def read_png(path):
    """RGBA8 as a numpy array of rows, row 0 at the top (vtkPNGReader puts row 0 at the bottom)."""
    import numpy as np
    from vtkmodules.vtkIOImage import vtkPNGReader
    from vtkmodules.util.numpy_support import vtk_to_numpy

    if not os.path.exists(path):
        fail(f"{path}: brickyard wrote no such image")
    r = vtkPNGReader()
    r.SetFileName(path)
    r.Update()
    img = r.GetOutput()
    w, h, _ = img.GetDimensions()
    a = vtk_to_numpy(img.GetPointData().GetScalars())
    return np.ascontiguousarray(a.reshape(h, w, -1)[::-1])


def images_equal(a, b, tolerance=2, fraction=1e-3):
    """Whether two RGBA8 frames show the same image: at most `fraction` of the pixels differ
    by more than `tolerance` levels in any channel."""
    import numpy as np
    if a.shape != b.shape:
        return False
    differ = (np.abs(a.astype(np.int16) - b.astype(np.int16)) > tolerance).any(axis=2)
    return float(differ.mean()) <= fraction


def camera_check(side, embree_depth_path, by_depth_png, width, height):
    """Embree's float depth against brickyard's depth PNG (near 255, far 51, miss 0; grey =
    round(255 * (1 - 0.8 * (d - lo) / (hi - lo))) over the frame's finite depths)."""
    import numpy as np
    em = np.fromfile(embree_depth_path, dtype="<f4")
    if em.size != width * height:
        fail(f"{embree_depth_path}: {em.size} depths, expected {width}x{height}")
    em = em.reshape(height, width)
    grey = read_png(by_depth_png)[:, :, 0].astype(np.float64)
    if grey.shape != em.shape:
        fail(f"{by_depth_png}: {grey.shape[1]}x{grey.shape[0]}, Embree's frame is {width}x{height}")
    em_hit = np.isfinite(em)
    by_hit = grey > 0
    both = em_hit & by_hit
    out = {
        "embree_coverage": float(em_hit.mean()),
        "brickyard_coverage": float(by_hit.mean()),
        "coverage_mismatch": float((em_hit != by_hit).mean()),
        "embree_only": float((em_hit & ~by_hit).mean()),
        "brickyard_only": float((by_hit & ~em_hit).mean()),
    }
    voxel = min(float(s) for s in side["spacing"])
    if both.any():
        lo, hi = float(em[em_hit].min()), float(em[em_hit].max())
        span = hi - lo if hi > lo else 1.0
        # brickyard's depth, inverted from its grey level with Embree's near and far: a camera
        # that differs shifts or scales it; one grey level is `quantum` of depth.
        by_depth = lo + (1.0 - grey / 255.0) / 0.8 * span
        err = np.abs(by_depth[both] - em[both]) / voxel
        quantum = span / (0.8 * 255.0) / voxel
        out.update({
            "depth_median_voxels": float(np.median(err)),
            "depth_p99_voxels": float(np.percentile(err, 99)),
            "depth_quantum_voxels": float(quantum),
            "depth_within_2_quanta": float((err <= 2 * quantum + 1e-9).mean()),
        })
    return out


def median(values):
    return statistics.median(values) if values else float("nan")


def cmd_report(a):
    d = a.dir
    with open(os.path.join(d, "vtk.json")) as f:
        vtk = json.load(f)
    with open(os.path.join(d, "embree.json")) as f:
        emb = json.load(f)
    with open(os.path.join(d, "brickyard-stats.json")) as f:
        by = json.load(f)
    side = read_sidecar(a.raw)
    frames = by["frames"]
    if not frames:
        fail("brickyard's statistics hold no frame")
    seconds = [float(fr["seconds"]) for fr in frames]
    ids = [int(fr["frame"]) for fr in frames]
    colour = [read_png(os.path.join(d, "frames", f"colour_{i:04d}.png")) for i in ids]

    # The first complete frame: the first whose image is the last frame's. A synchronous back
    # end's frame 0 is; a progressive one's is not, and its time to the complete image is the
    # frames' times up to it (the loader works meanwhile, between frames too).
    last = colour[-1]
    k = next(i for i, c in enumerate(colour) if images_equal(c, last))
    steady_reached = len(colour) >= 2 and images_equal(colour[-2], last)
    steady_s = seconds[k + 1:] if len(seconds) > k + 1 else seconds[1:]
    by_first_ms = seconds[0] * 1e3
    by_complete_ms = sum(seconds[:k + 1]) * 1e3
    by_steady_ms = median(steady_s) * 1e3 if steady_s else float("nan")

    check = camera_check(side, os.path.join(d, "embree-depth.f32"),
                         os.path.join(d, "frames", f"depth_{ids[-1]:04d}.png"), a.width, a.height)

    peer_first_ms = vtk["flying_edges_ms"] + emb["build_ms"] + emb["first_frame_ms"]
    ratio_first = peer_first_ms / by_complete_ms if by_complete_ms > 0 else float("nan")
    ratio_steady = by_steady_ms / emb["steady_frame_ms"] if emb["steady_frame_ms"] > 0 else float("nan")

    results = {
        "setup": {
            "field": a.field, "size": side["dims"], "isovalue": a.iso, "width": a.width, "height": a.height,
            "threads": a.threads, "backend": by["backend"], "backend_params": by.get("params", {}),
            "camera": {"eye": a.eye, "target": a.target, "up": a.up, "fov_degrees": a.fov},
            "world_box": world_box(side), "raw": os.path.abspath(a.raw), "store": os.path.abspath(a.store),
        },
        "vtk": vtk,
        "embree": emb,
        "brickyard": {
            "backend": by["backend"],
            "frames": len(frames),
            "frame_ms": [s * 1e3 for s in seconds],
            "first_frame_ms": by_first_ms,
            "first_frame_complete": k == 0,
            "first_complete_frame": ids[k],
            "first_complete_ms": by_complete_ms,
            "steady_frames": len(steady_s),
            "steady_frame_ms": by_steady_ms,
            "steady_reached": steady_reached,
            "render_command_wall_ms": a.by_wall_ms,
            "bytes_read_first_frame": frames[0]["cache"]["bytes_read"],
        },
        "camera_check": check,
        "ratios": {
            "peer_first_over_brickyard_first": ratio_first,
            "brickyard_steady_over_embree_steady": ratio_steady,
        },
    }
    ok = check["coverage_mismatch"] < a.max_mismatch
    results["camera_check"]["max_mismatch"] = a.max_mismatch
    results["camera_check"]["agree"] = ok

    with open(os.path.join(d, "results.json"), "w") as f:
        json.dump(results, f, indent=2)
        f.write("\n")
    rows = [
        ("vtk_flying_edges", vtk["flying_edges_ms"],
         f"{vtk['triangles']} triangles, {vtk['estimated_threads']} threads, SMP {vtk['smp_backend']}, median of {len(vtk['flying_edges_runs_ms'])}"),
        ("embree_build", emb["build_ms"], f"rtcCommitScene, build quality {emb['build_quality']}, median of {emb['builds']}"),
        ("embree_first_frame", emb["first_frame_ms"], f"{a.width}x{a.height} primary rays"),
        ("embree_steady_frame", emb["steady_frame_ms"], f"median of {emb['steady_frames']}"),
        ("peer_first_total", peer_first_ms, "flying edges + build + first frame"),
        ("brickyard_first_frame", by_first_ms, f"{by['backend']} frame 0, cold cache"),
        ("brickyard_first_complete", by_complete_ms, f"frames 0-{ids[k]} summed"),
        ("brickyard_steady_frame", by_steady_ms, f"median of {len(steady_s)}"),
        ("brickyard_render_command", a.by_wall_ms, f"wall clock: store opened, {len(frames)} frames, PNGs written"),
    ]
    with open(os.path.join(d, "results.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["step", "ms", "note"])
        for name, ms, note in rows:
            w.writerow([name, f"{ms:.4f}", note])
        w.writerow(["ratio_peer_first_over_brickyard_first", f"{ratio_first:.4f}", "(vtk + embree build + embree first) / brickyard first complete"])
        w.writerow(["ratio_brickyard_steady_over_embree_steady", f"{ratio_steady:.4f}", "brickyard steady / embree steady"])
        w.writerow(["coverage_mismatch", f"{check['coverage_mismatch']:.6f}", "pixels hit by one side only"])

    dims = "x".join(str(n) for n in side["dims"])
    print()
    print(f"peers: {a.field} {dims} f32, isovalue {a.iso:g}, {a.width}x{a.height}, {a.threads} threads, brickyard back end {by['backend']}")
    print(f"  {'step':<28} {'ms':>10}  note")
    for name, ms, note in rows:
        print(f"  {name:<28} {ms:>10.2f}  {note}")
    print(f"  {'(vtk+build+first)/brickyard first':<40} {ratio_first:>7.3f}   >1: brickyard shows a new isovalue sooner")
    print(f"  {'brickyard steady / embree steady':<40} {ratio_steady:>7.3f}   <1: brickyard's steady frame is faster")
    if k > 0:
        print(f"  brickyard's frame 0 was not complete: its image matches the steady one from frame {ids[k]} on")
    if not steady_reached:
        print("  warning: brickyard's last two frames differ: it had not converged; raise --frames")
    c = check
    line = (f"  camera check: coverage embree {c['embree_coverage']:.4f}, brickyard {c['brickyard_coverage']:.4f}, "
            f"mismatch {c['coverage_mismatch']:.4%} (embree only {c['embree_only']:.4%}, brickyard only {c['brickyard_only']:.4%})")
    print(line)
    if "depth_median_voxels" in c:
        print(f"  depth: median {c['depth_median_voxels']:.3f} voxels, p99 {c['depth_p99_voxels']:.3f} voxels "
              f"(one grey level of the depth PNG = {c['depth_quantum_voxels']:.3f} voxels; "
              f"{c['depth_within_2_quanta']:.2%} within two levels)")
    print(f"  figures: {os.path.join(d, 'results.json')}, {os.path.join(d, 'results.csv')}")
    if not ok:
        print(f"peers: the camera check failed: {c['coverage_mismatch']:.2%} of the pixels are hit by one side only "
              f"(limit {a.max_mismatch:.2%}); the two sides did not render the same view", file=sys.stderr)
        sys.exit(3)
    print(f"  camera check passed (mismatch under {a.max_mismatch:.2%})")


# --- main ----------------------------------------------------------------------------------


def vec3(text):
    try:
        v = [float(x) for x in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not three comma-separated numbers")
    if len(v) != 3 or not all(math.isfinite(x) for x in v):
        raise argparse.ArgumentTypeError(f"'{text}' is not three comma-separated numbers")
    return v


def main():
    p = argparse.ArgumentParser(prog="peers.py", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="cmd", required=True)

    def camera_args(s):
        s.add_argument("--eye", type=vec3, required=True)
        s.add_argument("--target", type=vec3, required=True)
        s.add_argument("--up", type=vec3, required=True)
        s.add_argument("--fov", type=float, required=True)

    s = sub.add_parser("scene")
    s.add_argument("--store", required=True)
    s.add_argument("--backend", required=True)
    s.add_argument("--iso", type=float, required=True)
    s.add_argument("--width", type=int, required=True)
    s.add_argument("--height", type=int, required=True)
    s.add_argument("--frames", type=int, required=True)
    s.add_argument("--out", required=True)
    camera_args(s)

    s = sub.add_parser("vtk")
    s.add_argument("--raw", required=True)
    s.add_argument("--iso", type=float, required=True)
    s.add_argument("--threads", type=int, required=True)
    s.add_argument("--repeats", type=int, default=3)
    s.add_argument("--smp-backend", default="")
    s.add_argument("--mesh", required=True)
    s.add_argument("--json", required=True)

    s = sub.add_parser("report")
    s.add_argument("--dir", required=True)
    s.add_argument("--raw", required=True)
    s.add_argument("--store", required=True)
    s.add_argument("--field", required=True)
    s.add_argument("--iso", type=float, required=True)
    s.add_argument("--width", type=int, required=True)
    s.add_argument("--height", type=int, required=True)
    s.add_argument("--threads", type=int, required=True)
    s.add_argument("--by-wall-ms", type=float, required=True)
    s.add_argument("--max-mismatch", type=float, default=0.01)
    camera_args(s)

    a = p.parse_args()
    {"scene": cmd_scene, "vtk": cmd_vtk, "report": cmd_report}[a.cmd](a)


if __name__ == "__main__":
    main()
