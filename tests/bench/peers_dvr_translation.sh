#!/usr/bin/env bash
# bench/peers/dvr.py's translation of a brickyard DVR scene into VTK (issue 43), checked on tiny
# synthetic volumes by `dvr.py selftest`: a 1- and a 4-voxel slab composite to 1 - (1 - a)^L
# over the background, and the volume's box and a marker land where brickyard's pinhole camera
# projects them, for vtkFixedPointVolumeRayCastMapper and vtkGPUVolumeRayCastMapper (Mesa), and
# for brickyard's reference back end on the same volumes. Then the same checks with the
# translation broken on purpose (opacity per world unit instead of per voxel; the image not
# flipped to top-row-first) must fail.
#
# Exits 77 (skipped) where python3-vtk9 and numpy are not importable or there is no X display
# to render into (Debian's VTK 9.1 has X render windows only): no xvfb-run and no DISPLAY.
#   peers_dvr_translation.sh SOURCE_DIR BRICKYARD_EXE
set -uo pipefail
dvr="$1/bench/peers/dvr.py" by="$2"
py=/usr/bin/python3

if ! [ -x "$py" ] || ! "$py" -c 'import numpy, vtkmodules.vtkRenderingVolume' 2>/dev/null; then
  echo "skipped: python3-vtk9 and python3-numpy are not importable by $py (apt-get install python3-vtk9 python3-numpy)"
  exit 77
fi
if command -v xvfb-run >/dev/null; then
  x=(xvfb-run -a -s "-screen 0 640x480x24 -nolisten tcp")
elif [ -n "${DISPLAY:-}" ]; then
  x=()
else
  echo "skipped: no xvfb-run and no DISPLAY: VTK has no window to render into (apt-get install xvfb xauth)"
  exit 77
fi

# Runs the selftest with these arguments: its output in `out`, its own exit status in `rc`.
# Not xvfb-run's: beside other tests xvfb-run sometimes fails to remove its temporary directory
# after the run ("problem while cleaning up temporary directory", exit 5), which says nothing
# of the selftest.
selftest() {
  out=$("${x[@]}" sh -c '"$@"; echo "selftest exit status $?"' sh "$py" "$dvr" selftest "$@" 2>&1)
  rc=$(sed -n 's/^selftest exit status \([0-9]*\)$/\1/p' <<<"$out" | tail -n 1)
  rc=${rc:-99}  # no status line: the selftest never ran
  out=$(grep -v '^selftest exit status ' <<<"$out")
}

failures=0
selftest --brickyard "$by"
echo "$out"
[ "$rc" -eq 0 ] || { echo "FAIL: the selftest exited $rc"; failures=$((failures + 1)); }

for fault in unit-distance flip; do
  selftest --mappers fixed-point --fault "$fault"
  if [ "$rc" -eq 1 ] && grep -q "checks failed" <<<"$out"; then
    echo "ok: with the fault '$fault' the selftest fails, as it must: $(grep -c FAIL <<<"$out") check(s) caught it"
  else
    echo "FAIL: with the fault '$fault' the selftest exited $rc; it must fail:"
    echo "$out" | sed 's/^/    /'
    failures=$((failures + 1))
  fi
done

[ "$failures" -eq 0 ] && echo "all cases passed" || { echo "$failures case(s) failed"; exit 1; }
