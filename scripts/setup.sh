#!/usr/bin/env bash
# Installs the Debian packages brickyard needs, only those that are missing.
# Idempotent: when everything is present it changes nothing and asks no mirror.
# Extra packages a script needs besides these may be given as arguments (scripts/fuzz.sh).
set -euo pipefail

packages=(
  cmake g++ ninja-build pkg-config ccache
  liblmdb-dev lmdb-utils liblz4-dev
  libopenvdb-dev libboost-iostreams-dev libnifti2-dev libnetcdf-dev libgdcm-dev
  libtbb-dev libgtest-dev libgmock-dev libbenchmark-dev
  libcli11-dev nlohmann-json3-dev libpng-dev libfmt-dev libxxhash-dev zlib1g-dev libexpat1-dev libabsl-dev
  gnuplot-nox
  "$@"
)

missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if [ ${#missing[@]} -eq 0 ]; then
  exit 0
fi

if [ "$(id -u)" -eq 0 ]; then
  sudo=()
elif command -v sudo >/dev/null 2>&1; then
  sudo=(sudo)
else
  echo "setup: missing Debian packages: ${missing[*]}" >&2
  echo "setup: not root and no sudo; install them with: apt-get install ${missing[*]}" >&2
  exit 1
fi

echo "setup: installing ${missing[*]}" >&2
export DEBIAN_FRONTEND=noninteractive
"${sudo[@]}" apt-get update -qq
"${sudo[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}"
