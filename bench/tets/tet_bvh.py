#!/usr/bin/env python3
"""tet_bvh's figures (issue 39), each from `brickyard render --stats` in one run:

  builds   BVH build time (BIH and SAH) and frame rates at 1024^2 for meshes of 0.2, 1 and 10
           million tets (mesh:sphere, jittered), cold first frame and steady frames
  table4   the paper's Table 4 on its own terms: per-frame packet-box, ray-box, isorange,
           extraction and ray-isopolygon tests, single rays and packets of 2x2 .. 16x16
  shells   the replicated shell (1, 2^3, 4^3, 8^3 copies side by side): frame time, peak
           memory, bytes read by the first frame, BVH memory
  table5   a moving mesh's time series: one BVH refitted per step against a BVH per step,
           frame times over two cycles, refit and build time, BVH memory (the paper's Table 5)
  flight   a mesh larger than the L2 budget flown along an orbit, then a jump: median and p95
           frame time, frames to converge after the jump, bytes read
  stored   BVHs stored by the importer (import --bvh) against built when a cluster arrives: cold
           first frame, BVH time, bytes read, page and store size, and a flight under a small L1
  big      a 100M-tet mesh at 1024^2 with L1 + L2 under 4 GB: settled frame rate (--big only)
  error    `brickyard bench`: error against the tet reference next to the run time

usage: bench/tets/tet_bvh.py [--out DIR] [--sizes 0.2,1,10] [--only builds,table4,...] [--big]

Stores are made in DIR (default /tmp/brickyard-tets, shared with mesh_import.sh) when missing;
figures go to DIR/tet_bvh.json and are printed as tables. Threads: all cores (2 here).
"""

import argparse
import json
import math
import os
import statistics
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
BRICKYARD = os.environ.get("BRICKYARD", os.path.join(ROOT, "build", "bin", "brickyard"))
CAMERA = {"eye": [1.9, -1.1, 1.3], "target": [0.5, 0.5, 0.45], "up": [0, 0, 1], "fov_degrees": 38}
CLUSTER_TETS = 8192


def run(args, time_file=None):
    cmd = [BRICKYARD, "-q"] + args
    if time_file:
        cmd = ["/usr/bin/time", "-f", "%e %M", "-o", time_file] + cmd
    done = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    if done.returncode != 0:
        sys.exit(f"tet_bvh: {' '.join(cmd)} failed ({done.returncode}):\n{done.stderr}")
    return done.stdout


def peak_mib(time_file):
    with open(time_file) as f:
        return int(f.read().split()[1]) / 1024


def cells_for(million):
    return round((million * 1e6 / 6) ** (1 / 3))


def manifest(store):
    if not os.path.exists(os.path.join(store, "data.mdb")):
        return None
    try:
        return json.loads(run(["info", store, "--json"]))
    except SystemExit:
        return None


def ensure_store(store, import_args):
    m = manifest(store)
    if not (m and m.get("complete")):
        run(["import"] + import_args + ["-o", store, "--force"])
    return store


def sphere_store(out, million):
    store = os.path.join(out, f"sphere-{million:g}M.store")
    return ensure_store(store, ["mesh:sphere", "--cells", str(cells_for(million)), "--jitter", "0.1"])


def store_tets(store):
    return manifest(store)["mesh"]["tets"]


def store_mib(store):
    return sum(os.path.getsize(os.path.join(store, f)) for f in os.listdir(store)) / 2**20


def scene(out, name, store, frames=8, size=1024, iso=(0.3,), light="headlight", cache=None, keyframes=None, extra=None):
    """A still camera repeated over `frames` keyframes (frame 0 cold, the rest warm), or the
    given keyframes, one a frame."""
    keys = keyframes or [CAMERA] * frames
    s = {
        "dataset": store,
        "backend": "tet_bvh",
        "image": {"width": size, "height": size},
        "camera_path": {"frames": len(keys), "keyframes": keys},
        "mode": "iso",
        "isosurfaces": [{"value": v} for v in iso],
        "shading": {"light": light},
    }
    if cache:
        s["cache"] = cache
    if extra:
        s.update(extra)
    path = os.path.join(out, name + ".json")
    with open(path, "w") as f:
        json.dump(s, f, indent=1)
    return path


def render(scene_path, out, params=(), time_file=None):
    stats = os.path.join(out, "stats.json")
    image = os.path.splitext(scene_path)[0] + ".png"
    args = ["render", scene_path, "--frames", "all", "--stats", stats, "-o", image]
    for p in params:
        args += ["--set", p]
    run(args, time_file)
    with open(stats) as f:
        return json.load(f)


def ms(frame):
    return frame["seconds"] * 1e3


def steady(frames):
    return statistics.median(ms(f) for f in frames[2:])


def table(title, header, rows):
    print(f"\n## {title}\n")
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    for r in rows:
        print("| " + " | ".join(str(v) for v in r) + " |")


def builds(out, sizes):
    rows, figures = [], []
    for m in sizes:
        store = sphere_store(out, m)
        tets = store_tets(store)
        for method, sah in (("BIH", 0), ("SAH", 1)):
            st = render(scene(out, "builds", store), out, ["exact=1", f"sah={sah}"])
            first = st["frames"][0]
            b = first["backend"]
            built_tets = b["bvh_builds"] * min(CLUSTER_TETS, tets)
            f = {
                "million_tets": tets / 1e6, "method": method, "clusters_built": b["bvh_builds"],
                "build_ms": b["bvh_build_ms"], "build_ms_per_mtet": b["bvh_build_ms"] / (built_tets / 1e6),
                "bvh_mib": b["bvh_bytes"] / 2**20, "cold_ms": ms(first), "steady_ms": steady(st["frames"]),
            }
            f["fps"] = 1e3 / f["steady_ms"]
            figures.append(f)
            rows.append([f"{f['million_tets']:.2f}", method, int(f["clusters_built"]), f"{f['build_ms']:.0f}",
                         f"{f['build_ms_per_mtet']:.0f}", f"{f['bvh_mib']:.1f}", f"{f['cold_ms']:.0f}",
                         f"{f['steady_ms']:.1f}", f"{f['fps']:.1f}"])
    table("BVH builds and frame rates, 1024^2, one isosurface, headlight",
          ["M tets", "build", "clusters built", "build ms (CPU, all threads)", "ms per M tets", "BVH MiB",
           "cold frame ms", "steady ms", "fps"], rows)
    return figures


def table4(out, million):
    store = sphere_store(out, million)
    rows, figures = [], []
    keys = ["packet_box_tests", "ray_box_tests", "isorange_tests", "isopolygon_extractions", "ray_isopolygon_tests",
            "full_miss_rays_culled", "footprint_culled_rays", "footprint_culled_box_rays"]
    for packet in (1, 2, 4, 8, 16):
        st = render(scene(out, "table4", store, frames=5), out, ["exact=1", f"packet={packet}"])
        b = st["frames"][-1]["backend"]
        f = {"packet": packet, "steady_ms": steady(st["frames"]), **{k: b[k] for k in keys}}
        figures.append(f)
        rows.append([f"{packet}x{packet}" if packet > 1 else "single", f"{f['steady_ms']:.1f}",
                     f"{1e3 / f['steady_ms']:.1f}"] + [f"{b[k] / 1e6:.3f}" for k in keys])
    table(f"Table 4: tests per frame (millions), {store_tets(store) / 1e6:.1f}M tets, 1024^2",
          ["packet", "ms", "fps", "packet-box", "ray-box", "isorange", "extractions", "ray-isopolygon",
           "corner-culled rays", "footprint-culled (polygons)", "footprint-culled (boxes)"], rows)
    return figures


def shells(out):
    rows, figures = [], []
    time_file = os.path.join(out, "time.txt")
    for r in (1, 2, 4, 8):
        store = ensure_store(os.path.join(out, f"shell-x{r}.store"),
                             ["mesh:sphere", "--cells", "24", "--jitter", "0.1", "--replicate", str(r)])
        st = render(scene(out, "shells", store, frames=5, cache={"l1": "1GiB", "l2": "1GiB"}), out, ["exact=1"],
                    time_file)
        page_bytes = manifest(store)["mesh"]["page_bytes"]
        first = st["frames"][0]
        f = {"copies": r**3, "million_tets": store_tets(store) / 1e6, "cold_ms": ms(first),
             "steady_ms": steady(st["frames"]), "peak_rss_mib": peak_mib(time_file),
             "first_frame_read_mib": first["cache"]["bytes_read"] / 2**20,
             "l1_used_mib": st["cache"]["l1"]["resident"] * page_bytes / 2**20,
             "l2_peak_mib": st["cache"]["l2_peak_bytes"] / 2**20, "bvh_mib": first["backend"]["bvh_bytes"] / 2**20,
             "steady_read_mib": sum(fr["cache"]["bytes_read"] for fr in st["frames"][1:]) / 2**20}
        figures.append(f)
        rows.append([f["copies"], f"{f['million_tets']:.1f}", f"{f['cold_ms']:.0f}", f"{f['steady_ms']:.1f}",
                     f"{f['peak_rss_mib']:.0f}", f"{f['first_frame_read_mib']:.1f}", f"{f['steady_read_mib']:.1f}",
                     f"{f['l1_used_mib']:.1f}", f"{f['l2_peak_mib']:.1f}", f"{f['bvh_mib']:.1f}"])
    table("Replicated shell (24^3 cubes a copy), 1024^2, exact frames, L1 and L2 budgets 1 GiB each",
          ["copies", "M tets", "cold ms", "steady ms", "peak RSS MiB (L1 pool included)", "read by frame 0 MiB",
           "read after MiB", "L1 used MiB", "L2 peak MiB", "BVH MiB"], rows)
    return figures


def table5(out, steps=8):
    store = ensure_store(os.path.join(out, f"moving-1M-{steps}.store"),
                         ["mesh:sphere", "--cells", "55", "--jitter", "0.1", "--steps", str(steps), "--move", "0.01"])
    path = scene(out, "table5", store, frames=2 * steps, extra={"time_series": {"first": 0, "count": steps}})
    rows, figures = [], []
    for mode, per_step in (("refit", 0), ("BVH per step", 1)):
        st = render(path, out, ["exact=1", f"bvh_per_step={per_step}", "bvh_cache=4096"])
        frames = st["frames"]
        first, second = frames[1:steps], frames[steps:]
        f = {"mode": mode, "steps": steps,
             "first_cycle_ms": statistics.median(ms(x) for x in first),
             "second_cycle_ms": statistics.median(ms(x) for x in second),
             "refit_ms_per_frame": statistics.median(x["backend"]["bvh_refit_ms"] for x in second),
             "build_ms_per_frame": statistics.median(x["backend"]["bvh_build_ms"] for x in first),
             "bvh_mib": frames[-1]["backend"]["bvh_bytes"] / 2**20}
        figures.append(f)
        rows.append([mode, f"{f['first_cycle_ms']:.1f}", f"{f['second_cycle_ms']:.1f}", f"{f['build_ms_per_frame']:.1f}",
                     f"{f['refit_ms_per_frame']:.1f}", f"{f['bvh_mib']:.1f}"])
    table(f"Table 5: a moving mesh of {store_tets(store) / 1e6:.1f}M tets, {steps} steps, two cycles, 1024^2",
          ["time steps by", "ms a frame, 1st cycle", "2nd cycle", "build ms/frame (1st)", "refit ms/frame (2nd)",
           "BVH MiB at the end"], rows)
    return figures


def orbit_with_jump(orbit_frames=48, hold_frames=24):
    keys = []
    for i in range(orbit_frames):
        a = -0.5 + 2 * math.pi * i / orbit_frames * 0.5
        keys.append({"eye": [0.5 + 1.9 * math.cos(a), 0.5 + 1.9 * math.sin(a), 1.2], "target": [0.5, 0.5, 0.45],
                     "up": [0, 0, 1], "fov_degrees": 38})
    # The jump: close to the side of the sphere the orbit never faced.
    b = 4.2
    close = {"eye": [0.5 + 0.75 * math.cos(b), 0.5 + 0.75 * math.sin(b), 0.55], "target": [0.5, 0.5, 0.45],
             "up": [0, 0, 1], "fov_degrees": 40}
    return keys + [close] * hold_frames, orbit_frames


def flight(out, million, l1, l2):
    store = sphere_store(out, million)
    size_mib = store_mib(store)
    keys, jump = orbit_with_jump()
    path = scene(out, "flight", store, keyframes=keys, cache={"l1": l1, "l2": l2})
    st = render(path, out, ["exact=0"])
    frames = st["frames"]
    times = sorted(ms(f) for f in frames)
    after = frames[jump:]
    converge = next((i + 1 for i, f in enumerate(after) if f["backend"]["unfinished_rays"] == 0), None)
    f = {"million_tets": store_tets(store) / 1e6, "store_mib": size_mib, "l1": l1, "l2": l2, "frames": len(frames),
         "median_ms": statistics.median(times), "p95_ms": times[int(0.95 * (len(times) - 1))],
         "frames_to_converge_after_jump": converge,
         "read_mib": sum(fr["cache"]["bytes_read"] for fr in frames) / 2**20}
    table(f"Flight: {f['million_tets']:.1f}M tets (store {size_mib:.0f} MiB, L1 {l1}, L2 {l2}), 1024^2, {len(frames)} frames "
          f"(orbit, then a jump held {len(frames) - jump} frames), frames as shown (exact=0)",
          ["median ms", "p95 ms", "frames to converge after the jump", "MiB read"],
          [[f"{f['median_ms']:.1f}", f"{f['p95_ms']:.1f}", converge, f"{f['read_mib']:.0f}"]])
    return f


def stored(out, sizes=(1, 10), runs=3):
    rows, figures = [], []
    for m in sizes:
        plain = sphere_store(out, m)
        with_bvh = ensure_store(os.path.join(out, f"sphere-{m:g}M-bvh.store"),
                                ["mesh:sphere", "--cells", str(cells_for(m)), "--jitter", "0.1", "--bvh"])
        for label, store in (("built on load", plain), ("stored (--bvh)", with_bvh)):
            colds, bvh_ms, st = [], [], None
            for _ in range(runs):  # each a new process: the first frame loads every cluster and BVH
                st = render(scene(out, "stored", store, frames=4), out, ["exact=1"])
                b = st["frames"][0]["backend"]
                colds.append(ms(st["frames"][0]))
                bvh_ms.append(b["bvh_build_ms"] + b["bvh_load_ms"])
            page = manifest(store)["mesh"]["page_bytes"]
            fl = render(path_of_flight(out, store), out, ["exact=0"])
            f = {"million_tets": store_tets(store) / 1e6, "bvh": label, "cold_ms": statistics.median(colds),
                 "bvh_cpu_ms": statistics.median(bvh_ms), "read_mib": st["frames"][0]["cache"]["bytes_read"] / 2**20,
                 "page_kib": page / 1024, "store_mib": store_mib(store), "steady_ms": steady(st["frames"]),
                 "flight_median_ms": statistics.median(ms(x) for x in fl["frames"]),
                 "flight_read_mib": sum(x["cache"]["bytes_read"] for x in fl["frames"]) / 2**20}
            figures.append(f)
            rows.append([f"{f['million_tets']:.1f}", label, f"{f['cold_ms']:.0f}", f"{f['bvh_cpu_ms']:.1f}",
                         f"{f['read_mib']:.1f}", f"{f['page_kib']:.0f}", f"{f['store_mib']:.0f}", f"{f['steady_ms']:.1f}",
                         f"{f['flight_median_ms']:.1f}", f"{f['flight_read_mib']:.0f}"])
    table(f"BVHs built when a cluster arrives against stored by the importer, 1024^2 (cold: median of {runs} processes; "
          "flight: the orbit and jump below, L1 48 MiB, L2 64 MiB)",
          ["M tets", "BVHs", "cold frame ms", "BVH CPU ms", "read by frame 0 MiB", "page KiB", "store MiB", "steady ms",
           "flight median ms", "flight MiB read"], rows)
    return figures


def path_of_flight(out, store):
    keys, _ = orbit_with_jump()
    return scene(out, "flight", store, keyframes=keys, cache={"l1": "48MiB", "l2": "64MiB"})


def big(out):
    store = sphere_store(out, 100)
    time_file = os.path.join(out, "time.txt")
    path = scene(out, "big", store, frames=5, cache={"l1": "2GiB", "l2": "1536MiB"})
    st = render(path, out, ["exact=1"], time_file)
    f = {"million_tets": store_tets(store) / 1e6, "cold_ms": ms(st["frames"][0]), "steady_ms": steady(st["frames"]),
         "peak_rss_mib": peak_mib(time_file), "l1_plus_l2_gib": 3.5,
         "read_mib": st["frames"][0]["cache"]["bytes_read"] / 2**20}
    f["fps"] = 1e3 / f["steady_ms"]
    table(f"{f['million_tets']:.1f}M tets, 1024^2, L1 2 GiB + L2 1.5 GiB",
          ["cold frame ms", "steady ms", "fps", "peak RSS MiB", "read by frame 0 MiB"],
          [[f"{f['cold_ms']:.0f}", f"{f['steady_ms']:.1f}", f"{f['fps']:.1f}", f"{f['peak_rss_mib']:.0f}",
            f"{f['read_mib']:.0f}"]])
    return f


def error(out, million):
    store = sphere_store(out, million)
    path = scene(out, "error", store, frames=1, size=512)
    with open(path) as f:
        s = json.load(f)
    del s["camera_path"]
    s["camera"] = CAMERA
    with open(path, "w") as f:
        json.dump(s, f)
    report = os.path.join(out, "bench-tets")
    text = run(["bench", path, "--backends", "tet_bvh", "--warm", "5", "--cold", "1", "--out", report])
    print("\n## Error against the tet reference (`brickyard bench`, 512^2)\n")
    print(text.strip())
    return {"report": report, "text": text}


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="/tmp/brickyard-tets")
    p.add_argument("--sizes", default="0.2,1,10", help="million tets for the build table")
    p.add_argument("--only", default="builds,table4,shells,table5,flight,stored,error")
    p.add_argument("--big", action="store_true", help="also the 100M-tet mesh (about 1 GiB of store)")
    a = p.parse_args()
    if not os.access(BRICKYARD, os.X_OK):
        sys.exit(f"tet_bvh: {BRICKYARD}: no brickyard executable (./scripts/build.sh)")
    if not os.access("/usr/bin/time", os.X_OK):
        sys.exit("tet_bvh: needs /usr/bin/time (Debian package time) for peak memory")
    os.makedirs(a.out, exist_ok=True)
    sizes = [float(s) for s in a.sizes.split(",")]
    only = set(a.only.split(","))
    unknown = only - {"builds", "table4", "shells", "table5", "flight", "stored", "error", "big"}
    if unknown:
        sys.exit(f"tet_bvh: unknown --only part(s): {', '.join(sorted(unknown))}")
    figures = {}
    if "builds" in only:
        figures["builds"] = builds(a.out, sizes)
    if "table4" in only:
        figures["table4"] = table4(a.out, 1)
    if "shells" in only:
        figures["shells"] = shells(a.out)
    if "table5" in only:
        figures["table5"] = table5(a.out)
    if "flight" in only:
        figures["flight"] = flight(a.out, 10, "48MiB", "64MiB")
    if "stored" in only:
        figures["stored"] = stored(a.out)
    if "error" in only:
        figures["error"] = error(a.out, 1)
    if a.big or "big" in only:
        figures["big"] = big(a.out)
    with open(os.path.join(a.out, "tet_bvh.json"), "w") as f:
        json.dump(figures, f, indent=1)
    print(f"\nfigures: {os.path.join(a.out, 'tet_bvh.json')}")


if __name__ == "__main__":
    main()
