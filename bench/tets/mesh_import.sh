#!/usr/bin/env bash
# The tetrahedral store's figures (issue: unstructured meshes): for procedural meshes of about
# 1, 10 and 100 million tets (mesh:sphere, jittered), the import's throughput (tets per second)
# and peak memory, the store's size and cluster table; the reference's frame at 512^2 on the
# 1M and 10M meshes; the replicated shell at 1 to 8^3 copies; a mesh file read whole; and a
# close view of the largest mesh, with an L2 budget a quarter of its store, and the bytes it
# reads against the store's size.
#
#   bench/tets/mesh_import.sh [--sizes 1,10,100] [--out DIR] [--no-render]
#
# Stores go to DIR (default /tmp/brickyard-tets); figures to DIR/mesh_import.csv.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
by="${BRICKYARD:-$root/build/bin/brickyard}"
sizes="1,10,100" out="/tmp/brickyard-tets" render=1
while [ $# -gt 0 ]; do
  case "$1" in
    --sizes) sizes="${2:?--sizes needs a list of millions}"; shift 2 ;;
    --out) out="${2:?--out needs a directory}"; shift 2 ;;
    --no-render) render=0; shift ;;
    -h|--help) sed -n '2,11p' "$0"; exit 0 ;;
    *) echo "mesh_import: unknown argument $1" >&2; exit 2 ;;
  esac
done
[ -x "$by" ] || { echo "mesh_import: $by: no brickyard executable (./scripts/build.sh)" >&2; exit 2; }
[ -x /usr/bin/time ] || { echo "mesh_import: needs /usr/bin/time (Debian package time) for peak memory" >&2; exit 2; }
mkdir -p "$out"
csv="$out/mesh_import.csv"
echo "million_tets,cells,tets,seconds,tets_per_second,peak_rss_mib,store_mib,cluster_table_kib,clusters,frame_512_ms" >"$csv"
largest=""
for m in ${sizes//,/ }; do
  cells=$(/usr/bin/python3 -c "print(round(($m * 1e6 / 6) ** (1 / 3)))")
  store="$out/sphere-${m}M.store"
  rm -rf "$store"
  /usr/bin/time -f "%e %M" -o "$out/time.txt" "$by" -q import "mesh:sphere" --cells "$cells" --jitter 0.1 -o "$store" >"$out/import.txt"
  read -r seconds rss_kib <"$out/time.txt"
  info="$("$by" info "$store")"
  tets=$(echo "$info" | sed -n 's/^\([0-9]*\) tetrahedra.*/\1/p')
  clusters=$(echo "$info" | sed -n 's/.* in \([0-9]*\) clusters.*/\1/p')
  table=$(echo "$info" | sed -n 's/^cluster table \([^,]*\),.*/\1/p')
  store_mib=$(du -sm "$store" | cut -f1)
  frame_ms=""
  if [ "$render" = 1 ] && [ "$m" -le 10 ]; then
    sed "s|\"dataset\": *\"[^\"]*\"|\"dataset\": \"$store\"|" "$root/scenes/tet-iso.json" | grep -v '"time_step"' >"$out/scene.json"
    "$by" -q render "$out/scene.json" -o "$out/sphere-${m}M.png" --stats "$out/stats.json" >/dev/null
    frame_ms=$(/usr/bin/python3 -c "import json; print(round(json.load(open('$out/stats.json'))['frames'][0]['seconds'] * 1e3, 1))")
  fi
  tps=$(/usr/bin/python3 -c "print(round($tets / $seconds))")
  echo "$m M tets: $tets tets ($cells^3 cubes) in $seconds s = $tps tets/s, peak $((rss_kib / 1024)) MiB, store $store_mib MiB, $clusters clusters, table $table${frame_ms:+, reference 512^2 iso ${frame_ms} ms}"
  echo "$m,$cells,$tets,$seconds,$tps,$((rss_kib / 1024)),$store_mib,$table,$clusters,$frame_ms" >>"$csv"
  largest="$store"
done

# The replicated shell (the paper's "bucky-like" scalability scene): one sphere mesh of 24^3
# cubes, 1, 2^3, 4^3 and 8^3 times side by side.
for r in 1 2 4 8; do
  store="$out/shell-x$r.store"
  rm -rf "$store"
  /usr/bin/time -f "%e %M" -o "$out/time.txt" "$by" -q import "mesh:sphere" --cells 24 --jitter 0.1 --replicate "$r" -o "$store" >/dev/null
  read -r seconds rss_kib <"$out/time.txt"
  tets=$("$by" info "$store" | sed -n 's/^\([0-9]*\) tetrahedra.*/\1/p')
  echo "shell x$r^3: $tets tets in $seconds s, peak $((rss_kib / 1024)) MiB, store $(du -sm "$store" | cut -f1) MiB"
  rm -rf "$store"
done

# A mesh file read whole (the in-memory path: reader, validation, partition): the 10M mesh
# exported as .vtu (appended raw) and imported back.
if [ -d "$out/sphere-10M.store" ]; then
  "$by" -q export "$out/sphere-10M.store" -o "$out/sphere-10M.vtu" >/dev/null
  rm -rf "$out/vtu.store"
  /usr/bin/time -f "%e %M" -o "$out/time.txt" "$by" -q import "$out/sphere-10M.vtu" -o "$out/vtu.store" >"$out/import.txt"
  read -r seconds rss_kib <"$out/time.txt"
  mb=$(( $(stat -c %s "$out/sphere-10M.vtu") / 1000000 ))
  echo "file import of sphere-10M.vtu ($mb MB): $seconds s = $(/usr/bin/python3 -c "print(round($mb / $seconds))") MB/s, peak $((rss_kib / 1024)) MiB"
  grep -E "read and validated|wrote" "$out/import.txt" | sed 's/^ */  /'
  rm -f "$out/sphere-10M.vtu"
fi

# A close view of the largest mesh: the camera near one corner, looking along the diagonal.
cat >"$out/close.json" <<JSON
{ "dataset": "$largest", "backend": "reference", "image": { "width": 512, "height": 512 },
  "camera": { "eye": [0.16, 0.12, 0.2], "target": [0.3, 0.3, 0.3], "up": [0, 0, 1], "fov_degrees": 40 },
  "mode": "iso", "isosurfaces": [ { "value": 0.0 } ], "shading": { "light": "headlight" },
  "cache": { "l1": "64MiB", "l2": "256MiB" } }
JSON
"$by" -q render "$out/close.json" -o "$out/close.png" --stats "$out/close-stats.json" >/dev/null
/usr/bin/python3 - "$out/close-stats.json" "$largest" <<'PY'
import json, os, sys
s = json.load(open(sys.argv[1]))
l3 = s["cache"]["l3"]
size = sum(os.path.getsize(os.path.join(sys.argv[2], f)) for f in os.listdir(sys.argv[2]))
print(f"close view of {sys.argv[2]}: read {l3['reads']} of {l3['records']} clusters, "
      f"{l3['bytes_read'] / 2**20:.1f} MiB of a {size / 2**20:.0f} MiB store ({100 * l3['bytes_read'] / size:.2f}%), "
      f"frame {s['frames'][0]['seconds'] * 1e3:.0f} ms warm")
PY
