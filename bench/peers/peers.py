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

and for tetrahedral meshes (tets.sh drives them):
  tets-vtk     read the .vtu that brickyard exported from its store (vtkXMLUnstructuredGridReader,
               timed apart), run vtkContour3DLinearGrid on it with vtkSMPTools limited to N
               threads, and write the triangles for embree_frame
  tets-report  as report, for the mesh: VTK's extraction against brickyard's first frame

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


ME = "peers"  # the prefix of messages; dvr.py, which imports this module, sets its own


def fail(message, code=1):
    print(f"{ME}: {message}", file=sys.stderr)
    sys.exit(code)


def read_sidecar(raw, types=("f32",)):
    """A raw file's sidecar (FILE.raw.json, as `brickyard generate` and `export` write it), of a
    value type among `types`: bench/peers generates f32 for the isosurface peers, so that both
    sides see the same values; dvr.py reads the store's own type."""
    path = raw + ".json"
    try:
        with open(path) as f:
            side = json.load(f)
    except OSError as e:
        fail(f"{path}: {e.strerror}")
    for key in ("dims", "type", "spacing", "origin"):
        if key not in side:
            fail(f"{path}: no '{key}'")
    if side["type"] not in types:
        fail(f"{path}: type {side['type']}; expected {' or '.join(types)}")
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


def init_smp(backend, threads):
    """vtkSMPTools on `backend` (VTK's own when empty), limited to `threads` threads."""
    from vtkmodules.vtkCommonCore import vtkSMPTools

    smp = vtkSMPTools()
    if backend:
        smp.SetBackend(backend)
        if smp.GetBackend() != backend:
            fail(f"VTK has no SMP back end '{backend}' (it uses {smp.GetBackend()})", 2)
    smp.Initialize(threads)
    return smp


def triangles_of(poly, who):
    """A vtkPolyData's points (float32, N x 3) and triangles (uint32, M x 3); fails on a polygon
    that is not a triangle."""
    import numpy as np
    from vtkmodules.util.numpy_support import vtk_to_numpy

    points = vtk_to_numpy(poly.GetPoints().GetData()).astype("<f4", copy=False) if poly.GetNumberOfPoints() else np.zeros((0, 3), "<f4")
    polys = poly.GetPolys()
    if polys.GetNumberOfCells():
        offsets = vtk_to_numpy(polys.GetOffsetsArray())
        if not np.all(np.diff(offsets) == 3):
            fail(f"{who} produced a polygon that is not a triangle")
        tris = vtk_to_numpy(polys.GetConnectivityArray()).astype("<u4").reshape(-1, 3)
    else:
        tris = np.zeros((0, 3), "<u4")
    return points, tris


def write_bymesh(path, points, tris):
    """The triangles for embree_frame: "BYMESH01", uint32 vertex and triangle counts, float32
    x,y,z per vertex, uint32 a,b,c per triangle, little-endian."""
    import numpy as np

    with open(path, "wb") as f:
        f.write(b"BYMESH01")
        f.write(np.array([len(points), len(tris)], "<u4").tobytes())
        f.write(np.ascontiguousarray(points).tobytes())
        f.write(np.ascontiguousarray(tris).tobytes())


def timed_updates(algorithm, repeats):
    """Milliseconds of each of `repeats` full re-executions of a VTK algorithm."""
    runs = []
    for _ in range(repeats):
        algorithm.Modified()
        t0 = time.perf_counter()
        algorithm.Update()
        runs.append((time.perf_counter() - t0) * 1e3)
    return runs


def cmd_vtk(a):
    import numpy as np
    from vtkmodules.vtkCommonCore import vtkVersion
    from vtkmodules.vtkCommonDataModel import vtkImageData
    from vtkmodules.vtkFiltersCore import vtkFlyingEdges3D
    from vtkmodules.util.numpy_support import numpy_to_vtk

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

    smp = init_smp(a.smp_backend, a.threads)

    fe = vtkFlyingEdges3D()
    fe.SetInputData(image)
    fe.SetValue(0, a.iso)
    # Positions and triangles only: what Embree's frame needs. Normals would cost VTK more.
    fe.ComputeNormalsOff()
    fe.ComputeGradientsOff()
    fe.ComputeScalarsOff()
    runs = timed_updates(fe, a.repeats)
    points, tris = triangles_of(fe.GetOutput(), "vtkFlyingEdges3D")
    write_bymesh(a.mesh, points, tris)

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


def camera_check(unit, embree_depth_path, by_depth_png, width, height, unit_name="voxels"):
    """Embree's float depth against brickyard's depth PNG (near 255, far 51, miss 0; grey =
    round(255 * (1 - 0.8 * (d - lo) / (hi - lo))) over the frame's finite depths). Depth
    differences are in `unit` lengths (a voxel; a mesh's unit length), keys named by `unit_name`."""
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
        "depth_unit": unit_name,
    }
    if both.any():
        # brickyard's depth, inverted from its grey level with its near and far as Embree sees
        # them: Embree's depth at the pixels brickyard draws nearest (grey 255) and farthest
        # (grey 51), not Embree's own extremes, which a single ray through a crack between
        # triangles would set. One grey level is `quantum` of depth.
        near, far = both & (grey == 255), both & (grey == 51)
        lo = float(em[near].min()) if near.any() else float(em[em_hit].min())
        hi = float(em[far].max()) if far.any() else float(em[em_hit].max())
        span = hi - lo if hi > lo else 1.0
        by_depth = lo + (1.0 - grey / 255.0) / 0.8 * span
        err = np.abs(by_depth[both] - em[both]) / unit
        quantum = span / (0.8 * 255.0) / unit
        out.update({
            f"depth_median_{unit_name}": float(np.median(err)),
            f"depth_p99_{unit_name}": float(np.percentile(err, 99)),
            f"depth_quantum_{unit_name}": float(quantum),
            "depth_within_2_quanta": float((err <= 2 * quantum + 1e-9).mean()),
            "depth_beyond_2_quanta_pixels": int((err > 2 * quantum + 1e-9).sum()),
        })
    return out


def print_camera_check(c, unit_name, unit_words):
    print(f"  camera check: coverage embree {c['embree_coverage']:.4f}, brickyard {c['brickyard_coverage']:.4f}, "
          f"mismatch {c['coverage_mismatch']:.4%} (embree only {c['embree_only']:.4%}, brickyard only {c['brickyard_only']:.4%})")
    if f"depth_median_{unit_name}" in c:
        print(f"  depth: median {c[f'depth_median_{unit_name}']:.3f} {unit_words}, p99 {c[f'depth_p99_{unit_name}']:.3f} {unit_words} "
              f"(one grey level of the depth PNG = {c[f'depth_quantum_{unit_name}']:.3f} {unit_words}; "
              f"{c['depth_within_2_quanta']:.2%} within two levels, {c['depth_beyond_2_quanta_pixels']} pixels beyond)")


def camera_verdict(c, max_mismatch):
    """Exits 3 when more than `max_mismatch` of the pixels are hit by one side only."""
    if c["coverage_mismatch"] >= max_mismatch:
        print(f"peers: the camera check failed: {c['coverage_mismatch']:.2%} of the pixels are hit by one side only "
              f"(limit {max_mismatch:.2%}); the two sides did not render the same view", file=sys.stderr)
        sys.exit(3)
    print(f"  camera check passed (mismatch under {max_mismatch:.2%})")


def median(values):
    return statistics.median(values) if values else float("nan")


def load_json(d, name):
    path = os.path.join(d, name)
    try:
        with open(path) as f:
            return json.load(f)
    except OSError as e:
        fail(f"{path}: {e.strerror}")


def brickyard_side(d):
    """brickyard's frames (OUT/brickyard-stats.json and OUT/frames/colour_NNNN.png): frame 0, the
    first complete frame and the steady ones after it.

    The first complete frame: the first whose image is the last frame's. A synchronous back
    end's frame 0 is; a progressive one's is not, and its time to the complete image is the
    frames' times up to it (the loader works meanwhile, between frames too)."""
    by = load_json(d, "brickyard-stats.json")
    frames = by["frames"]
    if not frames:
        fail("brickyard's statistics hold no frame")
    seconds = [float(fr["seconds"]) for fr in frames]
    ids = [int(fr["frame"]) for fr in frames]
    colour = [read_png(os.path.join(d, "frames", f"colour_{i:04d}.png")) for i in ids]
    last = colour[-1]
    k = next(i for i, c in enumerate(colour) if images_equal(c, last))
    steady_s = seconds[k + 1:] if len(seconds) > k + 1 else seconds[1:]
    return {
        "stats": by,
        "ids": ids,
        "k": k,
        "seconds": seconds,
        "steady_s": steady_s,
        "steady_reached": len(colour) >= 2 and images_equal(colour[-2], last),
        "first_ms": seconds[0] * 1e3,
        "complete_ms": sum(seconds[:k + 1]) * 1e3,
        "steady_ms": median(steady_s) * 1e3 if steady_s else float("nan"),
        "last_depth_png": os.path.join(d, "frames", f"depth_{ids[-1]:04d}.png"),
    }


def brickyard_results(b, wall_ms):
    frames = b["stats"]["frames"]
    return {
        "backend": b["stats"]["backend"],
        "frames": len(frames),
        "frame_ms": [s * 1e3 for s in b["seconds"]],
        "first_frame_ms": b["first_ms"],
        "first_frame_complete": b["k"] == 0,
        "first_complete_frame": b["ids"][b["k"]],
        "first_complete_ms": b["complete_ms"],
        "steady_frames": len(b["steady_s"]),
        "steady_frame_ms": b["steady_ms"],
        "steady_reached": b["steady_reached"],
        "render_command_wall_ms": wall_ms,
        "bytes_read_first_frame": frames[0]["cache"]["bytes_read"],
    }


def ratio(a, b):
    return a / b if b > 0 else float("nan")


def write_tables(d, results, rows, extra):
    """results.json; results.csv: the rows (step, ms, note), then `extra` (name, value, note)."""
    with open(os.path.join(d, "results.json"), "w") as f:
        json.dump(results, f, indent=2)
        f.write("\n")
    with open(os.path.join(d, "results.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["step", "ms", "note"])
        for name, ms, note in rows:
            w.writerow([name, f"{ms:.4f}", note])
        for name, value, fmt, note in extra:
            w.writerow([name, format(value, fmt), note])


def print_rows(rows):
    print(f"  {'step':<28} {'ms':>10}  note")
    for name, ms, note in rows:
        print(f"  {name:<28} {ms:>10.2f}  {note}")


def print_brickyard_warnings(b):
    if b["k"] > 0:
        print(f"  brickyard's frame 0 was not complete: its image matches the steady one from frame {b['ids'][b['k']]} on")
    if not b["steady_reached"]:
        print("  warning: brickyard's last two frames differ: it had not converged; raise --frames")


def cmd_report(a):
    d = a.dir
    vtk = load_json(d, "vtk.json")
    emb = load_json(d, "embree.json")
    side = read_sidecar(a.raw)
    b = brickyard_side(d)
    by = b["stats"]
    k, ids = b["k"], b["ids"]
    by_first_ms, by_complete_ms, by_steady_ms = b["first_ms"], b["complete_ms"], b["steady_ms"]

    check = camera_check(min(float(s) for s in side["spacing"]), os.path.join(d, "embree-depth.f32"),
                         b["last_depth_png"], a.width, a.height)

    peer_first_ms = vtk["flying_edges_ms"] + emb["build_ms"] + emb["first_frame_ms"]
    ratio_first = ratio(peer_first_ms, by_complete_ms)
    ratio_steady = ratio(by_steady_ms, emb["steady_frame_ms"])

    results = {
        "setup": {
            "field": a.field, "size": side["dims"], "isovalue": a.iso, "width": a.width, "height": a.height,
            "threads": a.threads, "backend": by["backend"], "backend_params": by.get("params", {}),
            "camera": {"eye": a.eye, "target": a.target, "up": a.up, "fov_degrees": a.fov},
            "world_box": world_box(side), "raw": os.path.abspath(a.raw), "store": os.path.abspath(a.store),
        },
        "vtk": vtk,
        "embree": emb,
        "brickyard": brickyard_results(b, a.by_wall_ms),
        "camera_check": check,
        "ratios": {
            "peer_first_over_brickyard_first": ratio_first,
            "brickyard_steady_over_embree_steady": ratio_steady,
        },
    }
    ok = check["coverage_mismatch"] < a.max_mismatch
    results["camera_check"]["max_mismatch"] = a.max_mismatch
    results["camera_check"]["agree"] = ok

    rows = [
        ("vtk_flying_edges", vtk["flying_edges_ms"],
         f"{vtk['triangles']} triangles, {vtk['estimated_threads']} threads, SMP {vtk['smp_backend']}, median of {len(vtk['flying_edges_runs_ms'])}"),
        ("embree_build", emb["build_ms"], f"rtcCommitScene, build quality {emb['build_quality']}, median of {emb['builds']}"),
        ("embree_first_frame", emb["first_frame_ms"], f"{a.width}x{a.height} primary rays"),
        ("embree_steady_frame", emb["steady_frame_ms"], f"median of {emb['steady_frames']}"),
        ("peer_first_total", peer_first_ms, "flying edges + build + first frame"),
        ("brickyard_first_frame", by_first_ms, f"{by['backend']} frame 0, cold cache"),
        ("brickyard_first_complete", by_complete_ms, f"frames 0-{ids[k]} summed"),
        ("brickyard_steady_frame", by_steady_ms, f"median of {len(b['steady_s'])}"),
        ("brickyard_render_command", a.by_wall_ms, f"wall clock: store opened, {len(ids)} frames, PNGs written"),
    ]
    write_tables(d, results, rows, [
        ("ratio_peer_first_over_brickyard_first", ratio_first, ".4f", "(vtk + embree build + embree first) / brickyard first complete"),
        ("ratio_brickyard_steady_over_embree_steady", ratio_steady, ".4f", "brickyard steady / embree steady"),
        ("coverage_mismatch", check["coverage_mismatch"], ".6f", "pixels hit by one side only"),
    ])

    dims = "x".join(str(n) for n in side["dims"])
    print()
    print(f"peers: {a.field} {dims} f32, isovalue {a.iso:g}, {a.width}x{a.height}, {a.threads} threads, brickyard back end {by['backend']}")
    print_rows(rows)
    print(f"  {'(vtk+build+first)/brickyard first':<40} {ratio_first:>7.3f}   >1: brickyard shows a new isovalue sooner")
    print(f"  {'brickyard steady / embree steady':<40} {ratio_steady:>7.3f}   <1: brickyard's steady frame is faster")
    print_brickyard_warnings(b)
    print_camera_check(check, "voxels", "voxels")
    print(f"  figures: {os.path.join(d, 'results.json')}, {os.path.join(d, 'results.csv')}")
    camera_verdict(check, a.max_mismatch)


# --- tetrahedral meshes --------------------------------------------------------------------


VTK_TETRA = 10


def cmd_tets_vtk(a):
    import numpy as np
    from vtkmodules.vtkCommonCore import vtkVersion
    from vtkmodules.vtkCommonDataModel import vtkDataObject
    from vtkmodules.vtkFiltersCore import vtkContour3DLinearGrid
    from vtkmodules.vtkIOXML import vtkXMLUnstructuredGridReader
    from vtkmodules.util.numpy_support import vtk_to_numpy

    if not os.path.exists(a.vtu):
        fail(f"{a.vtu}: no such file")
    # The reader: timed apart, not part of the extraction (brickyard's store is written once too).
    t0 = time.perf_counter()
    reader = vtkXMLUnstructuredGridReader()
    reader.SetFileName(a.vtu)
    reader.Update()
    grid = reader.GetOutput()
    read_ms = (time.perf_counter() - t0) * 1e3
    if grid is None or grid.GetNumberOfCells() == 0:
        fail(f"{a.vtu}: vtkXMLUnstructuredGridReader read no cells")
    types = vtk_to_numpy(grid.GetCellTypesArray())
    if not np.all(types == VTK_TETRA):
        fail(f"{a.vtu}: {int(np.count_nonzero(types != VTK_TETRA))} of its {len(types)} cells are not tetrahedra")

    # The scalar: the array named, else the active scalars, else the first one-component point array.
    pd = grid.GetPointData()
    names = [pd.GetArrayName(i) for i in range(pd.GetNumberOfArrays())
             if pd.GetArray(i) is not None and pd.GetArray(i).GetNumberOfComponents() == 1]
    if a.array:
        if a.array not in names:
            fail(f"{a.vtu}: no one-component point array '{a.array}' (it has: {', '.join(names) or 'none'})")
        name = a.array
    elif pd.GetScalars() is not None and pd.GetScalars().GetNumberOfComponents() == 1:
        name = pd.GetScalars().GetName()
    elif names:
        name = names[0]
    else:
        fail(f"{a.vtu}: no one-component point array to contour")
    pd.SetActiveScalars(name)
    values = vtk_to_numpy(pd.GetArray(name))
    value_range = [float(values.min()), float(values.max())]
    if not vtkContour3DLinearGrid.CanFullyProcessDataObject(grid, name):
        fail(f"{a.vtu}: vtkContour3DLinearGrid cannot fully process this grid (its array '{name}'), so it would not be timed fairly")

    smp = init_smp(a.smp_backend, a.threads)
    cg = vtkContour3DLinearGrid()
    cg.SetInputData(grid)
    cg.SetInputArrayToProcess(0, 0, 0, vtkDataObject.FIELD_ASSOCIATION_POINTS, name)
    cg.SetValue(0, a.iso)
    # Positions and triangles only, as embree_frame needs; points merged or not (VTK's default:
    # not, three points a triangle), no scalar tree (it pays off over many isovalues only).
    cg.SetMergePoints(bool(a.merge_points))
    cg.InterpolateAttributesOff()
    cg.ComputeNormalsOff()
    cg.ComputeScalarsOff()
    cg.UseScalarTreeOff()
    runs = timed_updates(cg, a.repeats)
    points, tris = triangles_of(cg.GetOutput(), "vtkContour3DLinearGrid")
    write_bymesh(a.mesh, points, tris)

    out = {
        "vtk_version": vtkVersion.GetVTKVersion(),
        "smp_backend": smp.GetBackend(),
        "threads": a.threads,
        "estimated_threads": smp.GetEstimatedNumberOfThreads(),
        "threads_used": cg.GetNumberOfThreadsUsed(),
        "isovalue": a.iso,
        "array": name,
        "value_range": value_range,
        "cells": int(grid.GetNumberOfCells()),
        "mesh_points": int(grid.GetNumberOfPoints()),
        "read_ms": read_ms,
        "contour_runs_ms": runs,
        "contour_first_ms": runs[0],
        "contour_ms": statistics.median(runs),
        "merge_points": bool(a.merge_points),
        "points": int(len(points)),
        "triangles": int(len(tris)),
        "compute_normals": False,
    }
    with open(a.json, "w") as f:
        json.dump(out, f, indent=2)
        f.write("\n")
    print(f"peers-tets: vtk: read {out['cells']} tets in {read_ms:.1f} ms (not counted); {out['triangles']} triangles, "
          f"vtkContour3DLinearGrid {out['contour_ms']:.2f} ms (median of {len(runs)}; first {runs[0]:.2f} ms) "
          f"on {a.threads} threads ({out['threads_used']} used), SMP back end {out['smp_backend']}", file=sys.stderr)
    if not len(tris):
        fail(f"no surface at isovalue {a.iso:g}: array '{name}' of {a.vtu} holds values in "
             f"[{value_range[0]:g}, {value_range[1]:g}]; choose --iso inside them")


def mesh_of(manifest_path):
    """The store's mesh from `brickyard info --json`: its box (world units), tetrahedra, and the
    unit length brickyard reports depth errors in (the edge of a cube holding one tet's share of
    the box, storage/store.cpp)."""
    m = load_json(os.path.dirname(manifest_path) or ".", os.path.basename(manifest_path))
    if m.get("kind") not in (None, "tetrahedral") or "mesh" not in m:
        fail(f"{manifest_path}: not a tetrahedral store's manifest")
    lo, hi = [[float(v) for v in c] for c in m["mesh"]["bounds"]]
    tets = int(m["mesh"]["tets"])
    volume = 1.0
    for a in range(3):
        volume *= max(hi[a] - lo[a], 1e-300)
    unit = (volume / tets) ** (1.0 / 3.0) if tets else 1.0
    return {"box": [lo, hi], "tets": tets, "clusters": int(m["mesh"]["clusters"]), "unit_length": unit}


def cmd_tets_report(a):
    d = a.dir
    vtk = load_json(d, "vtk.json")
    emb = load_json(d, "embree.json")
    mesh = mesh_of(a.manifest)
    if vtk["cells"] != mesh["tets"]:
        fail(f"the .vtu holds {vtk['cells']} cells, the store {mesh['tets']} tets: the two sides do not see the same mesh")
    b = brickyard_side(d)
    by = b["stats"]
    k, ids = b["k"], b["ids"]
    by_first_ms, by_complete_ms, by_steady_ms = b["first_ms"], b["complete_ms"], b["steady_ms"]

    check = camera_check(mesh["unit_length"], os.path.join(d, "embree-depth.f32"), b["last_depth_png"],
                         a.width, a.height, unit_name="units")

    peer_first_ms = vtk["contour_ms"] + emb["build_ms"] + emb["first_frame_ms"]
    ratio_extract = ratio(vtk["contour_ms"], by_complete_ms)
    ratio_first = ratio(peer_first_ms, by_complete_ms)
    ratio_steady = ratio(by_steady_ms, emb["steady_frame_ms"])
    f0 = by["frames"][0].get("backend", {})

    results = {
        "setup": {
            "source": a.source, "tets": mesh["tets"], "clusters": mesh["clusters"], "isovalue": a.iso,
            "width": a.width, "height": a.height, "threads": a.threads, "backend": by["backend"],
            "backend_params": by.get("params", {}),
            "camera": {"eye": a.eye, "target": a.target, "up": a.up, "fov_degrees": a.fov},
            "world_box": mesh["box"], "unit_length": mesh["unit_length"], "store": os.path.abspath(a.store),
        },
        "vtk": vtk,
        "embree": emb,
        "brickyard": dict(brickyard_results(b, a.by_wall_ms), first_frame_backend=f0),
        "camera_check": check,
        "ratios": {
            "vtk_extraction_over_brickyard_first": ratio_extract,
            "peer_first_over_brickyard_first": ratio_first,
            "brickyard_steady_over_embree_steady": ratio_steady,
        },
    }
    ok = check["coverage_mismatch"] < a.max_mismatch
    results["camera_check"]["max_mismatch"] = a.max_mismatch
    results["camera_check"]["agree"] = ok

    params = by.get("params", {})
    exact = f"exact={params['exact']:g}" if "exact" in params else "exact default"
    builds = ""  # tet_bvh's counters of frame 0: its passes, and the cluster BVHs it built
    if "passes" in f0:
        builds += f", {f0['passes']:g} passes"
    if "bvh_builds" in f0:
        builds += f", {f0['bvh_builds']:g} cluster BVHs built"
        if "bvh_build_ms" in f0:
            builds += f" in {f0['bvh_build_ms']:.1f} ms"
    rows = [
        ("vtk_read", vtk["read_ms"], f"vtkXMLUnstructuredGridReader, {vtk['cells']} tets (not in the ratios)"),
        ("vtk_contour", vtk["contour_ms"],
         f"vtkContour3DLinearGrid, {vtk['triangles']} triangles, {vtk['estimated_threads']} threads, SMP {vtk['smp_backend']}, "
         f"merge points {'on' if vtk['merge_points'] else 'off'}, median of {len(vtk['contour_runs_ms'])}"),
        ("embree_build", emb["build_ms"], f"rtcCommitScene, build quality {emb['build_quality']}, median of {emb['builds']}"),
        ("embree_first_frame", emb["first_frame_ms"], f"{a.width}x{a.height} primary rays"),
        ("embree_steady_frame", emb["steady_frame_ms"], f"median of {emb['steady_frames']}"),
        ("peer_first_total", peer_first_ms, "contour + build + first frame"),
        ("brickyard_first_frame", by_first_ms, f"{by['backend']} frame 0, cold process, {exact}{builds}"),
        ("brickyard_first_complete", by_complete_ms, f"frames 0-{ids[k]} summed"),
        ("brickyard_steady_frame", by_steady_ms, f"median of {len(b['steady_s'])}"),
        ("brickyard_render_command", a.by_wall_ms, f"wall clock: store opened, {len(ids)} frames, PNGs written"),
    ]
    write_tables(d, results, rows, [
        ("ratio_vtk_extraction_over_brickyard_first", ratio_extract, ".4f", "vtk contour / brickyard first complete"),
        ("ratio_peer_first_over_brickyard_first", ratio_first, ".4f", "(vtk contour + embree build + embree first) / brickyard first complete"),
        ("ratio_brickyard_steady_over_embree_steady", ratio_steady, ".4f", "brickyard steady / embree steady"),
        ("coverage_mismatch", check["coverage_mismatch"], ".6f", "pixels hit by one side only"),
    ])

    print()
    print(f"peers-tets: {a.source}, {mesh['tets']} tets in {mesh['clusters']} clusters, isovalue {a.iso:g}, "
          f"{a.width}x{a.height}, {a.threads} threads, brickyard back end {by['backend']}")
    print_rows(rows)
    print(f"  {'vtk contour / brickyard first':<40} {ratio_extract:>7.3f}   >1: brickyard's first image comes before VTK's triangles")
    print(f"  {'(contour+build+first)/brickyard first':<40} {ratio_first:>7.3f}   >1: brickyard shows a new isovalue sooner")
    print(f"  {'brickyard steady / embree steady':<40} {ratio_steady:>7.3f}   <1: brickyard's steady frame is faster")
    print_brickyard_warnings(b)
    print_camera_check(check, "units", f"units ({mesh['unit_length']:.4g})")
    print(f"  figures: {os.path.join(d, 'results.json')}, {os.path.join(d, 'results.csv')}")
    camera_verdict(check, a.max_mismatch)


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

    def report_args(s):  # what both reports take beside their inputs
        s.add_argument("--iso", type=float, required=True)
        s.add_argument("--width", type=int, required=True)
        s.add_argument("--height", type=int, required=True)
        s.add_argument("--threads", type=int, required=True)
        s.add_argument("--by-wall-ms", type=float, required=True)
        s.add_argument("--max-mismatch", type=float, default=0.01)
        camera_args(s)

    s = sub.add_parser("report")
    s.add_argument("--dir", required=True)
    s.add_argument("--raw", required=True)
    s.add_argument("--store", required=True)
    s.add_argument("--field", required=True)
    report_args(s)

    s = sub.add_parser("tets-vtk")
    s.add_argument("--vtu", required=True)
    s.add_argument("--array", default="")
    s.add_argument("--iso", type=float, required=True)
    s.add_argument("--threads", type=int, required=True)
    s.add_argument("--repeats", type=int, default=3)
    s.add_argument("--smp-backend", default="")
    s.add_argument("--merge-points", type=int, choices=(0, 1), default=0)
    s.add_argument("--mesh", required=True)
    s.add_argument("--json", required=True)

    s = sub.add_parser("tets-report")
    s.add_argument("--dir", required=True)
    s.add_argument("--manifest", required=True)
    s.add_argument("--store", required=True)
    s.add_argument("--source", required=True)
    report_args(s)

    a = p.parse_args()
    {"scene": cmd_scene, "vtk": cmd_vtk, "report": cmd_report, "tets-vtk": cmd_tets_vtk,
     "tets-report": cmd_tets_report}[a.cmd](a)


if __name__ == "__main__":
    main()
