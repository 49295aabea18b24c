#!/usr/bin/env bash
# The project's Table II (Knoll et al. 2006): octree_cgt on one scene, single rays against
# packets of every size, then 8x8 packets with each optimisation added in turn, the levels of
# detail (multires at dP/dV 1 and 2) last. For each row:
# frame time (median of the frames after the first) and fps, octree lookups, cells intersected
# and nodes visited per ray, and octree page visits per frame (each tile counts the pages it pins).
#
#   bench/octree_cgt/table2.sh [SCENE [STORE]] [--frames N] [--size WxH]
#
# SCENE defaults to scenes/default-iso.json; STORE to the scene's dataset. The store needs its
# octree volume (brickyard build-octree STORE). Rows render in one process each, frames
# repeated on one camera; the first frame is cold and not counted. Machine-readable figures
# go to table2.csv in the current directory (or $TABLE2_CSV).
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
by="${BRICKYARD:-$root/build/bin/brickyard}"
scene="" store="" frames=4 size=""
while [ $# -gt 0 ]; do
  case "$1" in
    --frames) frames="${2:?--frames needs a count}"; shift 2 ;;
    --size) size="${2:?--size needs WxH}"; shift 2 ;;
    -h|--help) sed -n '2,13p' "$0"; exit 0 ;;
    -*) echo "table2: unknown option $1" >&2; exit 2 ;;
    *) if [ -z "$scene" ]; then scene="$1"; elif [ -z "$store" ]; then store="$1"; else echo "table2: too many arguments" >&2; exit 2; fi; shift ;;
  esac
done
scene="${scene:-$root/scenes/default-iso.json}"
[ -f "$scene" ] || { echo "table2: $scene: no such scene" >&2; exit 2; }
[ -x "$by" ] || { echo "table2: $by: no brickyard executable (./scripts/build.sh)" >&2; exit 2; }
case "$frames" in ''|*[!0-9]*) echo "table2: --frames: '$frames' is not a count" >&2; exit 2 ;; esac
[ "$frames" -ge 2 ] || { echo "table2: --frames: at least 2 (the first is cold)" >&2; exit 2; }
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
args=()
[ -n "$store" ] && args+=(--dataset "$store")
if [ -n "$size" ]; then
  w="${size%x*}" h="${size#*x}"
  python3 - "$scene" "$work/scene.json" "$w" "$h" <<'PY'
import json, os, re, sys
src, dst, w, h = sys.argv[1:]
text = re.sub(r"^\s*//.*$", "", open(src).read(), flags=re.M)
s = json.loads(text)
s["image"] = {"width": int(w), "height": int(h)}
if not os.path.isabs(s["dataset"]):
    s["dataset"] = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(src)), s["dataset"]))
json.dump(s, open(dst, "w"))
PY
  scene="$work/scene.json"
fi
list="0$(for ((i = 1; i < frames; ++i)); do printf ',0'; done)"
csv="${TABLE2_CSV:-table2.csv}"
echo "row,packet,mcell,cell,slice,dpdv,ms,fps,lookups_per_ray,cells_per_ray,nodes_per_ray,page_visits_per_frame" > "$csv"
printf '%-34s %9s %7s %11s %11s %11s %11s\n' "octree_cgt" "ms" "fps" "lookups/ray" "cells/ray" "nodes/ray" "page visits"
row() {
  local name="$1" packet="$2" mcell="$3" cell="$4" slice="$5" dpdv="${6:-0}"
  "$by" -q render "$scene" "${args[@]}" --backend octree_cgt --frames "$list" --set packet="$packet" --set mcell="$mcell" \
    --set cell="$cell" --set slice="$slice" --set dpdv="$dpdv" -o "$work/f.png" --stats "$work/s.json" > /dev/null
  python3 - "$work/s.json" "$name" "$packet" "$mcell" "$cell" "$slice" "$dpdv" "$csv" <<'PY'
import json, statistics, sys
path, name, packet, mcell, cell, slice_, dpdv, csv = sys.argv[1:]
frames = json.load(open(path))["frames"][1:]  # the first is cold
ms = statistics.median(f["seconds"] for f in frames) * 1e3
f = frames[-1]
rays = max(f["rays"], 1)
vals = [ms, 1e3 / ms, f["samples"] / rays, f["cells"] / rays, f["nodes"] / rays, f["bricks"]]
print(f"{name:34s} {vals[0]:9.1f} {vals[1]:7.2f} {vals[2]:11.2f} {vals[3]:11.2f} {vals[4]:11.2f} {vals[5]:11.0f}")
with open(csv, "a") as out:
    out.write(",".join([name, packet, mcell, cell, slice_, dpdv] + [f"{v:.4g}" for v in vals]) + "\n")
PY
}
row "single ray" 1 1 1 1
for p in 2 4 8 16; do row "packets ${p}x${p}" "$p" 1 1 1; done
row "8x8, no culling, no slice reuse" 8 0 0 0
row "8x8 + macrocell culling" 8 1 0 0
row "8x8 + cell culling" 8 1 1 0
row "8x8 + slice reuse" 8 1 1 1
row "8x8 + multires (dP/dV 1)" 8 1 1 1 1
row "8x8 + multires (dP/dV 2)" 8 1 1 1 2
echo "figures: $csv"
