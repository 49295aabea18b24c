#!/usr/bin/env bash
# Memory soak (issue 42, item 5): imports, once, a 1024^3 u8 grid of a procedural field with its
# octree volume (octree_cgt reads it) and a procedural tetrahedral mesh (tet_bvh), then flies
# each back end over them with bench_soak: a random camera every frame, random zoom so that
# some frames need far more pages than the budgets hold (thrash), small frames, small L1 and L2
# budgets. One process per back end, so that each RSS starts fresh. Per back end it prints the
# budget, the fixed overhead and what it is, the peak resident bytes, RSS at frame 100 and at
# the end, and two PASS/FAIL lines; the table goes to OUT/soak.csv, per-frame samples to
# OUT/soak-BACKEND.csv. Figures, not assertions: the quick asserting version is ctest's Soak.*.
#
#   bench/soak.sh [--out DIR] [--size 1024] [--field gyroid] [--mesh-cells 255] [--frames 2000]
#       [--frames-for NAME=N ...] [--image 96] [--l1 16MiB] [--l2 64MiB] [--backends LIST]
#       [-- EXTRA bench_soak OPTIONS]
#
# Stores are kept in DIR (default out/soak), named after what they hold, and reused while
# complete.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/.." && pwd)"
by="${BRICKYARD:-$root/build/bin/brickyard}"
soak="${BENCH_SOAK:-$root/build/bench/bench_soak}"
out="$root/out/soak" size=1024 field=gyroid mesh_cells=255 frames=2000 image=96 l1=16MiB l2=64MiB
backends="raymarch,reference,gobbetti,gigavoxels,octree_cgt,tet_bvh"
frames_for=() extra=()
while [ $# -gt 0 ]; do
  case "$1" in
    --out) out="${2:?--out needs a directory}"; shift 2 ;;
    --size) size="${2:?}"; shift 2 ;;
    --field) field="${2:?}"; shift 2 ;;
    --mesh-cells) mesh_cells="${2:?}"; shift 2 ;;
    --frames) frames="${2:?}"; shift 2 ;;
    --frames-for) frames_for+=(--frames-for "${2:?}"); shift 2 ;;
    --image) image="${2:?}"; shift 2 ;;
    --l1) l1="${2:?}"; shift 2 ;;
    --l2) l2="${2:?}"; shift 2 ;;
    --backends) backends="${2:?}"; shift 2 ;;
    --) shift; extra=("$@"); break ;;
    -h|--help) sed -n '2,16p' "$0"; exit 0 ;;
    *) echo "soak: unknown argument $1" >&2; exit 2 ;;
  esac
done
[ -x "$by" ] || { echo "soak: $by: no brickyard executable (./scripts/build.sh)" >&2; exit 2; }
[ -x "$soak" ] || { echo "soak: $soak: no bench_soak (cmake --build build --target bench_soak)" >&2; exit 2; }
mkdir -p "$out"
grid="$out/$field-$size-u8.store" mesh="$out/mesh-$field-$mesh_cells.store"

# Step 1: the stores, once: kept while `info` says they are complete (their names say what
# they were made from), the grid with its octree volume.
t0=$(date +%s)
if ! "$by" info "$grid" 2>/dev/null | grep -q "^octree depth"; then
  "$by" -q import "field:$field" --size "$size" --type u8 --octree --no-disk-check --force --out "$grid" | tail -n 3
fi
if ! "$by" info "$mesh" 2>/dev/null | grep -q "^store .*: complete"; then
  "$by" -q import "mesh:$field" --cells "$mesh_cells" --jitter 0.1 --bvh --force --out "$mesh" | tail -n 3
fi
echo "stores ready in $(( $(date +%s) - t0 )) s: $grid ($(du -sh "$grid" | cut -f1)), $mesh ($(du -sh "$mesh" | cut -f1))"

# Step 2: one process per back end.
summary="$out/soak.csv" failed=""
rm -f "$summary"
for b in ${backends//,/ }; do
  t=$(date +%s)
  "$soak" --grid "$grid" --mesh "$mesh" --backends "$b" --frames "$frames" "${frames_for[@]}" --size "$image" --l1 "$l1" --l2 "$l2" \
    --csv "$out" --summary "$summary" "${extra[@]}" || failed="$failed $b"
  echo "($b: $(( $(date +%s) - t )) s)"
done
echo
echo "== $summary"
cat "$summary"
[ -z "$failed" ] || { echo "soak: bench_soak failed for:$failed" >&2; exit 1; }
