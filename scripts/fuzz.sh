#!/usr/bin/env bash
# Builds the libFuzzer targets (preset `fuzz`: clang, ASan + UBSan) and runs each for SECONDS
# (default 60), one at a time in one process, against a working copy of its corpus:
# build-fuzz/corpus/<target>/ starts as the committed seeds (tests/fuzz/corpus/<target>/) and
# past findings (tests/fuzz/regressions/<target>/) and collects what libFuzzer finds; nothing
# is written into the repository. Stops at the first finding and prints its reproducer; at the
# end prints, per target, executions per second, coverage (libFuzzer's final cov: and ft:) and
# the corpus size.
#
# Usage: scripts/fuzz.sh [SECONDS] [TARGET...]   (targets: the names under tests/fuzz/corpus/)
# Environment: BRICKYARD_FUZZ_ARGS adds libFuzzer flags (e.g. "-max_len=65536").
set -euo pipefail
cd "$(dirname "$0")/.."
seconds="${1:-60}"
shift || true
case "$seconds" in '' | *[!0-9]*) echo "fuzz: SECONDS must be a whole number, not '$seconds'" >&2; exit 2 ;; esac

./scripts/setup.sh clang libclang-rt-dev
build=build-fuzz
lock=/tmp/brickyard-build.lock
if [ ! -f "$build/CMakeCache.txt" ]; then
  flock "$lock" cmake --preset fuzz >/dev/null
fi
flock "$lock" cmake --build --preset fuzz

if [ $# -gt 0 ]; then
  targets=("$@")
else
  targets=()
  for exe in "$build"/tests/fuzz/fuzz_*; do
    name="${exe##*/fuzz_}"
    [ "$name" = make_seeds ] || targets+=("$name")
  done
fi

rows=()
table() {
  printf '\n%-14s %10s %8s %8s %10s\n' target "exec/s" cov ft corpus
  for r in "${rows[@]}"; do printf '%-14s %10s %8s %8s %10s\n' $r; done
}

for t in "${targets[@]}"; do
  exe="$build/tests/fuzz/fuzz_$t"
  if [ ! -x "$exe" ]; then
    echo "fuzz: no target '$t' (built: $(ls "$build"/tests/fuzz | sed -n 's/^fuzz_//p' | grep -v make_seeds | tr '\n' ' '))" >&2
    exit 2
  fi
  corpus="$build/corpus/$t"
  artifacts="$build/artifacts/$t"
  mkdir -p "$corpus" "$artifacts"
  # Past findings named noasan-* are replayed by the normal build only: they make a library
  # outside brickyard (OpenVDB) ask operator new[] for an exabyte, which ASan reports as fatal
  # where a release build throws std::bad_alloc (and brickyard reports it).
  for d in tests/fuzz/corpus/"$t" tests/fuzz/regressions/"$t"; do
    if [ -d "$d" ]; then
      find "$d" -maxdepth 1 -type f ! -name 'noasan-*' -exec cp -n {} "$corpus"/ \;
    fi
  done
  log="$build/fuzz-$t.log"
  echo "fuzz: $t for ${seconds}s (log: $log)"
  rc=0
  # One process, one input at a time; a hang of 25 s or 2 GiB of memory is a finding too.
  # Leaks in code outside brickyard are suppressed (tests/fuzz/lsan.supp says which). A malloc
  # or nothrow new too large to make returns null, as in a release build (OpenVDB checks that
  # for sizes it reads from its files); a throwing new that large is still a finding.
  ASAN_OPTIONS="${ASAN_OPTIONS:-detect_leaks=1:abort_on_error=1:allocator_may_return_null=1}" \
  LSAN_OPTIONS="${LSAN_OPTIONS:-suppressions=$PWD/tests/fuzz/lsan.supp:print_suppressions=0}" \
  UBSAN_OPTIONS="${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}" \
    "$exe" -max_total_time="$seconds" -timeout=25 -rss_limit_mb=2048 -print_final_stats=1 \
      -artifact_prefix="$artifacts/" ${BRICKYARD_FUZZ_ARGS:-} "$corpus" </dev/null >"$log" 2>&1 || rc=$?
  last=$(grep -E '^#[0-9]+.*cov: ' "$log" | tail -n 1 || true)
  cov=$(sed -n 's/.* cov: \([0-9]*\).*/\1/p' <<<"$last")
  ft=$(sed -n 's/.* ft: \([0-9]*\).*/\1/p' <<<"$last")
  execs=$(sed -n 's/^stat::average_exec_per_sec: *\([0-9]*\).*/\1/p' "$log" | tail -n 1)
  files=$(find "$corpus" -maxdepth 1 -type f | wc -l)
  rows+=("$t ${execs:--} ${cov:--} ${ft:--} $files")
  if [ "$rc" -ne 0 ]; then
    reproducer=$(sed -n 's/.*Test unit written to \(.*\)$/\1/p' "$log" | tail -n 1)
    grep -E 'ERROR: |SUMMARY: |^fuzz: |uncaught exception|what\(\)|runtime error' "$log" | head -n 8 >&2 || true
    echo >&2
    echo "fuzz: $t found something (exit $rc); log: $log" >&2
    if [ -n "$reproducer" ]; then
      echo "fuzz: reproducer: $reproducer" >&2
      echo "fuzz: replay it: $exe $reproducer" >&2
      echo "fuzz: once fixed, keep it (minimised: $exe -minimize_crash=1 -runs=10000 $reproducer):" >&2
      echo "      mkdir -p tests/fuzz/regressions/$t && cp $reproducer tests/fuzz/regressions/$t/" >&2
    fi
    table
    exit 1
  fi
done
table
