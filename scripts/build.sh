#!/usr/bin/env bash
# Installs what is missing, configures (once) and builds a preset (default: release).
set -euo pipefail
cd "$(dirname "$0")/.."
preset="${1:-release}"
./scripts/setup.sh
case "$preset" in
  release) dir=build ;;
  *) dir="build-$preset" ;;
esac
if [ ! -f "$dir/CMakeCache.txt" ]; then
  cmake --preset "$preset" >/dev/null
fi
cmake --build --preset "$preset"
