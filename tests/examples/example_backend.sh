#!/usr/bin/env bash
# The out-of-tree example back end (examples/backend/), built against the installed package
# and loaded by the installed brickyard: it must build, load, and render the MIP that raymarch
# renders at the same step (the same samples at the same positions, so the same PNG), and
# its error against the reference must be what raymarch's is.
#   example_backend.sh BUILD_DIR SOURCE_DIR
set -euo pipefail
build=$1 source=$2
work=$(mktemp -d /tmp/brickyard-example-XXXXXX)
trap 'rm -rf "$work"' EXIT

cmake --install "$build" --prefix "$work/prefix" >/dev/null
cmake -S "$source/examples/backend" -B "$work/build" -G Ninja -DCMAKE_PREFIX_PATH="$work/prefix" \
      -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build "$work/build" >/dev/null
module="$work/build/libexample_mip.so"
by="$work/prefix/bin/brickyard"

"$by" -q import field:marschner-lobb --size 40 --type u8 --out "$work/ml.store" >/dev/null
cat > "$work/mip.json" <<'SCENE'
{"dataset": "ml.store", "backend": "example-mip", "mode": "mip", "image": {"width": 64, "height": 64},
 "camera": {"eye": [1.8, -1.2, 1.4], "target": [0.5, 0.5, 0.5], "fov_degrees": 40}}
SCENE
# Listed: read the whole listing first (grep -q stops at its match, and the lister, still
# writing, would die of SIGPIPE under pipefail).
listing=$("$by" --module "$module" render --list-backends)
grep -q "example-mip  (mip; structured)" <<<"$listing"
example=$("$by" --module "$module" render "$work/mip.json" --set step=0.25 -o "$work/example.png" --error-maps "$work/maps")
baseline=$("$by" render "$work/mip.json" --backend raymarch --set step=0.25 -o "$work/raymarch.png" --error-maps "$work/maps")
echo "$example"
echo "$baseline"
cmp "$work/example.png" "$work/raymarch.png"
rmse() { sed -n 's/.*RMSE \([0-9.e-]*\),.*/\1/p' <<<"$1"; }
[ -n "$(rmse "$example")" ] && [ "$(rmse "$example")" = "$(rmse "$baseline")" ]
echo "example-mip: built against the installed package, loaded, and equal to raymarch"
