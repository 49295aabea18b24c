#!/usr/bin/env bash
# bench/peers/vdb.sh: OpenVDB's own renderer, vdb_render, next to brickyard's back ends on a level
# set (issue 43), on the same VDB file, camera, image and lighting: the level set is imported into
# a store (with its octree volume), both sides draw its zero isosurface as a white diffuse surface
# under a headlight on black, and `brickyard bench --peers` puts vdb_render's first and steady
# frames, its memory and its error against brickyard's reference into the back ends' report.
# docs/peers.md ("Level sets: vdb.sh") says what is translated and measured.
#
# Installs what it needs from Debian (libopenvdb-tools: vdb_render and vdb_tool); nothing in the
# library links it.
set -euo pipefail

here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
me=peers-vdb
. "$here/lib.sh"

usage() {
  cat <<EOF
usage: bench/peers/vdb.sh [options]

  --vdb FILE              a level set (a VDB of class level set; default: vdb_tool's
                          dodecahedron, --size voxels across)
  --size N                the default shape's voxels across (default 256)
  --width W, --height H   the image (default 512x512)
  --eye X,Y,Z --target X,Y,Z --up X,Y,Z --fov DEG
                          the camera in the box's normalised coordinates, vertical field of view
                          (default 1.6,-1.1,1.4  0.5,0.5,0.5  0,0,1  35)
  --threads N             vdb_render's threads (-cpus) and brickyard's -j (default 2)
  --frames N              vdb_render runs: the first is its first frame, the rest steady (default 5)
  --backends LIST         the back ends 'brickyard bench' runs beside it (default: its own)
  --brickyard PATH        the brickyard executable (default build/bin/brickyard)
  --out DIR               output folder (default out/peers-vdb)
  -h, --help              this text

Exit status: 0 on success, 2 for a bad argument, 1 otherwise.
EOF
}

vdb="" size=256 width=512 height=512 eye=1.6,-1.1,1.4 target=0.5,0.5,0.5 up=0,0,1 fov=35 threads=2 frames=5
backends="" brickyard="$root/build/bin/brickyard" out="out/peers-vdb"

while [ $# -gt 0 ]; do
  opt="$1"
  case "$opt" in
    -h | --help) usage; exit 0 ;;
    --vdb | --size | --width | --height | --eye | --target | --up | --fov | --threads | --frames | --backends | --brickyard | --out)
      [ $# -ge 2 ] || die "$opt needs a value"
      val="$2"
      shift 2
      ;;
    --*=*) die "write '${opt%%=*} ${opt#*=}', not '$opt'" ;;
    *) die "unknown argument '$opt'" ;;
  esac
  case "$opt" in
    --vdb) [ -f "$val" ] || die "--vdb: $val: no such file"; vdb="$val" ;;
    --size) { is_int "$val" && [ "$val" -ge 8 ] && [ "$val" -le 4096 ]; } || die "--size: '$val' is not an integer in [8, 4096]"; size="$val" ;;
    --fov) { is_number "$val" && awk -v f="$val" 'BEGIN { exit !(f > 0 && f < 179) }'; } || die "--fov: '$val' is not an angle in (0, 179)"; fov="$val" ;;
    --frames) { is_int "$val" && [ "$val" -ge 2 ]; } || die "--frames: '$val' is not an integer of at least 2"; frames="$val" ;;
    --backends) [[ "$val" =~ ^[A-Za-z0-9_.,-]+$ ]] || die "--backends: '$val' is not a list of back ends"; backends="$val" ;;
    *) shared_option "$opt" "$val" ;;  # --width --height --eye --target --up --threads --brickyard --out
  esac
done

need_brickyard "$brickyard"
install_debian python3 libopenvdb-tools

mkdir -p "$out/data"
out="$(cd "$out" && pwd)"
rm -f "$out/peers.json" "$out/vdb_render.png"
if [ -z "$vdb" ]; then
  vdb="$out/data/dodecahedron-$size.vdb"
  echo "$me: making a dodecahedron level set, $size voxels across (vdb_tool)" >&2
  vdb_tool -platonic f=12 d="$size" s=1 -write "$vdb" >/dev/null
fi
vdb="$(cd "$(dirname "$vdb")" && pwd)/$(basename "$vdb")"
store="$out/data/$(basename "${vdb%.vdb}").store"
by=("$brickyard" -q -j "$threads")
echo "$me: importing $vdb with its octree volume" >&2
"${by[@]}" import "$vdb" --out "$store" --octree --force >/dev/null
"${by[@]}" info "$store" --json >"$out/data/manifest.json"
"$py" -c 'import json,sys; b=json.load(open(sys.argv[1]))["build"]; sys.exit(not b.get("level_set"))' "$out/data/manifest.json" ||
  fail "$vdb is not a level set (its grid class is not LEVEL_SET): vdb_render draws a level set's zero crossing"

"$py" "$here/vdb.py" scene --store "$store" --width "$width" --height "$height" --eye "$eye" --target "$target" --up "$up" \
  --fov "$fov" --out "$out/scene.json"
"$py" "$here/vdb.py" render --scene "$out/scene.json" --manifest "$out/data/manifest.json" --vdb "$vdb" \
  --threads "$threads" --frames "$frames" --out "$out"

bench_args=()
[ -n "$backends" ] && bench_args+=(--backends "$backends")
echo "$me: brickyard bench with vdb_render (into $out/bench)" >&2
"${by[@]}" bench "$out/scene.json" --dataset "$store" --peers "$out/peers.json" --out "$out/bench" "${bench_args[@]}"
echo "$me: the report, with vdb_render's error against the reference: $out/bench/bench.md" >&2
