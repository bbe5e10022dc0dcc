#!/usr/bin/env bash
# Configures (Release, Ninja when available) and builds into build/.
#   scripts/build.sh                 everything (libraries, apps, tests, benchmarks)
#   scripts/build.sh TARGET...       only these targets (the demo builds just its apps)
# TH_CMAKE_ARGS adds configure options, e.g. TH_CMAKE_ARGS=-DTH_BUILD_BENCH=OFF.
set -euo pipefail
cd "$(dirname "$0")/.."
jobs=${TH_JOBS:-$(nproc)}
generator=()
if command -v ninja >/dev/null 2>&1; then generator=(-G Ninja); fi
if [[ -f build/CMakeCache.txt ]] && ! grep -q "CMAKE_HOME_DIRECTORY:INTERNAL=$(pwd)$" build/CMakeCache.txt; then
  rm -rf build  # a build tree copied from another checkout
fi
# shellcheck disable=SC2086
cmake -S . -B build "${generator[@]}" -DCMAKE_BUILD_TYPE=Release ${TH_CMAKE_ARGS:-} >/dev/null
targets=()
for t in "$@"; do targets+=(--target "$t"); done
cmake --build build -j "$jobs" "${targets[@]}"
