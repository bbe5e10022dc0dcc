#!/usr/bin/env bash
# The one script for a machine with a GPU, a LibTorch with CUDA (a PyTorch installation), a
# compiler, CMake and Ninja, but none of the project's other libraries: they come in the carry
# bundle (scripts/device-bundle.sh, copied beside the sources as build-bundle/). Run from the
# repository root:
#   bash scripts/device-run.sh
# It builds only the targets it runs (into build-device/, reused by a second run), then, within
# a wall-time budget (phases that no longer fit are skipped and say so):
#   1. CUDA on the apps: a tiny dataset; the tiny surface network trained with --device cuda; the
#      same checkpoint evaluated with --device cpu and --device cuda, per_image.csv compared
#      (psnr, ssim and lpips within 1e-4, relative for psnr; point counts); a 1-rank NCCL run of a
#      few training steps (it says whether the all-reduce ran: the apps make no communicator for
#      WORLD_SIZE=1).
#   2. Figures: seconds per 512x512 view (transhuman-render, one dataset view) at 64 and 16
#      samples, fp32 and bf16, with the 438-view identity set projected; seconds per training step
#      at the paper's batch (configs/default.yaml: 6 patches of 20x20 rays, 64 samples, 512x512
#      images) and at configs/demo.yaml; peak GPU memory of each (nvidia-smi, sampled every 100 ms:
#      the whole device's memory, CUDA context included).
#   3. With the time left, CTest on the built tests (the tests have no device switch: they check
#      this LibTorch build on the CPU; failures of reference scripts for want of a Python module
#      are named as such).
# Everything lands in $OUT (default device-out/): summary.md (the figures and verdicts),
# build.log, tests.txt (CTest), bench.md (each figure's raw numbers), runs.log (every program's
# output), gpu-memory.csv. Exit status 0 when every check that ran passed.
# Environment:
#   DEVICE=cuda|cpu   cpu: a rehearsal on a machine without a GPU (TH_QUICK=1 by default there)
#   TH_QUICK=1        shortened workloads (small views, few steps): checks the script, not speed
#   TH_BUDGET_S       wall-time budget in seconds, build included (default 500)
#   TH_BUNDLE         the carry bundle (default build-bundle; empty: the system's packages)
#   TH_TORCH_PREFIX   LibTorch's CMake prefix (default: python3's torch.utils.cmake_prefix_path,
#                     else CMake's own search)
#   TH_BUILD_DIR      build folder (default build-device)  TH_JOBS  build jobs (default nproc)
#   TH_BUILD_LOCK     a file to `flock` around the build (for machines shared by builds)
set -uo pipefail

repo=$(cd "$(dirname "$0")/.." && pwd)
cd "$repo"
start=$(date +%s)
device=${DEVICE:-cuda}
case "$device" in cuda | cpu) ;; *)
  echo "device-run: DEVICE must be cuda or cpu" >&2
  exit 2
  ;;
esac
quick=${TH_QUICK:-$([[ $device == cpu ]] && echo 1 || echo 0)}
budget=${TH_BUDGET_S:-500}
bundle=${TH_BUNDLE-build-bundle}
build=${TH_BUILD_DIR:-build-device}
jobs=${TH_JOBS:-$(nproc)}
out=${OUT:-$repo/device-out}
mkdir -p "$out"
work=$(mktemp -d "${TMPDIR:-/tmp}/th-device-run.XXXXXX")
summary=$out/summary.md runs=$out/runs.log bench=$out/bench.md memcsv=$out/gpu-memory.csv
: >"$summary" && : >"$runs"
echo "| what | setting | precision | seconds | process seconds | 438 views, minutes | peak GPU memory |" >"$bench"
echo "|---|---|---|---|---|---|---|" >>"$bench"
echo "phase,baseline_mib,peak_mib,peak_minus_baseline_mib" >"$memcsv"
failures=0

elapsed() { echo $(($(date +%s) - start)); }
left() { echo $((budget - $(elapsed))); }
say() { echo "$*" | tee -a "$summary"; }
note() { echo "device-run [$(elapsed) s]: $*" | tee -a "$runs" >&2; }
fail() {
  failures=$((failures + 1))
  say "- FAIL: $*"
}
fits() {  # fits <seconds> <what>: true when the budget still has that much
  if (($(left) >= $1)); then return 0; fi
  say "- skipped (budget: $(left) s left, needs about $1 s): $2"
  return 1
}
now() { date +%s.%N; }
secs() { awk -v a="$1" -v b="$2" 'BEGIN { printf "%.2f", b - a }'; }

# GPU memory while a command runs: the device's used MiB sampled every 100 ms.
has_smi=0
[[ $device == cuda ]] && command -v nvidia-smi >/dev/null 2>&1 && has_smi=1
last_peak=n/a
with_memory() {  # with_memory <phase> <command...>
  local phase=$1 poller="" base=0 status
  shift
  if ((has_smi)); then
    base=$(nvidia-smi --query-gpu=memory.used --format=csv,noheader,nounits | head -n 1)
    nvidia-smi --query-gpu=memory.used --format=csv,noheader,nounits -lms 100 >"$work/mem.txt" &
    poller=$!
  fi
  "$@" >>"$runs" 2>&1
  status=$?
  if [[ -n $poller ]]; then
    kill "$poller" 2>/dev/null
    wait "$poller" 2>/dev/null
    local peak
    peak=$(awk 'BEGIN { m = 0 } $1 + 0 > m { m = $1 + 0 } END { print m }' "$work/mem.txt")
    echo "$phase,$base,$peak,$((peak - base))" >>"$memcsv"
    last_peak="$((peak - base)) MiB"
  fi
  return $status
}
run_logged() {  # run_logged <what> <command...>: output to runs.log
  echo "### $1: ${*:2}" >>"$runs"
  shift
  "$@" >>"$runs" 2>&1
}

say "# Device run: $(date -u '+%Y-%m-%d %H:%M UTC'), DEVICE=$device, quick=$quick, budget ${budget} s"
say ""
if ((has_smi)); then
  say "GPU: $(nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader | head -n 1)"
fi
say "CPU: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ *//'), $(nproc) cores"
say "Commit: $(git rev-parse --short HEAD 2>/dev/null || echo unknown)"

# --- Build ------------------------------------------------------------------------------------
torch_prefix=${TH_TORCH_PREFIX:-$(python3 -c 'import torch; print(torch.utils.cmake_prefix_path)' 2>/dev/null)}
cmake_args=(-G Ninja -DCMAKE_BUILD_TYPE=Release -DTH_BUILD_BENCH=ON -DTH_BUILD_TESTS=ON)
[[ -n $torch_prefix ]] && cmake_args+=("-DCMAKE_PREFIX_PATH=$torch_prefix")
case "$bundle" in "" | /*) ;; *) bundle=$repo/$bundle ;; esac
[[ -n $bundle ]] && cmake_args+=("-DTH_BUNDLE=$bundle")
lock=()
[[ -n ${TH_BUILD_LOCK:-} ]] && lock=(flock "$TH_BUILD_LOCK" nice -n 5)
targets=(transhuman-train transhuman-eval transhuman-render transhuman-synth
  transhuman-bench-model transhuman-bench-speed
  test_core test_render test_model test_pipeline test_train test_eval test_inference test_dist)
t0=$(now)
(
  echo "### cmake ${cmake_args[*]}"
  cmake -S . -B "$build" "${cmake_args[@]}" || exit 1
  echo "### build: ${targets[*]}"
  if ((${#lock[@]} == 0)); then
    cmake --build "$build" -j "$jobs" --target "${targets[@]}" || exit 1
  else  # one target per hold of the lock
    for t in "${targets[@]}"; do
      "${lock[@]}" cmake --build "$build" -j "$jobs" --target "$t" || exit 1
    done
  fi
) >"$out/build.log" 2>&1
build_status=$?
t1=$(now)
say "LibTorch: $(grep -o 'LibTorch [^ ]* ([^)]*)' "$out/build.log" | head -n 1)"
say "Build: $(secs "$t0" "$t1") s for ${#targets[@]} targets with $jobs jobs (exit $build_status)"
if ((build_status != 0)); then
  fail "build (the end of build.log:)"
  tail -n 30 "$out/build.log" | sed 's/^/    /' >>"$summary"
  exit 1
fi
bin=$build/apps
needed=$(readelf -d "$bin/transhuman-train" | awk '/NEEDED/ { gsub(/[][]/, "", $5); print $5 }' | tr '\n' ' ')
say "transhuman-train's shared libraries: $needed"
if grep -qE 'opencv|yaml|spdlog|fmt|png|jpeg|httplib' <<<"$needed"; then
  fail "transhuman-train needs a shared library that the bundle replaces"
fi

# --- 1. CUDA on the apps --------------------------------------------------------------------
say ""
say "## CUDA on the apps ($device)"
data=$work/tiny
kmeans=$work/kmeans
tiny_args=(data.root=$data data.split_file=$data/split.yaml model.grouping.cache_dir=$kmeans train.val_views=0)
quick_train=()
((quick)) && quick_train=(train.epochs=1 train.iters_per_epoch=6 train.warmup_epochs=0 train.log_every_steps=3)
tiny_ckpt=$work/tiny_surface/checkpoints/latest.pt
if run_logged "tiny dataset" "$bin/transhuman-synth" --config configs/synth/tiny.yaml --out "$data" --force; then
  t0=$(now)
  if with_memory tiny_surface_train "$bin/transhuman-train" --config tests/configs/tiny_surface.yaml \
    --out "$work/tiny_surface" --device "$device" "${tiny_args[@]}" "${quick_train[@]}"; then
    say "- trained the tiny surface network on $device: $(secs "$t0" "$(now)") s, peak $last_peak"
  else
    fail "training the tiny surface network on $device (runs.log)"
  fi
else
  fail "generating the tiny dataset (runs.log)"
fi

if [[ -f $tiny_ckpt ]] && fits 60 "CPU against $device evaluation"; then
  ok=1
  for side in ref:cpu dev:$device; do
    run_logged "eval ${side#*:}" "$bin/transhuman-eval" --config "$work/tiny_surface/config.yaml" \
      --checkpoint "$tiny_ckpt" --out "$work/eval_${side%%:*}" --device "${side#*:}" --force || ok=0
  done
  if ((ok)) && [[ -f $work/eval_ref/per_image.csv && -f $work/eval_dev/per_image.csv ]]; then
    # Columns: human,frame,view,psnr,ssim,lpips,seconds,points,culled_points,evaluated_points.
    verdict=$(awk -F, '
      FNR == 1 { next }
      NR == FNR { key = $1 "," $2 "," $3; p[key] = $4; s[key] = $5; l[key] = $6; e[key] = $10; n++; next }
      {
        key = $1 "," $2 "," $3
        if (!(key in p)) { missing++; next }
        d = $4 - p[key]; if (d < 0) d = -d; r = (p[key] != 0) ? d / p[key] : d; if (r > mp) mp = r
        d = $5 - s[key]; if (d < 0) d = -d; if (d > ms) ms = d
        if ($6 ~ /^[0-9.eE+-]+$/ && l[key] ~ /^[0-9.eE+-]+$/) { d = $6 - l[key]; if (d < 0) d = -d; if (d > ml) ml = d }
        d = $10 - e[key]; if (d < 0) d = -d; if (d > me) me = d
        m++
      }
      END {
        ok = (m == n && !missing && mp <= 1e-4 && ms <= 1e-4 && ml <= 1e-4)
        printf "%s %d images; largest differences: psnr %.2e (relative), ssim %.2e, lpips %.2e, evaluated points %d\n", ok ? "PASS" : "FAIL", m, mp, ms, ml, me
      }' "$work/eval_ref/per_image.csv" "$work/eval_dev/per_image.csv")
    say "- per_image.csv, cpu against $device on the same checkpoint: $verdict"
    [[ $verdict == PASS* ]] || failures=$((failures + 1))
    {
      echo "### per_image.csv (cpu)"
      cat "$work/eval_ref/per_image.csv"
      echo "### per_image.csv ($device)"
      cat "$work/eval_dev/per_image.csv"
    } >>"$runs"
  else
    fail "evaluating the tiny checkpoint on cpu and $device (runs.log)"
  fi
fi

if [[ -f $tiny_ckpt ]] && fits 40 "the 1-rank NCCL run"; then
  backend=$([[ $device == cuda ]] && echo nccl || echo gloo)
  if WORLD_SIZE=1 RANK=0 MASTER_ADDR=127.0.0.1 MASTER_PORT=$((29600 + RANDOM % 200)) \
    run_logged "1-rank $backend" "$bin/transhuman-train" --config tests/configs/tiny_train.yaml \
    --out "$work/one_rank" --device "$device" --max-steps 3 "${tiny_args[@]}" \
    train.dist_backend=$backend; then
    if grep -q '"allreduce_seconds"' "$work/one_rank/metrics.jsonl" 2>/dev/null; then
      say "- 1-rank $backend training, 3 steps: ran, with the $backend all-reduce"
    else
      say "- 1-rank $backend training, 3 steps: ran as one process (WORLD_SIZE=1 makes no communicator: $backend not exercised)"
    fi
  else
    fail "1-rank $backend training (runs.log)"
  fi
fi

# --- 2. Figures -------------------------------------------------------------------------------
say ""
say "## Figures ($device)"
big=$work/synth512
px=$( ((quick)) && echo 128 || echo 512)
cat >"$work/synth512.yaml" <<EOF
parent: $repo/configs/synth/default.yaml
frames: 2
threads: $jobs
contact_sheet: false
people:
  train: [CoreView_313, CoreView_315]
  unseen: [CoreView_s08]
image:
  width: $px
  height: $px
split:
  train_frames: 1
  pose_interval: 1
  test_interval: 1
  fitting_interval: 1
EOF
big_args=(data.root=$big data.split_file=$big/split.yaml model.grouping.cache_dir=$kmeans
  train.val_views=0 train.log_every_steps=5 train.save_every_epochs=0)
steps=$( ((quick)) && echo 4 || echo 25)
((quick)) && big_args[4]=train.log_every_steps=2
# Seconds per step: the median of metrics.jsonl's windows after the first (warm-up).
step_time() {
  grep -o '"time_per_step": *[0-9.e+-]*' "$1/metrics.jsonl" 2>/dev/null | cut -d: -f2 | tail -n +2 |
    sort -g | awk '{ v[NR] = $1 } END { if (NR) printf "%.3f", v[int((NR + 1) / 2)]; else print "n/a" }'
}
paper_ckpt=""
if fits 60 "the 512x512 dataset" &&
  run_logged "512 dataset" "$bin/transhuman-synth" --config "$work/synth512.yaml" --out "$big" --force; then
  for cfg in paper demo; do
    if [[ $cfg == paper ]]; then
      args=(--config configs/default.yaml data.ratio=1.0)
      what="the paper's batch (6 x 20x20 rays, 64 samples, ${px}x${px} images)"
      if ((quick)); then  # a CPU takes about half a minute for one such step
        args+=(data.patch.count=1 data.patch.size=8 render.samples=8)
        what="the paper's config, quick (1 x 8x8 rays, 8 samples, ${px}x${px} images)"
      fi
    else
      args=(--config configs/demo.yaml data.ratio=0.25)
      what="configs/demo.yaml (4 x 16x16 rays, 16 samples, $((px / 4))x$((px / 4)) images)"
    fi
    fits 60 "training step at $what" || continue
    for prec in fp32 bf16; do
      [[ $cfg == demo && $prec == bf16 ]] && continue
      fits 45 "training step at $what, $prec" || continue
      dir=$work/train_${cfg}_$prec
      if with_memory "train_${cfg}_$prec" "$bin/transhuman-train" "${args[@]}" --out "$dir" \
        --device "$device" --precision "$prec" --max-steps "$steps" "${big_args[@]}"; then
        st=$(step_time "$dir")
        say "- training step at $what, $prec: $st s/step, peak GPU memory $last_peak"
        echo "| training step | $cfg | $prec | $st | | | $last_peak |" >>"$bench"
        [[ $cfg == paper && $prec == fp32 ]] && paper_ckpt=$dir/checkpoints/latest.pt
      else
        fail "training at $what, $prec (runs.log)"
      fi
    done
  done
fi

# One dataset view of an unseen person at full size: process start, checkpoint, frame preparation
# and the render; the app's own s/frame and the wall time are both kept.
if [[ -n $paper_ckpt && -f $paper_ckpt ]]; then
  for samples in 64 16; do
    for prec in fp32 bf16; do
      fits 40 "a ${px}x${px} view, $samples samples, $prec" || continue
      dir=$work/render_${samples}_$prec
      t0=$(now)
      if with_memory "view_${samples}_$prec" "$bin/transhuman-render" \
        --config "$work/train_paper_fp32/config.yaml" --checkpoint "$paper_ckpt" --out "$dir" \
        --device "$device" --precision "$prec" --camera 3 --force render.samples=$samples; then
        wall=$(secs "$t0" "$(now)")
        per=$(grep -o '[0-9.]* s/frame' "$dir/log.txt" 2>/dev/null | tail -n 1 | cut -d' ' -f1)
        per=${per:-$wall}
        proj=$(awk -v s="$per" 'BEGIN { printf "%.1f", s * 438 / 60 }')
        say "- ${px}x${px} view, $samples samples, $prec: $per s/view (process $wall s), 438-view identity set ≈ $proj min (paper, one V100: 17 min at 64, 9 min at 16); peak GPU memory $last_peak"
        echo "| ${px}x${px} view | $samples samples | $prec | $per | $wall | $proj | $last_peak |" >>"$bench"
      else
        fail "rendering a view at $samples samples, $prec (runs.log)"
      fi
    done
  done
fi
say "- paper, one V100: peak 6.2 GB rendering, 7.8 GB training"

# The benchmarks, when they take a device.
for b in model speed; do
  exe=$build/bench/transhuman-bench-$b
  if [[ -x $exe ]] && "$exe" --help 2>/dev/null | grep -q -- '--device'; then
    if fits 90 "transhuman-bench-$b"; then
      qa=()
      [[ $b == model ]] && qa=(--quick --out "")
      [[ $b == speed ]] && qa=(--config "$work/train_paper_fp32/config.yaml" --checkpoint "$paper_ckpt"
        --sections view train --repeat 1 --out "")
      with_memory "bench_$b" "$exe" --device "$device" "${qa[@]}" || fail "transhuman-bench-$b"
      say "- transhuman-bench-$b: peak GPU memory $last_peak (its figures: runs.log)"
    fi
  else
    say "- transhuman-bench-$b has no --device option: not run (CPU only)"
  fi
done

# --- 3. CPU tests -------------------------------------------------------------------------------
say ""
say "## Tests (CTest, CPU)"
python=$(command -v python3 || echo /usr/bin/python3)
if (($(left) >= 60)); then
  cap=$(($(left) - 20))
  (
    cd "$build" && TH_PYTHON=$python OMP_NUM_THREADS=1 timeout "$cap" ctest -j "$jobs" \
      --output-on-failure --timeout "$cap" \
      -R '^(synth_tiny|trained_tiny|app_train|test_core|test_render|test_model|test_pipeline|test_train|test_eval|test_inference|test_dist)'
  ) >"$out/tests.txt" 2>&1
  status=$?
  line=$(grep -E 'tests passed|tests failed' "$out/tests.txt" | tail -n 1)
  if ((status == 124)); then
    say "- stopped after $cap s (budget): $(grep -c 'Test #' "$out/tests.txt") tests had finished"
  else
    say "- ${line:-no summary (tests.txt)}"
  fi
  grep -E '^\s+[0-9]+ - ' "$out/tests.txt" | head -n 40 | sed 's/^ */  - /' >>"$summary"
  if grep -q 'ModuleNotFoundError' "$out/tests.txt"; then
    say "- some failures are reference scripts whose Python modules $python lacks: $(grep -o "No module named '[^']*'" "$out/tests.txt" | sort -u | tr '\n' ' ')"
  fi
  ((status == 0 || status == 124)) || failures=$((failures + 1))  # a budget stop is no failure
else
  say "- skipped (budget: $(left) s left)"
fi

say ""
say "Total: $(elapsed) s; $failures failed check(s)"
rm -rf "$work"
((failures == 0))
