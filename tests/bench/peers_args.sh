#!/usr/bin/env bash
# bench/peers/peers.sh (grids), bench/peers/tets.sh (tetrahedral meshes) and bench/peers/dvr.sh
# (volume rendering) refuse bad arguments with exit status 2 and a message naming the option,
# before they install, compile or generate anything; --help exits 0. Needs neither VTK nor
# Embree: every case here stops at argument checking.
#   peers_args.sh SOURCE_DIR BRICKYARD_EXE
set -uo pipefail
peers="$1/bench/peers/peers.sh" by="$2"
failures=0

expect() {  # expect STATUS PATTERN ARGS...: runs $peers
  local status=$1 pattern=$2
  shift 2
  local out rc name
  name="$(basename "$peers")"
  out=$("$peers" "$@" 2>&1)
  rc=$?
  if [ "$rc" -ne "$status" ] || ! grep -q -- "$pattern" <<<"$out"; then
    echo "FAIL: $name $*: exit $rc (expected $status), output:"
    echo "$out" | sed 's/^/    /'
    failures=$((failures + 1))
  else
    echo "ok: $name $* -> $rc: $(head -1 <<<"$out")"
  fi
}

expect 0 "usage: bench/peers/peers.sh" --help
expect 2 "--size: 'abc' is not an integer" --size abc
expect 2 "--size needs a value" --size
expect 2 "unknown argument '--bogus'" --bogus
expect 2 "write '--iso 0.5', not '--iso=0.5'" --iso=0.5
expect 2 "--eye: '1,2' is not X,Y,Z" --eye 1,2
expect 2 "--frames: '1' is not an integer in \[2, 1000\]" --frames 1
expect 2 "--embree-quality: 'best' is not low, medium or high" --embree-quality best
expect 2 "no back end 'no-such-backend' (it has: .*raymarch" --brickyard "$by" --backend no-such-backend
expect 2 "no field 'no-such-field' (it has: .*marschner-lobb" --brickyard "$by" --backend raymarch --field no-such-field
expect 1 "no brickyard executable" --brickyard /nonexistent/brickyard --backend raymarch

peers="$1/bench/peers/tets.sh"
expect 0 "usage: bench/peers/tets.sh" --help
expect 2 "--cells: 'abc' is not an integer" --cells abc
expect 2 "--jitter: '0.5' is not a number in \[0, 0.2\]" --jitter 0.5
expect 2 "--vtk-merge: '2' is not 0 or 1" --vtk-merge 2
expect 2 "unknown argument '--size'" --size 64
expect 2 "write '--iso 0.1', not '--iso=0.1'" --iso=0.1
expect 2 "--frames: '1' is not an integer in \[2, 1000\]" --frames 1
expect 2 "--mesh: /nonexistent.vtu: no such file" --mesh /nonexistent.vtu
expect 2 "--cells and --jitter are for a procedural mesh" --mesh /nonexistent.vtu --cells 8
expect 2 "neither mesh:FIELD nor a mesh file" --mesh volume.raw
expect 2 "no back end 'no-such-backend' (it has: .*tet_bvh" --brickyard "$by" --backend no-such-backend
expect 2 "'raymarch' does not render tetrahedral meshes" --brickyard "$by" --backend raymarch
expect 2 "no field 'no-such-field' (it has: .*sphere" --brickyard "$by" --mesh mesh:no-such-field
expect 1 "no brickyard executable" --brickyard /nonexistent/brickyard

peers="$1/bench/peers/dvr.sh"
scenes="$1/scenes"
expect 0 "usage: bench/peers/dvr.sh" --help
expect 2 "unknown argument '--iso'" --iso 0.5
expect 2 "--threads: 'abc' is not an integer" --threads abc
expect 2 "--sample-distances: 'x' is not a number of voxels" --sample-distances 1,x
expect 2 "--sample-distances: '0' is not a number of voxels" --sample-distances 0
expect 2 "--type: 'u32' is not u8, i8, u16, i16 or f32" --field fbm --type u32
expect 2 "--size and --type are for --field" --size 64
expect 2 "--store and --field: give one" --store x --field fbm
expect 2 "--scene: /nonexistent.json: no such file" --scene /nonexistent.json
expect 2 "'mode' is \"iso\"; the volume-rendering peers need a dvr scene" --scene "$scenes/bench-iso.json"
expect 2 "--store: /nonexistent.store: no such directory" --brickyard "$by" --store /nonexistent.store
expect 2 "no field 'no-such-field' (it has: .*fbm" --brickyard "$by" --field no-such-field
expect 1 "no brickyard executable" --brickyard /nonexistent/brickyard --field fbm

peers="$1/bench/peers/vdb.sh"
expect 0 "usage: bench/peers/vdb.sh" --help
expect 2 "unknown argument '--iso'" --iso 0
expect 2 "--vdb: /nonexistent.vdb: no such file" --vdb /nonexistent.vdb
expect 2 "--size: '4' is not an integer in \\[8, 4096\\]" --size 4
expect 2 "--eye: '1,2' is not X,Y,Z" --eye 1,2
expect 2 "--fov: '180' is not an angle" --fov 180
expect 2 "--frames: '1' is not an integer of at least 2" --frames 1
expect 1 "no brickyard executable" --brickyard /nonexistent/brickyard

[ "$failures" -eq 0 ] && echo "all cases passed" || { echo "$failures case(s) failed"; exit 1; }
