#!/usr/bin/env bash
# The test command: installs dependencies (Debian 12, idempotent), builds, runs every test.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install-deps.sh
bash scripts/build.sh
# Tests run two at a time (2 cores); each keeps LibTorch to one thread.
cd build
OMP_NUM_THREADS=1 ctest --output-on-failure -j "${TH_TEST_JOBS:-2}" --timeout 900 "$@"
