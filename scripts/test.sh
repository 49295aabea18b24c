#!/usr/bin/env bash
# Builds everything (tests and benchmarks) and runs the whole test suite with ctest.
# Pass a preset to test a sanitizer build: ./scripts/test.sh asan | tsan
# ./scripts/test.sh sanitizers builds both and runs the tests that start threads (ctest label
# "threads") under ASan + UBSan and then under TSan: the second CI command (.ci/sanitizers).
set -euo pipefail
cd "$(dirname "$0")/.."
preset="${1:-release}"
if [ "$preset" = sanitizers ]; then
  for p in asan tsan; do
    ./scripts/build.sh "$p"
    echo "== ctest --preset $p -L threads"
    ctest --preset "$p" -L threads
  done
  exit 0
fi
./scripts/build.sh "$preset"
ctest --preset "$preset"
