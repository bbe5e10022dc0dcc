#!/usr/bin/env bash
# The end-to-end speed benchmark: several paths side by side on the demo's trained checkpoint
# (trained first, as scripts/demo.sh trains it, when runs/demo has none): a 512x512 test view at
# 64 and 16 samples per ray (seconds, points evaluated, peak memory, per-ray differences), the
# 36-view orbit at 512x512, seconds per training step at configs/demo.yaml, and the demo's
# identity evaluation (108 views, with each rendered image compared with the reference path's).
# By default the paths are fp32 products through BLAS, fp32 as configured (oneDNN products) and
# bf16, alternating twice, each in a process of its own. Appends the figures, with the date, the
# commit, the processor and the machine's load, to bench/results/speed.md.
#   scripts/bench-speed.sh [transhuman-bench-speed options...]
#   e.g. scripts/bench-speed.sh --sections view train --paths exact default --repeat 1
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
defaults=()
[[ " $* " == *" --paths "* ]] || defaults+=(--paths blas fp32 bf16)
[[ " $* " == *" --repeat "* ]] || defaults+=(--repeat 2)
[[ " $* " == *" --eval-images "* ]] || defaults+=(--eval-images)
OMP_WAIT_POLICY=${OMP_WAIT_POLICY:-passive} build/bench/transhuman-bench-speed --config configs/demo.yaml \
  --checkpoint "$run/checkpoints/latest.pt" --out bench/results/speed.md ${defaults[@]+"${defaults[@]}"} "$@"
