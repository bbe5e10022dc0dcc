#!/usr/bin/env bash
# What bf16 does to learning, on the demo (configs/demo.yaml) on this machine:
#   1. fp32: the demo as configured in fp32 (its wall time T and step count S);
#   2. bf16 for the same S steps;
#   3. bf16 for the same wall time T: the schedule stretched to the steps bf16 makes in T
#      (epochs from step 2's time per step, train.max_minutes = T as a cap);
#   4. with --long MINUTES: one longer bf16 run, validation every 2 epochs (validation PSNR
#      against wall time).
# Each run is evaluated on the identity setting in fp32 (the same renderer for every row), with
# the fraction of test rays whose final transmittance is below 1e-3 and 1e-4. Appends the
# tables, with the date, the commit and the processor, to bench/results/learning.md.
#   scripts/bench-learning.sh [--long MINUTES] [--runs DIR] [--skip-short]
set -euo pipefail
cd "$(dirname "$0")/.."
long=0
runs=runs/learning
skip_short=0
while (($#)); do
  case "$1" in
    --long) long=$2; shift 2 ;;
    --runs) runs=$2; shift 2 ;;
    --skip-short) skip_short=1; shift ;;
    *) echo "bench-learning: unknown option '$1' (--long MINUTES, --runs DIR, --skip-short)" >&2; exit 2 ;;
  esac
done
bash scripts/install-deps.sh
bash scripts/build.sh transhuman-synth transhuman-train transhuman-eval
build/apps/transhuman-synth --config configs/synth/default.yaml --out data/synthetic
export OMP_WAIT_POLICY=${OMP_WAIT_POLICY:-passive}
mkdir -p "$runs"
iters=$(awk '$1 == "iters_per_epoch:" {print $2; exit}' configs/demo.yaml)

# A field of the last line of a JSON-lines file that has it.
last() { python3 -c "import json,sys
v=None
for l in open(sys.argv[1]):
    d=json.loads(l)
    if sys.argv[2] in d: v=d[sys.argv[2]]
print(v)" "$1" "$2"; }

train() {  # NAME OVERRIDES...
  local name=$1; shift
  echo "bench-learning: training $name ($*)"
  build/apps/transhuman-train --config configs/demo.yaml --out "$runs/$name" --force "$@"
  build/apps/transhuman-eval --config configs/demo.yaml --checkpoint "$runs/$name/checkpoints/latest.pt" \
    --out "$runs/$name/eval_identity" --force precision=fp32 eval.save_images=false
}

if ((skip_short == 0)); then
  train fp32 precision=fp32
  steps=$(last "$runs/fp32/metrics.jsonl" step)
  wall=$(last "$runs/fp32/metrics.jsonl" elapsed_s)
  train bf16_steps precision=bf16
  bf16_wall=$(last "$runs/bf16_steps/metrics.jsonl" elapsed_s)
  epochs=$(python3 -c "print(max(1, round($wall / ($bf16_wall / $steps) / $iters)))")
  train bf16_wall precision=bf16 train.epochs="$epochs" train.max_minutes="$(python3 -c "print($wall / 60)")"
fi
if ((long > 0)); then
  per_step=$(python3 -c "import json
rows=[json.loads(l) for l in open('$runs/bf16_steps/metrics.jsonl') if 'elapsed_s' in l]
print(rows[-1]['elapsed_s'] / rows[-1]['step'])")
  epochs=$(python3 -c "print(max(2, round($long * 60 / $per_step / $iters)))")
  train bf16_long precision=bf16 train.epochs="$epochs" train.max_minutes="$long" train.val_every_epochs=2 \
    train.save_every_epochs=4
fi

python3 - "$runs" "$long" <<'EOF' | tee -a bench/results/learning.md
import json, os, subprocess, sys, datetime
runs, long = sys.argv[1], float(sys.argv[2])
def rows(path):
    return [json.loads(l) for l in open(path)] if os.path.exists(path) else []
def summary(name):
    p = os.path.join(runs, name, 'eval_identity', 'summary.json')
    return json.load(open(p)) if os.path.exists(p) else None
commit = subprocess.run(['git', 'rev-parse', '--short', 'HEAD'], capture_output=True, text=True).stdout.strip()
cpu = next((l.split(':', 1)[1].strip() for l in open('/proc/cpuinfo') if l.startswith('model name')), 'unknown')
load = open('/proc/loadavg').read().split()[:3]
print(f"\n# Learning in bf16 and fp32 ({datetime.datetime.utcnow():%Y-%m-%d %H:%M} UTC)\n")
print(f"configs/demo.yaml, commit {commit}, {cpu}, {os.cpu_count()} cores, load at the end {' '.join(load)}. "
      "Every evaluation: identity setting (108 views), rendered in fp32.\n")
print("| run | precision | steps | wall time s | s per step | identity PSNR | SSIM | rays with T < 1e-3 | T < 1e-4 |")
print("|---|---|---|---|---|---|---|---|---|")
for name, label in [('fp32', 'fp32'), ('bf16_steps', 'bf16, same steps'), ('bf16_wall', 'bf16, same wall time'),
                    ('bf16_long', f'bf16, long ({long:g} min)')]:
    m = [r for r in rows(os.path.join(runs, name, 'metrics.jsonl')) if 'elapsed_s' in r]
    s = summary(name)
    if not m or not s:
        continue
    prec = 'fp32' if name == 'fp32' else 'bf16'
    print(f"| {label} | {prec} | {m[-1]['step']} | {m[-1]['elapsed_s']:.0f} | {m[-1]['elapsed_s'] / m[-1]['step']:.3f} | "
          f"{s['psnr']:.3f} | {s['ssim']:.4f} | {100 * s['opaque_rays_1e-3']:.3f}% | {100 * s['opaque_rays_1e-4']:.3f}% |")
m = rows(os.path.join(runs, 'bf16_long', 'metrics.jsonl'))
if long > 0 and m:
    elapsed = {r['step']: r['elapsed_s'] for r in m if 'elapsed_s' in r}
    print("\nLong bf16 run: validation PSNR (2 views) against wall time.\n")
    print("| step | wall time min | validation PSNR |")
    print("|---|---|---|")
    for r in m:
        if 'val_psnr' in r:
            t = elapsed.get(r['step'])
            print(f"| {r['step']} | {t / 60:.1f} | {r['val_psnr']:.2f} |" if t is not None else
                  f"| {r['step']} | - | {r['val_psnr']:.2f} |")
print()
EOF
