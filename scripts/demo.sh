#!/usr/bin/env bash
# The main job on the built-in default dataset, as far as the pipeline goes today:
# generate the default procedural volume (Marschner-Lobb, 256^3 f32), import it into a
# multiresolution brick store, verify and describe it, fly the benchmark camera path through
# its cache recording every access, replay that trace against every policy, render the
# dataset, the renderers' error-against-run-time report against the reference, and a
# procedural tetrahedral mesh imported, verified and rendered.
# Outputs go to out/demo/ (override with BRICKYARD_OUT=dir).
set -euo pipefail
cd "$(dirname "$0")/.."
./scripts/build.sh release
by=build/bin/brickyard
out="${BRICKYARD_OUT:-out/demo}"
mkdir -p "$out"

"$by" version
"$by" generate marschner-lobb --size 256 --type f32 --out "$out/default.raw"
"$by" import "$out/default.raw" --out "$out/default.store" --octree
"$by" verify "$out/default.store"
"$by" info "$out/default.store"
"$by" flight "$out/default.store" --path scenes/flight-orbit.json --l1 16MiB --l2 32MiB \
    --trace "$out/flight.bytrace" --stats "$out/cache-stats.json"
"$by" cachebench "$out/flight.bytrace" --plot "$out/miss-ratio.png"
"$by" render scenes/default-dvr.json --dataset "$out/default.store" -o "$out/dvr.png" --stats "$out/dvr-stats.json"
"$by" bench scenes/default-iso.json --dataset "$out/default.store" --out "$out/bench"
"$by" import mesh:sphere --cells 40 --jitter 0.15 --steps 3 --out "$out/shells.store"
"$by" verify "$out/shells.store"
"$by" render scenes/tet-iso.json --dataset "$out/shells.store" -o "$out/tet-iso.png"

echo
echo "outputs in $out/:"
echo "  default.raw         the default dataset, 256^3 f32 voxels (x fastest, little-endian)"
echo "  default.raw.json    its sidecar: dims, type, spacing, origin, value range, XXH3-64 checksum"
echo "  default.store/      its brick store (LMDB) and octree volume: brickyard info|verify|export $out/default.store"
echo "  flight.bytrace      every cache access of a 120-frame camera flight (scenes/flight-orbit.json)"
echo "  cache-stats.json    the cache's statistics after the flight"
echo "  miss-ratio.png      miss ratio against cache size for every policy and OPT (data: miss-ratio.png.csv)"
echo "  dvr.png             a direct volume rendering of it (scenes/default-dvr.json), statistics in dvr-stats.json"
echo "  bench/              every back end against the reference renderer (scenes/default-iso.json)"
echo "  shells.store/       a procedural tetrahedral mesh (384k tets, 3 time steps): brickyard info $out/shells.store"
echo "  tet-iso.png         four isosurfaces of it, clipped and shadowed (scenes/tet-iso.json)"
echo
echo "report: $out/bench/bench.md  (error-vs-time.png, contact-sheet.png, bench.csv, images/)"
