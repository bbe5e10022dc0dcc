#!/usr/bin/env bash
# Issue 15's one benchmark command: the exact and the default paths side by side, on the demo's
# trained checkpoint (trained first when runs/demo has none: about 12 minutes on 2 cores):
# a 512x512 test view at 64 and 16 samples per ray (seconds, points evaluated, peak memory,
# largest per-ray difference), the 36-view orbit at 512x512, seconds per training step at
# configs/demo.yaml, and the demo's identity evaluation (108 views). Appends the figures, with
# the date and the machine's load, to bench/results/speed.md.
#   scripts/bench-speed.sh [--sections "view orbit train eval"] [transhuman-bench-speed options...]
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install-deps.sh
bash scripts/build.sh transhuman-synth transhuman-train transhuman-bench-speed
data=data/synthetic
run=${TH_DEMO_RUN:-runs/demo}
build/apps/transhuman-synth --config configs/synth/default.yaml --out "$data"
if [[ ! -f "$run/checkpoints/latest.pt" ]]; then
  build/apps/transhuman-train --config configs/demo.yaml --out "$run" --force
fi
OMP_WAIT_POLICY=${OMP_WAIT_POLICY:-passive} build/bench/transhuman-bench-speed --config configs/demo.yaml \
  --checkpoint "$run/checkpoints/latest.pt" --out bench/results/speed.md "$@"
