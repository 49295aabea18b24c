#!/usr/bin/env bash
# bench/peers/dvr.sh: VTK's volume ray casters next to brickyard's DVR (issue 43), on the same
# voxels, transfer function, camera, lighting and image: a brickyard DVR scene and a store (or a
# procedural field made into one) are rendered by vtkFixedPointVolumeRayCastMapper (and, with
# --gpu-mapper, vtkGPUVolumeRayCastMapper on Mesa's llvmpipe) at each sample distance; their
# first and steady frames, the volume's read and the peak memory go into OUT/peers.json, which
# `brickyard bench SCENE --dataset STORE --peers OUT/peers.json` puts beside its back ends.
# docs/peers.md ("Volume rendering") says what is translated and measured, and how.
#
# Installs what it needs from Debian (python3-vtk9, python3-numpy, xvfb: Debian's VTK 9.1 renders
# into X windows only, so every VTK run goes through xvfb-run); nothing in the library links VTK.
set -euo pipefail

here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
me=peers-dvr
. "$here/lib.sh"

usage() {
  cat <<EOF
usage: bench/peers/dvr.sh [options]

  --scene FILE            a brickyard scene in dvr mode (default scenes/bench-dvr.json)
  --store DIR             the store to render (default: the scene's dataset); VTK reads its
                          finest level, which 'brickyard export' writes as a raw file
  --field NAME            instead of a store: 'brickyard generate' samples this field, and
  --size N                  N^3 voxels (default 128)
  --type T                  of type u8, i8, u16, i16 or f32 (default u16), imported into a store
  --width W, --height H   the image (default: the scene's)
  --threads N             threads of the fixed-point mapper (vtkMultiThreader), of VTK's SMP
                          tools and of llvmpipe; brickyard's -j in the bench (default 2)
  --frames N              frames per peer: the first, then N-1 steady ones (default 8, at least 2)
  --sample-distances L    VTK's sample distances in voxels, one peer row each (default 1,0.5)
  --gpu-mapper            also vtkGPUVolumeRayCastMapper, on Mesa's llvmpipe under Xvfb
  --backends LIST         the back ends 'brickyard bench' runs beside the peers (default: its own)
  --brickyard PATH        the brickyard executable (default build/bin/brickyard)
  --out DIR               output folder (default out/peers-dvr)
  -h, --help              this text

Exit status: 0 on success, 2 for a bad argument, 1 otherwise.
EOF
}

scene="$root/scenes/bench-dvr.json" store="" field="" size="" type="" width="" height="" threads=2 frames=8
sample_distances=1,0.5 gpu_mapper="" backends="" brickyard="$root/build/bin/brickyard" out="out/peers-dvr"

while [ $# -gt 0 ]; do
  opt="$1"
  case "$opt" in
    -h | --help) usage; exit 0 ;;
    --gpu-mapper) gpu_mapper=1; shift; continue ;;
    --scene | --store | --field | --size | --type | --width | --height | --threads | --frames | --sample-distances | \
      --backends | --brickyard | --out)
      [ $# -ge 2 ] || die "$opt needs a value"
      val="$2"
      shift 2
      ;;
    --*=*) die "write '${opt%%=*} ${opt#*=}', not '$opt'" ;;
    *) die "unknown argument '$opt'" ;;
  esac
  case "$opt" in
    --scene) [ -f "$val" ] || die "--scene: $val: no such file"; scene="$val" ;;
    --store) [ -n "$val" ] || die "--store: an empty path"; store="$val" ;;
    --field) [[ "$val" =~ ^[A-Za-z0-9_.-]+$ ]] || die "--field: '$val' is not a field name"; field="$val" ;;
    --size) { is_int "$val" && [ "$val" -ge 2 ] && [ "$val" -le 2048 ]; } || die "--size: '$val' is not an integer in [2, 2048]"; size="$val" ;;
    --type) case "$val" in u8 | i8 | u16 | i16 | f32) type="$val" ;; *) die "--type: '$val' is not u8, i8, u16, i16 or f32" ;; esac ;;
    --sample-distances)
      IFS=, read -r -a list <<<"$val"
      [ ${#list[@]} -ge 1 ] && [[ "$val" != *, ]] || die "--sample-distances: '$val' is not a list of numbers"
      for d in "${list[@]}"; do
        { is_number "$d" && awk -v d="$d" 'BEGIN { exit !(d >= 0.01 && d <= 16) }'; } ||
          die "--sample-distances: '$d' is not a number of voxels in [0.01, 16]"
      done
      sample_distances="$val"
      ;;
    --backends) [[ "$val" =~ ^[A-Za-z0-9_.,-]+$ ]] || die "--backends: '$val' is not a list of back ends"; backends="$val" ;;
    *) shared_option "$opt" "$val" ;;
  esac
done

if [ -n "$field" ] && [ -n "$store" ]; then die "--store and --field: give one (a store, or a field to make one of)"; fi
if [ -z "$field" ] && { [ -n "$size" ] || [ -n "$type" ]; }; then die "--size and --type are for --field"; fi
size="${size:-128}" type="${type:-u16}"

# --- the scene: read before anything is installed (standard-library python3 only) -------------

check_py=/usr/bin/python3
[ -x "$check_py" ] || check_py="$(command -v python3 || true)"
[ -n "$check_py" ] || fail "python3 is needed to read the scene (apt-get install python3)"
scene_dataset="$("$check_py" "$here/dvr.py" check --scene "$scene")" || exit $?

# --- brickyard and the store ------------------------------------------------------------------

need_brickyard "$brickyard"
by=("$brickyard" -q -j "$threads")
if [ -n "$field" ]; then
  known_fields="$("$brickyard" generate --list | awk '/^[^ ]/ {print $1}')"
  if ! grep -qx -- "$field" <<<"$known_fields"; then
    die "--field: this brickyard has no field '$field' (it has: $(echo $known_fields | tr ' ' ','))"
  fi
else
  if [ -z "$store" ]; then
    [ -n "$scene_dataset" ] || die "--scene $scene names no dataset: give --store or --field"
    [ -d "$scene_dataset" ] || die "--scene $scene: its dataset $scene_dataset is no directory: give --store or --field"
    store="$scene_dataset"
  fi
  [ -d "$store" ] || die "--store: $store: no such directory"
  manifest="$("${by[@]}" info "$store" --json 2>&1)" || die "--store: $store: not a store brickyard can open: $manifest"
  "$check_py" -c 'import json,sys; k=json.loads(sys.stdin.read()).get("kind","structured"); sys.exit(k!="structured")' <<<"$manifest" ||
    die "--store: $store is a tetrahedral store; the volume-rendering peers need a grid"
fi

# --- Debian packages ---------------------------------------------------------------------------

install_debian python3 python3-vtk9 python3-numpy xvfb xauth libgl1-mesa-dri

mkdir -p "$out"
out="$(cd "$out" && pwd)"
data="$out/data"
mkdir -p "$data"
rm -f "$out"/peers.json "$out"/vtk-*.png "$out"/vtk-*.json "$out/reference.png"

# --- the voxels: the store's finest level as a raw file, or the field's raw and its store -------

if [ -n "$field" ]; then
  raw="$data/$field-$size-$type.raw"
  store="$data/$field-$size-$type.store"
  echo "$me: generating $field ${size}^3 $type and its store in $data" >&2
  "${by[@]}" generate "$field" --size "$size" --type "$type" --out "$raw" >/dev/null
  rm -rf "$store"
  "${by[@]}" import "$raw" --out "$store" >/dev/null
else
  store="$(cd "$store" && pwd)"
  raw="$data/volume.raw"
  echo "$me: exporting the finest level of $store" >&2
  "${by[@]}" export "$store" --out "$raw" >/dev/null
fi
"${by[@]}" info "$store" --json >"$data/manifest.json"

size_args=()
[ -n "$width" ] && size_args+=(--width "$width")
[ -n "$height" ] && size_args+=(--height "$height")
"$py" "$here/dvr.py" scene --scene "$scene" --store "$store" "${size_args[@]}" --out "$out/scene.json"

# --- the peers: one process each, so that each one's first frame and peak memory are its own ----

xvfb=(xvfb-run -a -s "-screen 0 1280x1024x24 -nolisten tcp")
mappers=(fixed-point)
[ -n "$gpu_mapper" ] && mappers+=(gpu)
IFS=, read -r -a distances <<<"$sample_distances"
peer_args=()
for mapper in "${mappers[@]}"; do
  for d in "${distances[@]}"; do
    d="$("$py" -c 'import sys; print("%g" % float(sys.argv[1]))' "$d")"
    name="vtk-$mapper-sample$d"
    LP_NUM_THREADS="$threads" "${xvfb[@]}" "$py" "$here/dvr.py" render --scene "$out/scene.json" --raw "$raw" \
      --manifest "$data/manifest.json" --mapper "$mapper" --sample-distance "$d" --threads "$threads" \
      --frames "$frames" --png "$out/$name.png" --json "$out/$name.json"
    peer_args+=(--peer "$out/$name.json")
  done
done

dims="$("$py" -c 'import json,sys; m=json.load(open(sys.argv[1])); print("x".join(map(str, m["dims"])), m["value_type"])' "$data/manifest.json")"
title="$(basename "$scene") on $dims ($store), $threads threads"

# --- brickyard's bench with the peers, where this brickyard takes them ---------------------------

if "$brickyard" bench --help | grep -q -- --peers; then
  "$py" "$here/dvr.py" collect --out "$out" "${peer_args[@]}" --title "$title"
  bench_args=()
  [ -n "$backends" ] && bench_args+=(--backends "$backends")
  echo "$me: brickyard bench with the peers (into $out/bench)" >&2
  "${by[@]}" bench "$out/scene.json" --dataset "$store" --peers "$out/peers.json" --out "$out/bench" "${bench_args[@]}"
  echo "$me: the report, with the peers' error against the reference: $out/bench/bench.md" >&2
else
  echo "$me: this brickyard's bench takes no --peers yet: the peers are in $out/peers.json for when it does;" >&2
  echo "$me: their error here is against brickyard's reference back end ('brickyard render --backend reference')" >&2
  "${by[@]}" render "$out/scene.json" --backend reference -o "$out/reference.png" >"$out/reference.log"
  "$py" "$here/dvr.py" collect --out "$out" "${peer_args[@]}" --reference "$out/reference.png" --title "$title"
fi
