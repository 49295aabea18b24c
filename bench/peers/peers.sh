#!/usr/bin/env bash
# bench/peers: brickyard's isosurface next to the classic pipeline, on the same voxels, isovalue,
# camera and resolution, in one run: VTK's vtkFlyingEdges3D extracts the surface, Embree 3
# builds its BVH over the triangles and renders primary-ray frames, and a brickyard back end
# renders a store of the same volume. Prints each step's time and the two ratios the project's
# targets are about; writes the figures to --out. docs/peers.md says what is measured and how.
#
# Installs what it needs from Debian (python3-vtk9, python3-numpy, libembree-dev, g++) and
# compiles embree_frame.cpp into build-peers/; nothing in the library links VTK or Embree.
set -euo pipefail

here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"

usage() {
  cat <<EOF
usage: bench/peers/peers.sh [options]

  --backend NAME     brickyard back end (default octree_cgt; raymarch, gobbetti, ...)
  --field NAME       procedural field for 'brickyard generate' (default wavelet)
  --size N           N^3 voxels (default 256)
  --iso VALUE        isovalue, in the field's units (default 160)
  --width W          image width (default 512)
  --height H         image height (default 512)
  --frames N         frames per side: the first, then N-1 steady ones (default 8, at least 2)
  --threads N        threads for VTK, Embree and brickyard alike (default 2)
  --eye X,Y,Z        camera, in coordinates normalised to the volume's box
  --target X,Y,Z       (defaults: scenes/default-iso.json's camera:
  --up X,Y,Z            eye 1.6,-1.1,1.4, target 0.5,0.5,0.45, up 0,0,1, fov 35)
  --fov DEG          vertical field of view
  --set NAME=VALUE   a parameter of the brickyard back end (repeatable)
  --vtk-smp NAME     VTK SMP back end (Sequential, STDThread, TBB; default: VTK's own)
  --embree-quality Q Embree BVH build quality: low, medium (Embree's default) or high
  --max-mismatch F   the camera check fails above this fraction of pixels (default 0.01)
  --brickyard PATH   the brickyard executable (default build/bin/brickyard)
  --out DIR          output folder (default out/peers)
  -h, --help         this text

Exit status: 0 on success, 2 for a bad argument, 3 when the camera check fails, 1 otherwise.
EOF
}

me=peers
. "$here/lib.sh"

backend=octree_cgt field=wavelet size=256 iso=160 width=512 height=512 frames=8 threads=2
eye=1.6,-1.1,1.4 target=0.5,0.5,0.45 up=0,0,1 fov=35
sets=() vtk_smp="" embree_quality=medium max_mismatch=0.01 brickyard="$root/build/bin/brickyard" out="out/peers"

while [ $# -gt 0 ]; do
  opt="$1"
  case "$opt" in
    -h | --help) usage; exit 0 ;;
    --backend | --field | --size | --iso | --width | --height | --frames | --threads | --eye | --target | --up | \
      --fov | --set | --vtk-smp | --embree-quality | --max-mismatch | --brickyard | --out)
      [ $# -ge 2 ] || die "$opt needs a value"
      val="$2"
      shift 2
      ;;
    --*=*) die "write '${opt%%=*} ${opt#*=}', not '$opt'" ;;
    *) die "unknown argument '$opt'" ;;
  esac
  case "$opt" in
    --field) [[ "$val" =~ ^[A-Za-z0-9_.-]+$ ]] || die "--field: '$val' is not a field name"; field="$val" ;;
    --size) { is_int "$val" && [ "$val" -ge 2 ] && [ "$val" -le 2048 ]; } || die "--size: '$val' is not an integer in [2, 2048]"; size="$val" ;;
    *) shared_option "$opt" "$val" ;;
  esac
done

# --- brickyard: built, and it knows the back end and the field ----------------------------

need_brickyard "$brickyard"
by=("$brickyard" -q -j "$threads")
need_backend "$brickyard" "$backend"
known_fields="$("$brickyard" generate --list | awk '/^[^ ]/ {print $1}')"
if ! grep -qx -- "$field" <<<"$known_fields"; then
  die "--field: this brickyard has no field '$field' (it has: $(echo $known_fields | tr ' ' ','))"
fi

# --- Debian packages ------------------------------------------------------------------------

install_peers

# --- embree_frame, in a build folder of its own ----------------------------------------------

build_embree_frame

# --- data: one raw file, one store of it ------------------------------------------------------

mkdir -p "$out"
out="$(cd "$out" && pwd)"
data="$out/data"
raw="$data/$field-$size.raw"
store="$data/$field-$size.store"
mkdir -p "$data"
rm -rf "$out/frames" "$out/results.json" "$out/results.csv"
echo "peers: generating $field ${size}^3 f32 and its store in $data" >&2
"${by[@]}" generate "$field" --size "$size" --type f32 --out "$raw" >/dev/null
# octree_cgt reads the grid's octree volume: built once, like the bricks, whatever the isovalue.
import_args=()
[ "$backend" = octree_cgt ] && import_args=(--octree)
"${by[@]}" import "$raw" --out "$store" "${import_args[@]}" >/dev/null

cam=(--eye "$eye" --target "$target" --up "$up" --fov "$fov")
"$py" "$here/peers.py" scene --store "$store" --backend "$backend" --iso "$iso" --width "$width" --height "$height" \
  --frames "$frames" --out "$out/scene.json" "${cam[@]}"

# --- 1. VTK flying edges ------------------------------------------------------------------------

vtk_args=()
[ -n "$vtk_smp" ] && vtk_args=(--smp-backend "$vtk_smp")
"$py" "$here/peers.py" vtk --raw "$raw" --iso "$iso" --threads "$threads" "${vtk_args[@]}" \
  --mesh "$out/surface.bymesh" --json "$out/vtk.json"

# --- 2. Embree: BVH build and frames over those triangles ---------------------------------------

box="$("$py" -c 'import json,sys; s=json.load(open(sys.argv[1])); o=s["origin"]; h=[o[a]+s["spacing"][a]*(s["dims"][a]-1) for a in range(3)]; print(",".join(repr(float(v)) for v in o+h))' "$raw.json")"
run_embree "$box"

# --- 3. brickyard ---------------------------------------------------------------------------------

run_brickyard

# --- the table -------------------------------------------------------------------------------------

"$py" "$here/peers.py" report --dir "$out" --raw "$raw" --store "$store" --field "$field" --iso "$iso" \
  --width "$width" --height "$height" --threads "$threads" --by-wall-ms "$(( (t1 - t0) / 1000 ))e-3" \
  --max-mismatch "$max_mismatch" "${cam[@]}"
