#!/usr/bin/env bash
# Builds everything (tests and benchmarks) and runs the whole test suite with ctest.
# Pass a preset to test a sanitizer build: ./scripts/test.sh asan | tsan
set -euo pipefail
cd "$(dirname "$0")/.."
preset="${1:-release}"
./scripts/build.sh "$preset"
ctest --preset "$preset"
