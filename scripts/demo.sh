#!/usr/bin/env bash
# The main job: installs dependencies, builds, and runs TransHuman on the built-in data.
# (For now a dry run of configs/default.yaml: later stages add data generation, training and
# evaluation of the demo.)
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install-deps.sh
bash scripts/build.sh
./build/apps/transhuman-train --config configs/default.yaml --dry-run
