#!/usr/bin/env bash
# bench/peers/tets.sh: brickyard's tet_bvh next to the classic pipeline, on the same tetrahedral
# mesh, isovalue, camera and resolution, in one run: VTK's vtkContour3DLinearGrid extracts the
# isosurface from the .vtu that brickyard exports from its store, Embree 3 builds its BVH over
# those triangles and renders primary-ray frames, and brickyard's tet_bvh renders the store.
# Prints each step's time and the ratios issue 39 asks for; writes the figures to --out.
# docs/peers.md ("Tetrahedral meshes") says what is measured and how.
#
# Installs what it needs from Debian (python3-vtk9, python3-numpy, libembree-dev, g++) and
# compiles embree_frame.cpp into build-peers/, as peers.sh does (bench/peers/lib.sh).
set -euo pipefail

here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
me=peers-tets
. "$here/lib.sh"

usage() {
  cat <<EOF
usage: bench/peers/tets.sh [options]

  --mesh SOURCE      what 'brickyard import' reads: mesh:FIELD (default mesh:sphere) or a
                     mesh file (.vtu .pvd .vtk .msh .node; its first time step)
  --cells N          mesh:FIELD: N^3 cubes, 6 tets each (default 55: 1.0M tets; 32: 0.2M)
  --jitter J         mesh:FIELD: interior vertices moved by up to J cells, 0 to 0.2 (default 0.1)
  --array NAME       a mesh file's point array (default: its first)
  --iso VALUE        isovalue, in the mesh's units (default 0: mesh:sphere's sphere, radius 0.35)
  --backend NAME     brickyard back end for meshes (default tet_bvh; reference also renders them)
  --width W          image width (default 512)
  --height H         image height (default 512)
  --frames N         frames per side: the first, then N-1 steady ones (default 8, at least 2)
  --threads N        threads for VTK, Embree and brickyard alike (default 2)
  --eye X,Y,Z        camera, in coordinates normalised to the mesh's box
  --target X,Y,Z       (defaults: scenes/tet-iso.json's camera:
  --up X,Y,Z            eye 1.9,-1.1,1.3, target 0.5,0.5,0.45, up 0,0,1, fov 38)
  --fov DEG          vertical field of view
  --set NAME=VALUE   a parameter of the brickyard back end (repeatable; tet_bvh gets exact=1
                     first, so that its frame 0 is complete: --set exact=0 undoes it)
  --vtk-smp NAME     VTK SMP back end (Sequential, STDThread, TBB; default: VTK's own)
  --vtk-merge 0|1    vtkContour3DLinearGrid merges coincident points (default 0, VTK's default)
  --embree-quality Q Embree BVH build quality: low, medium (Embree's default) or high
  --max-mismatch F   the camera check fails above this fraction of pixels (default 0.01)
  --brickyard PATH   the brickyard executable (default build/bin/brickyard)
  --out DIR          output folder (default out/peers-tets)
  -h, --help         this text

Exit status: 0 on success, 2 for a bad argument, 3 when the camera check fails, 1 otherwise.
EOF
}

mesh=mesh:sphere cells=55 jitter=0.1 array="" iso=0 backend=tet_bvh width=512 height=512 frames=8 threads=2
eye=1.9,-1.1,1.3 target=0.5,0.5,0.45 up=0,0,1 fov=38
sets=() vtk_smp="" vtk_merge=0 embree_quality=medium max_mismatch=0.01 brickyard="$root/build/bin/brickyard" out="out/peers-tets"
cells_given="" jitter_given=""

while [ $# -gt 0 ]; do
  opt="$1"
  case "$opt" in
    -h | --help) usage; exit 0 ;;
    --mesh | --cells | --jitter | --array | --iso | --backend | --width | --height | --frames | --threads | --eye | \
      --target | --up | --fov | --set | --vtk-smp | --vtk-merge | --embree-quality | --max-mismatch | --brickyard | --out)
      [ $# -ge 2 ] || die "$opt needs a value"
      val="$2"
      shift 2
      ;;
    --*=*) die "write '${opt%%=*} ${opt#*=}', not '$opt'" ;;
    *) die "unknown argument '$opt'" ;;
  esac
  case "$opt" in
    --mesh) [ -n "$val" ] || die "--mesh: an empty source"; mesh="$val" ;;
    --cells) { is_int "$val" && [ "$val" -ge 1 ] && [ "$val" -le 512 ]; } || die "--cells: '$val' is not an integer in [1, 512]"; cells="$val" cells_given=1 ;;
    --jitter) { is_number "$val" && awk -v j="$val" 'BEGIN { exit !(j >= 0 && j <= 0.2) }'; } || die "--jitter: '$val' is not a number in [0, 0.2]"; jitter="$val" jitter_given=1 ;;
    --array) [[ "$val" =~ ^[A-Za-z0-9_.:-]+$ ]] || die "--array: '$val' is not an array name"; array="$val" ;;
    --vtk-merge) case "$val" in 0 | 1) vtk_merge="$val" ;; *) die "--vtk-merge: '$val' is not 0 or 1" ;; esac ;;
    *) shared_option "$opt" "$val" ;;
  esac
done

# A procedural mesh takes --cells and --jitter; a mesh file takes --array.
if [[ "$mesh" == mesh:* ]]; then
  [[ "${mesh#mesh:}" =~ ^[A-Za-z0-9_.-]+$ ]] || die "--mesh: '$mesh' is not mesh:FIELD"
  [ -z "$array" ] || die "--array: a procedural mesh ($mesh) has one array; --array is for mesh files"
else
  [ -z "$cells_given$jitter_given" ] || die "--cells and --jitter are for a procedural mesh (mesh:FIELD), not '$mesh'"
  case "$mesh" in
    *.vtu | *.pvd | *.vtk | *.msh | *.node | *.ele) ;;
    *) die "--mesh: '$mesh' is neither mesh:FIELD nor a mesh file (.vtu .pvd .vtk .msh .node/.ele)" ;;
  esac
  [ -f "$mesh" ] || die "--mesh: $mesh: no such file"
fi

# --- brickyard: built, and it knows the back end, which renders meshes -------------------------

need_brickyard "$brickyard"
by=("$brickyard" -q -j "$threads")
need_backend "$brickyard" "$backend"
"$brickyard" render --list-backends | awk -v b="$backend" '$1 == b' | grep -q 'tetrahedral' ||
  die "--backend: '$backend' does not render tetrahedral meshes"
if [[ "$mesh" == mesh:* ]]; then
  known_fields="$("$brickyard" generate --list | awk '/^[^ ]/ {print $1}')"
  grep -qx -- "${mesh#mesh:}" <<<"$known_fields" ||
    die "--mesh: this brickyard has no field '${mesh#mesh:}' (it has: $(echo $known_fields | tr ' ' ','))"
fi
# tet_bvh's frame 0 waits for its clusters (exact=1) unless the caller says otherwise: the
# issue's first frame is a complete one. Later --set options win (the CLI keeps the last).
[ "$backend" = tet_bvh ] && sets=(--set exact=1 "${sets[@]}")

# --- Debian packages, and embree_frame in a build folder of its own -------------------------

install_peers
build_embree_frame

# --- data: one store of the mesh, and the .vtu of that store -------------------------------

mkdir -p "$out"
out="$(cd "$out" && pwd)"
data="$out/data"
if [[ "$mesh" == mesh:* ]]; then
  name="${mesh#mesh:}-c$cells-j$jitter"
  import_args=(--cells "$cells" --jitter "$jitter")
else
  name="$(basename "$mesh")"
  name="${name%.*}"
  import_args=(--single-step)
  [ -n "$array" ] && import_args+=(--array "$array")
fi
store="$data/$name.store"
vtu="$data/$name.vtu"
mkdir -p "$data"
rm -rf "$out/frames" "$out/results.json" "$out/results.csv" "$store" "$vtu"
echo "peers-tets: importing $mesh into $store, and exporting it as $vtu" >&2
"${by[@]}" import "$mesh" "${import_args[@]}" -o "$store" >"$out/import.log"
# VTK reads what brickyard stores (validated tets, float coordinates), not the source file.
"${by[@]}" export "$store" -o "$vtu" --encoding appended >/dev/null
"$brickyard" info "$store" --json >"$out/manifest.json"

cam=(--eye "$eye" --target "$target" --up "$up" --fov "$fov")
"$py" "$here/peers.py" scene --store "$store" --backend "$backend" --iso "$iso" --width "$width" --height "$height" \
  --frames "$frames" --out "$out/scene.json" "${cam[@]}"

# --- 1. VTK: vtkContour3DLinearGrid ------------------------------------------------------------

vtk_args=()
[ -n "$vtk_smp" ] && vtk_args=(--smp-backend "$vtk_smp")
"$py" "$here/peers.py" tets-vtk --vtu "$vtu" --iso "$iso" --threads "$threads" --merge-points "$vtk_merge" "${vtk_args[@]}" \
  --mesh "$out/surface.bymesh" --json "$out/vtk.json"

# --- 2. Embree: BVH build and frames over those triangles ---------------------------------------

box="$("$py" -c 'import json,sys; b=json.load(open(sys.argv[1]))["mesh"]["bounds"]; print(",".join(repr(float(v)) for v in b[0]+b[1]))' "$out/manifest.json")"
run_embree "$box"

# --- 3. brickyard, a fresh process: frame 0 loads the clusters and builds their BVHs -----------

run_brickyard

# --- the table -------------------------------------------------------------------------------------

"$py" "$here/peers.py" tets-report --dir "$out" --manifest "$out/manifest.json" --store "$store" --source "$mesh" \
  --iso "$iso" --width "$width" --height "$height" --threads "$threads" --by-wall-ms "$(( (t1 - t0) / 1000 ))e-3" \
  --max-mismatch "$max_mismatch" "${cam[@]}"
