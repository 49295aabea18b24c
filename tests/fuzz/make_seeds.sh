#!/usr/bin/env bash
# Regenerates the seeds of tests/fuzz/corpus/<target>/ that come from elsewhere:
#   gen-*   written by fuzz_make_seeds with the project's own writers (stores, codecs, sidecars,
#           traces, .vtu files, an OpenVDB export);
#   data-*  copies of files in the tree (scenes/, tests/data/mesh/: files VTK, gmsh and TetGen
#           wrote), multi-file formats joined as the targets split them.
# hand-* files are written by hand and left alone. Commit what changes.
# Usage: tests/fuzz/make_seeds.sh [BUILD_DIR]   (default build-fuzz; any build configures it)
set -euo pipefail
cd "$(dirname "$0")/../.."
build="${1:-build-fuzz}"
corpus=tests/fuzz/corpus
flock /tmp/brickyard-build.lock cmake --build "$build" --target fuzz_make_seeds -j2 >/dev/null
find "$corpus" -type f \( -name 'gen-*' -o -name 'data-*' \) -delete
"$build/tests/fuzz/fuzz_make_seeds" "$corpus"

sep=$'\n--8<-- next file --8<--\n'  # fuzz::kFileSeparator
copy() {
  local target="$1"; shift
  mkdir -p "$corpus/$target"
  for f in "$@"; do cp "$f" "$corpus/$target/data-$(basename "$f")"; done
}
join_files() {  # OUT FILE...: the files joined by the separator
  local out="$1" first=1; shift
  : > "$out"
  for f in "$@"; do
    [ "$first" = 1 ] || printf '%s' "$sep" >> "$out"
    cat "$f" >> "$out"
    first=0
  done
}
m=tests/data/mesh
copy scene scenes/*.json
copy camera_path scenes/flight-orbit.json
copy mesh_vtu $m/hex_ascii.vtu $m/mixed_ascii.vtu $m/hex_binary_zlib_u32_bigendian.vtu $m/hex_binary_raw_u64.vtu \
  $m/hex_appended_raw_raw_u64_bigendian.vtu $m/hex_appended_base64_zlib_u32.vtu $m/mixed_appended_raw_zlib_u64.vtu
copy mesh_vtk $m/*.vtk
copy mesh_gmsh $m/box_msh22.msh $m/box_msh22_bin.msh $m/box_msh41.msh $m/box_msh41_bin.msh $m/prism_msh2_bin.msh $m/prism_msh41.msh
join_files "$corpus/mesh_tetgen/data-cube.1" $m/cube.1.node $m/cube.1.ele
# The target names a collection's files a.vtu and b.vtu.
tmp=$(mktemp)
sed -e 's/steps_0.vtu/a.vtu/' -e 's/steps_1.vtu/b.vtu/' -e '/steps_2.vtu/d' $m/steps.pvd > "$tmp"
join_files "$corpus/mesh_pvd/data-steps" "$tmp" $m/steps_0.vtu $m/steps_1.vtu
rm -f "$tmp"
echo "seeds: $(find "$corpus" -type f | wc -l) files, $(du -sh "$corpus" | cut -f1)"
