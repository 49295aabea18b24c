# bench/peers/lib.sh: what the peers drivers share (peers.sh for grids, tets.sh for tetrahedral
# meshes, dvr.sh for volume rendering, vdb.sh for level sets): argument checks, the brickyard
# executable and its back ends, the Debian packages, and
# embree_frame compiled into build-peers/. Sourced, not run: the driver sets `me` (the prefix
# of its messages), `here` (bench/peers) and `root` (the repository) first.

die() {  # usage error
  echo "$me: $*" >&2
  echo "$me: run with --help for the options" >&2
  exit 2
}

fail() {
  echo "$me: $*" >&2
  exit 1
}

is_int() { [[ "$1" =~ ^[0-9]+$ ]]; }
is_number() { [[ "$1" =~ ^[-+]?([0-9]+\.?[0-9]*|\.[0-9]+)([eE][-+]?[0-9]+)?$ ]]; }
is_vec3() {
  local IFS=, parts
  read -r -a parts <<<"$1"
  [ "${#parts[@]}" -eq 3 ] && is_number "${parts[0]}" && is_number "${parts[1]}" && is_number "${parts[2]}" &&
    [[ "$1" != *, ]]
}

# need_brickyard PATH: fails (1) unless PATH is an executable.
need_brickyard() {
  [ -x "$1" ] || fail "$1: no brickyard executable; build it first (cmake --preset release && cmake --build --preset release), or name one with --brickyard"
}

# need_backend BRICKYARD NAME: a usage error (2) unless that brickyard has the back end NAME.
need_backend() {
  local known
  known="$("$1" render --list-backends | awk '/^[^ ]/ {print $1}')"
  if ! grep -qx -- "$2" <<<"$known"; then
    die "--backend: this brickyard has no back end '$2' (it has: $(echo $known | tr ' ' ','))"
  fi
}

# install_debian PACKAGE...: the Debian packages that are missing, with apt-get (as root, or
# through sudo). Sets `py`, the python3 to run.
install_debian() {
  py=/usr/bin/python3  # Debian's: python3-vtk9 and python3-numpy are built for it, not for another python3 on PATH
  local need=() p sudo apt_install
  for p in "$@"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || need+=("$p")
  done
  [ ${#need[@]} -gt 0 ] || return 0
  if [ "$(id -u)" -eq 0 ]; then sudo=(); elif command -v sudo >/dev/null; then sudo=(sudo); else
    fail "missing Debian packages: ${need[*]}; not root and no sudo: apt-get install ${need[*]}"
  fi
  echo "$me: installing ${need[*]}" >&2
  export DEBIAN_FRONTEND=noninteractive
  apt_install=("${sudo[@]}" apt-get install -y -qq --no-install-recommends -o DPkg::Lock::Timeout=600)
  "${apt_install[@]}" "${need[@]}" >/dev/null ||
    { "${sudo[@]}" apt-get update -qq -o DPkg::Lock::Timeout=600 && "${apt_install[@]}" "${need[@]}" >/dev/null; } ||
    fail "apt-get could not install ${need[*]}"
}

# install_peers: Debian's python3-vtk9, python3-numpy, libembree-dev, g++ and pkg-config, where
# any is missing. Sets `py`, the python3 to run.
install_peers() {
  install_debian python3 python3-vtk9 python3-numpy libembree-dev g++ pkg-config
}

# build_embree_frame: compiles embree_frame.cpp into build-peers/ when it is missing or older
# than its source. Sets `exe`, its path.
build_embree_frame() {
  local bin_dir="$root/build-peers" embree_flags embree_how
  exe="$bin_dir/embree_frame"
  if pkg-config --exists embree3 2>/dev/null; then
    embree_flags=($(pkg-config --cflags --libs embree3))
    embree_how="pkg-config embree3"
  else
    # Debian's libembree-dev ships CMake files but no embree3.pc: headers and library by path.
    [ -f /usr/include/embree3/rtcore.h ] || fail "no embree3 headers (/usr/include/embree3/rtcore.h) and no pkg-config embree3"
    embree_flags=(-lembree3)
    embree_how="-lembree3 (libembree-dev has no embree3.pc)"
  fi
  if [ ! -x "$exe" ] || [ "$here/embree_frame.cpp" -nt "$exe" ]; then
    mkdir -p "$bin_dir"
    echo "$me: compiling $exe (g++ -O3, Embree by $embree_how)" >&2
    g++ -std=c++17 -O3 -Wall -Wextra -o "$exe.partial" "$here/embree_frame.cpp" "${embree_flags[@]}" -pthread
    mv "$exe.partial" "$exe"
  fi
}

# embree_summary PY EMBREE_JSON: the line that says what Embree measured.
embree_summary() {
  "$1" -c 'import json,sys; e=json.load(open(sys.argv[1])); print("build %.2f ms, first frame %.2f ms, steady %.2f ms" % (e["build_ms"], e["first_frame_ms"], e["steady_frame_ms"]))' "$2"
}

# run_embree BOX: Embree's BVH build and frames over $out/surface.bymesh in BOX (lo and hi,
# six comma-separated numbers), with the driver's camera, size, threads, frames and quality.
run_embree() {
  "$exe" --mesh "$out/surface.bymesh" --box "$1" "${cam[@]}" --width "$width" --height "$height" \
    --threads "$threads" --frames "$frames" --quality "$embree_quality" --depth "$out/embree-depth.f32" --json "$out/embree.json" >/dev/null
  echo "$me: embree: $(embree_summary "$py" "$out/embree.json")" >&2
}

# run_brickyard: the back end's frames of $out/scene.json in one process, wall clock from t0
# to t1 (nanoseconds).
run_brickyard() {
  echo "$me: brickyard $backend: $frames frames of one camera" >&2
  t0=$(date +%s%N)
  "${by[@]}" render "$out/scene.json" --backend "$backend" "${sets[@]}" --frames all \
    -o "$out/frames/colour.png" --depth "$out/frames/depth.png" --stats "$out/brickyard-stats.json" >"$out/brickyard.log"
  t1=$(date +%s%N)
}

# shared_option OPT VALUE: checks and sets the options the drivers share (the caller has
# taken OPT's VALUE; the driver's own options come first in its case).
shared_option() {
  local opt="$1" val="$2"
  case "$opt" in
    --iso) is_number "$val" || die "--iso: '$val' is not a number"; iso="$val" ;;
    --backend) [[ "$val" =~ ^[A-Za-z0-9_.-]+$ ]] || die "--backend: '$val' is not a back-end name"; backend="$val" ;;
    --width) { is_int "$val" && [ "$val" -ge 1 ] && [ "$val" -le 16384 ]; } || die "--width: '$val' is not an integer in [1, 16384]"; width="$val" ;;
    --height) { is_int "$val" && [ "$val" -ge 1 ] && [ "$val" -le 16384 ]; } || die "--height: '$val' is not an integer in [1, 16384]"; height="$val" ;;
    --frames) { is_int "$val" && [ "$val" -ge 2 ] && [ "$val" -le 1000 ]; } || die "--frames: '$val' is not an integer in [2, 1000]"; frames="$val" ;;
    --threads) { is_int "$val" && [ "$val" -ge 1 ] && [ "$val" -le 1024 ]; } || die "--threads: '$val' is not an integer in [1, 1024]"; threads="$val" ;;
    --eye) is_vec3 "$val" || die "--eye: '$val' is not X,Y,Z"; eye="$val" ;;
    --target) is_vec3 "$val" || die "--target: '$val' is not X,Y,Z"; target="$val" ;;
    --up) is_vec3 "$val" || die "--up: '$val' is not X,Y,Z"; up="$val" ;;
    --fov) is_number "$val" || die "--fov: '$val' is not a number"; fov="$val" ;;
    --set) [[ "$val" =~ ^[A-Za-z0-9_]+=.+$ ]] || die "--set: '$val' is not NAME=VALUE"; sets+=(--set "$val") ;;
    --vtk-smp) case "$val" in Sequential | STDThread | TBB | OpenMP) vtk_smp="$val" ;; *) die "--vtk-smp: '$val' is not Sequential, STDThread, TBB or OpenMP" ;; esac ;;
    --embree-quality) case "$val" in low | medium | high) embree_quality="$val" ;; *) die "--embree-quality: '$val' is not low, medium or high" ;; esac ;;
    --max-mismatch) is_number "$val" || die "--max-mismatch: '$val' is not a number"; max_mismatch="$val" ;;
    --brickyard) brickyard="$val" ;;
    --out) [ -n "$val" ] || die "--out: an empty path"; out="$val" ;;
  esac
}
