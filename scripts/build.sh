#!/usr/bin/env bash
# Configures and builds the project (Release) into build/. Extra arguments go to CMake's
# configure step, e.g. scripts/build.sh -DTH_BUILD_BENCH=OFF.
set -euo pipefail
cd "$(dirname "$0")/.."
jobs=${TH_JOBS:-$(nproc)}
generator=()
if command -v ninja >/dev/null 2>&1; then generator=(-G Ninja); fi
if [[ -f build/CMakeCache.txt ]] && ! grep -q "CMAKE_HOME_DIRECTORY:INTERNAL=$(pwd)$" build/CMakeCache.txt; then
  rm -rf build  # a build tree copied from another checkout
fi
if [[ ! -f build/CMakeCache.txt ]]; then
  cmake -S . -B build "${generator[@]}" -DCMAKE_BUILD_TYPE=Release "$@"
elif (($# > 0)); then
  cmake -S . -B build "$@"
fi
cmake --build build -j "$jobs"
