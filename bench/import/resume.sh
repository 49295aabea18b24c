#!/usr/bin/env bash
# Import throughput and resumption on a large raw file (issue 41, item 4):
#   - MB/s of raw input and peak RSS on 1 and on 2 threads (`brickyard -j N import`),
#   - the compression ratio,
#   - a kill at a fraction of the build (default 90%) and the rerun that resumes it: its time
#     against the uninterrupted build's remaining share, and the store equal to the uninterrupted
#     one record for record (`brickyard verify`, then the two stores' records compared by
#     mdb_dump of their bricks databases).
# Usage: bench/import/resume.sh [--size N] [--type u8|i16|...] [--field gyroid] [--kill-at 0.9]
#                               [--checkpoint-every S] [--work DIR] [--brickyard PATH]
# --checkpoint-every is given to the killed build and its rerun (default: import's own, 5 s; a
# build killed before its first checkpoint starts over). Before the rerun, `sync` writes back
# what the killed build left dirty in the page cache and is timed apart: that is the killed
# build's own I/O, which the rerun's final sync would otherwise pay for.
# The raw file (N^3 of the field, written by `brickyard generate`) is kept in WORK between runs.
set -euo pipefail
size=2048 type=u8 field=gyroid kill_at=0.9 work=/tmp/brickyard-import-bench by="" every=()
while [ $# -gt 0 ]; do
  case "$1" in
    --size) size=$2; shift 2 ;;
    --type) type=$2; shift 2 ;;
    --field) field=$2; shift 2 ;;
    --kill-at) kill_at=$2; shift 2 ;;
    --checkpoint-every) every=(--checkpoint-every "$2"); shift 2 ;;
    --work) work=$2; shift 2 ;;
    --brickyard) by=$2; shift 2 ;;
    *) echo "unknown option $1" >&2; exit 2 ;;
  esac
done
root="$(cd "$(dirname "$0")/../.." && pwd)"
if [ -z "$by" ]; then
  "$root/scripts/build.sh" release >/dev/null
  by="$root/build/bin/brickyard"
fi
command -v mdb_dump >/dev/null || "$root/scripts/setup.sh"
mkdir -p "$work"
raw="$work/$field-$size-$type.raw"
if [ ! -f "$raw" ] || [ ! -f "$raw.json" ]; then
  echo "== generate $field ${size}^3 $type"
  "$by" -q generate "$field" --size "$size" --type "$type" --out "$raw"
fi
bytes=$(stat -c %s "$raw")
mib=$(awk -v b="$bytes" 'BEGIN { printf "%.0f", b / 1048576 }')

# One import: prints seconds, peak RSS and peak anonymous RSS (MiB). RSS counts the pages of
# the memory-mapped raw file and store that the kernel keeps resident (clean, reclaimable); the
# anonymous part is the build's own memory.
import() {  # threads out [extra args]
  local threads=$1 out=$2; shift 2
  rm -rf "$out"
  local start=$(date +%s.%N) peak=0 anon=0
  "$by" -q -j "$threads" import "$raw" --out "$out" "$@" >"$work/import.log" &
  local pid=$!
  while kill -0 "$pid" 2>/dev/null; do
    if [ -r /proc/$pid/status ]; then
      read -r r a < <(awk '/^VmRSS/{r=$2} /^RssAnon/{a=$2} END{print r+0, a+0}' /proc/$pid/status 2>/dev/null || echo "0 0")
      [ "${r:-0}" -gt "$peak" ] && peak=$r
      [ "${a:-0}" -gt "$anon" ] && anon=$a
    fi
    sleep 0.2
  done
  wait "$pid"
  echo "$(awk -v s="$start" -v e="$(date +%s.%N)" 'BEGIN{print e-s}') $((peak / 1024)) $((anon / 1024))"
}

echo "== $raw: $mib MiB"
read -r t1 rss1 anon1 < <(import 1 "$work/s1")
rm -rf "$work/s1"
read -r t2 rss2 anon2 < <(import 2 "$work/s2")
stored=$(du -sb "$work/s2" | cut -f1)
rate() { awk -v m="$mib" -v t="$1" 'BEGIN{printf "%.1f", m/t}'; }
echo "1 thread:  $t1 s, $(rate "$t1") MiB/s, peak RSS $rss1 MiB (anonymous $anon1 MiB)"
echo "2 threads: $t2 s, $(rate "$t2") MiB/s, peak RSS $rss2 MiB (anonymous $anon2 MiB), $(awk -v a="$t1" -v b="$t2" 'BEGIN{printf "%.2f", a/b}')x of 1 thread"
printf "store: %.0f MiB on disk, %.2fx smaller than the input\n" "$(awk -v s="$stored" 'BEGIN{print s/1048576}')" "$(awk -v b="$bytes" -v s="$stored" 'BEGIN{print b/s}')"

# Checkpoints' cost: with and without them (one every 1e9 s), twice each, interleaved.
for i in 1 2; do
  read -r tc _ _ < <(import 2 "$work/s0")
  read -r tn _ _ < <(import 2 "$work/s0" --checkpoint-every 1000000000)
  echo "2 threads with checkpoints $tc s, without $tn s"
done
rm -rf "$work/s0"

# Killed at kill_at of the build's time, then resumed by the same command; where it resumed is
# what the rerun says.
kill_after=$(awk -v t="$t2" -v f="$kill_at" 'BEGIN{print t*f}')
rm -rf "$work/k"
"$by" -q -j 2 import "$raw" --out "$work/k" "${every[@]}" >/dev/null 2>&1 &
pid=$!
sleep "$kill_after"
kill -9 "$pid" 2>/dev/null || true
wait "$pid" 2>/dev/null || true
start=$(date +%s.%N)
sync
echo "writing back the killed build's dirty pages (sync): $(awk -v s="$start" -v e="$(date +%s.%N)" 'BEGIN{print e-s}') s"
start=$(date +%s.%N)
"$by" -j 2 import "$raw" --out "$work/k" "${every[@]}" >"$work/resume.log" 2>/dev/null
tr=$(awk -v s="$start" -v e="$(date +%s.%N)" 'BEGIN{print e-s}')
line=$(grep -h "resumed\|discarded\|up to date" "$work/resume.log" || true)
echo "killed after $kill_after s; the rerun: ${line:-started over} ($tr s)"
if z=$(echo "$line" | sed -n 's/.*at slice \([0-9]*\) of \([0-9]*\).*/\1 \2/p') && [ -n "$z" ]; then
  read -r done_z total_z <<<"$z"
  left=$(awk -v t="$t2" -v d="$done_z" -v n="$total_z" 'BEGIN{print t*(n-d)/n}')
  echo "the rerun took $tr s for the $(awk -v d="$done_z" -v n="$total_z" 'BEGIN{printf "%.1f", 100*(n-d)/n}')% left, which takes $left s of an uninterrupted build: $(awk -v r="$tr" -v m="$left" 'BEGIN{printf "%.1f", 100*(r-m)/m}')% more"
fi
"$by" -q verify "$work/k" >/dev/null && echo "verify: ok"
if cmp -s <(mdb_dump -s bricks "$work/k") <(mdb_dump -s bricks "$work/s2") &&
   cmp -s <(mdb_dump -s nodes "$work/k") <(mdb_dump -s nodes "$work/s2"); then
  echo "resumed store equals the uninterrupted one, record for record"
else
  echo "FAIL: the resumed store differs from the uninterrupted one"; exit 1
fi
rm -rf "$work/k" "$work/s2"
