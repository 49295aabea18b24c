#!/usr/bin/env bash
# bench/peers/vdb.py's translation of brickyard's camera into vdb_render's options (issue 43):
# a sphere level set made by vdb_tool must cover exactly the pixels whose rays through
# brickyard's pinhole camera meet the sphere, but within 1.5 pixels of its silhouette, in a wide
# and a tall image; with the field of view left vertical on purpose (vdb_render's -fov is the
# horizontal one) the same check must fail.
#
# Exits 77 (skipped) where vdb_render or vdb_tool is missing (apt-get install libopenvdb-tools).
#   peers_vdb_translation.sh SOURCE_DIR
set -uo pipefail
vdb="$1/bench/peers/vdb.py"
py=/usr/bin/python3
if ! command -v vdb_render >/dev/null || ! command -v vdb_tool >/dev/null || ! [ -x "$py" ]; then
  echo "skipped: vdb_render and vdb_tool are not installed (apt-get install libopenvdb-tools)"
  exit 77
fi
failures=0
"$py" "$vdb" selftest || failures=$((failures + 1))
out=$("$py" "$vdb" selftest --fault vertical-fov 2>&1)
rc=$?
if [ "$rc" -eq 1 ] && grep -q "checks failed" <<<"$out"; then
  echo "ok: with the field of view left vertical the selftest fails, as it must"
else
  echo "FAIL: with the fault 'vertical-fov' the selftest exited $rc; it must fail:"
  echo "$out" | sed 's/^/    /'
  failures=$((failures + 1))
fi
[ "$failures" -eq 0 ] && echo "all cases passed" || { echo "$failures case(s) failed"; exit 1; }
