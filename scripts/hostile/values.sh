# Hostile cases, group values (sourced by scripts/hostile.sh; scripts/hostile/lib.sh has the helpers).
# Invalid values, config ranges, decimal numbers, names, the benchmarks and helper scripts.

# ---- 6. invalid values are errors, never replaced by defaults ------------------------------------
check "render --orbit 0" 2 "--orbit: must be >= 1, not 0" "$apps/transhuman-render" --orbit 0
check "render --width -10" 2 "--width: must be >= 1, not -10" "$apps/transhuman-render" --width -10
check "mesh --frame -1" 2 "--frame: must be >= 0, not -1" "$apps/transhuman-mesh" --frame -1
check "eval --limit -5" 2 "--limit: must be >= 0, not -5" "$apps/transhuman-eval" --limit -5
check "train --max-steps -1" 2 "--max-steps: must be >= 0, not -1" "$apps/transhuman-train" --max-steps -1
printf 'parent: %s\ntrain:\n  lr:\n' "$repo/configs/default.yaml" >"$work/null.yaml"
check "lr: with no value" 2 "'train.lr' has no value" "$apps/transhuman-train" --dry-run --config "$work/null.yaml"
printf 'parent: %s\nseed: 1\nseed: 2\n' "$repo/configs/default.yaml" >"$work/twice.yaml"
check "duplicate YAML key" 2 "'seed' appears twice" "$apps/transhuman-train" --dry-run --config "$work/twice.yaml"
: >"$work/empty.yaml"
check "empty config file" 2 "is empty" "$apps/transhuman-train" --dry-run --config "$work/empty.yaml"
check "missing configs/default.yaml (run elsewhere)" 2 "does not exist" \
  sh -c "cd '$work' && '$apps/transhuman-train' --dry-run"
check "a folder given as config" 2 "is a folder" "$apps/transhuman-train" --dry-run --config "$work"
check "--dry-run when the data cannot be loaded" 2 "$work/nowhere" \
  "$apps/transhuman-train" "${tiny[@]}" --dry-run data.root="$work/nowhere" data.split_file="$data/split.yaml"
check "unknown flag" 2 "The following argument was not expected: --bogus" "$apps/transhuman-eval" --bogus
check "value out of range (was a 300-digit CLI11 range)" 2 "--threads: must be in [0, 4096], not -5" "$apps/transhuman-train" --threads -5

# ---- 4b. every config value in its range, refused by name before anything is written -------------
for kv in "threads=-5|'threads' = -5: must be in [0, 4096]" "eval.limit=-3|'eval.limit' = -3: must be >= 0" \
  "model.transhe.depth=-1|'model.transhe.depth' = -1: must be in [1, 64]" \
  "model.transhe.mlp_dim=-5|'model.transhe.mlp_dim' = -5: must be >= 1" \
  "train.beta1=2|'train.beta1' = 2: must be in [0, 1)" "model.transhe.dim=0|'model.transhe.dim' = 0: must be >= 1" \
  "train.min_lr=1|'train.min_lr' = 1: must be in [0, train.lr]" \
  "data.box_padding=.nan|'data.box_padding' = nan: must be finite" \
  "data.box_padding=-1|'data.box_padding' = -1: must be >= 0" \
  "train.dist_timeout_s=.inf|'train.dist_timeout_s' = inf: must be finite" \
  "data.ratio=0.001|'data.ratio' = 0.001: must be in [0.01, 1]" \
  "train.dist_timeout_s=0|'train.dist_timeout_s' = 0: must be in (0, 86400]" \
  "render.samples=100000|'render.samples' = 100000: must be in [2, 4096]"; do
  check "config ${kv%%|*}" 2 "config key ${kv#*|}" "$apps/transhuman-train" "${tiny[@]}" $(on "$data") --dry-run \
    --out "$work/range_${kv%%=*}" "${kv%%|*}"
  [[ -e "$work/range_${kv%%=*}" ]] && { failures=$((failures + 1)); rows+=("| ... wrote $work/range_${kv%%=*} | | | | | FAIL |"); }
done

# Checks that can refuse a run come before its folder is written: a corrected rerun goes through.
check "--device cuda without CUDA" 2 "device 'cuda' requested, but the linked LibTorch has no CUDA" \
  "$apps/transhuman-train" "${tiny[@]}" $(on "$data") --dry-run --out "$work/no_cuda" --device cuda
TH_MALLOC=bogus check "TH_MALLOC=bogus" 2 "environment variable TH_MALLOC='bogus'" \
  "$apps/transhuman-train" "${tiny[@]}" $(on "$data") --dry-run --out "$work/no_cuda"
if [[ -e "$work/no_cuda" ]]; then ok=FAIL; failures=$((failures + 1)); else ok=ok; fi
rows+=("| ... no run folder written by the refused runs | - | - | - | | $ok |")

# ---- 10. numbers are decimal, names are names, the helper programs run no shell -------------------
for how in "--limit 010" "eval.limit=010"; do
  "${evaluate[@]}" $(on "$data") --out "$work/e_limit" --force $how >/dev/null 2>&1
  n=$(rows_of "$work/e_limit/per_image.csv" 2>/dev/null || echo 0)
  if [[ $n == 10 ]]; then ok=ok; else ok=FAIL; failures=$((failures + 1)); fi
  rows+=("| eval $how: ten images, not octal eight | 0 | - | - | per_image.csv holds $n rows | $ok |")
done
check "render --dry-run --camera 0100 (decimal 100, not octal 64)" 2 "--camera: camera 100 does not exist for" \
  "$apps/transhuman-render" "${tiny[@]}" $(on "$data") --checkpoint "$ckpt" --dry-run --camera 0100
check "mesh --dry-run --view 0100" 2 "camera 100 out of range" \
  "$apps/transhuman-mesh" "${tiny[@]}" $(on "$data") --checkpoint "$ckpt" --dry-run --view 0100
check "view --port 0100000 (octal would be 32768)" 2 "--port: must be in [1, 65535], not 100000" \
  "$apps/transhuman-view" --port 0100000
check "train --threads 0x10" 2 "--threads: '0x10' is not a decimal integer" "$apps/transhuman-train" --threads 0x10
check "eval --limit 1e3" 2 "--limit: '1e3' is not a decimal integer" "$apps/transhuman-eval" --limit 1e3
check "mesh --voxel 0x1p-8 (a hexadecimal number)" 2 "--voxel: '0x1p-8' is not a decimal number" \
  "$apps/transhuman-mesh" --voxel 0x1p-8
check "config eval.limit=0x10" 2 "config key 'eval.limit' must be an integer, got '0x10'" \
  "$apps/transhuman-train" "${tiny[@]}" $(on "$data") --dry-run eval.limit=0x10
check_out "train --dry-run render.samples=010" "render: 10 samples/ray" \
  "$apps/transhuman-train" "${tiny[@]}" $(on "$data") --dry-run render.samples=010
WORLD_SIZE=1 RANK=0 LOCAL_WORLD_SIZE=abc check "LOCAL_WORLD_SIZE=abc" 2 \
  "environment variable LOCAL_WORLD_SIZE='abc' must be an integer in [1, 1]" \
  "$apps/transhuman-train" "${tiny[@]}" $(on "$data") --dry-run
WORLD_SIZE=1 RANK=0 LOCAL_WORLD_SIZE=1 check_ok "... LOCAL_WORLD_SIZE=1" \
  "$apps/transhuman-train" "${tiny[@]}" $(on "$data") --dry-run
# A person renamed (folder and split file): NAME as the split file spells it.
rename_person() {
  "$py" - "$1" "$2" <<'EOF2'
import json, os, sys
root, name = sys.argv[1:3]
split = open(root + '/split.yaml').read().replace('name: CoreView_s03,', 'name: ' + json.dumps(name) + ',')
open(root + '/split.yaml', 'w').write(split)
os.rename(root + '/CoreView_s03', root + '/' + name)
EOF2
}
d=$(copy name_newline) && rename_person "$d" $'CoreView\ns03'
check "a line break in a person's name" 2 "humans[0]: the person's name holds a control character (0x0a)" \
  "${evaluate[@]}" $(on "$d") --out "$work/e_name_nl"
absent "  ... no per_image.csv written" "$work/e_name_nl/per_image.csv"
d=$(copy name_formula) && rename_person "$d" "=cmd|' /C calc'!A0"
check "a spreadsheet formula as a person's name" 2 "the person's name '=cmd|' /C calc'!A0' starts with '='" \
  "${evaluate[@]}" $(on "$d") --out "$work/e_name_formula"
d=$(copy name_at) && rename_person "$d" "@SUM(1)"
check "a name starting with @" 2 "the person's name '@SUM(1)' starts with '@'" \
  "${evaluate[@]}" $(on "$d") --out "$work/e_name_at"
d=$(copy name_comma) && rename_person "$d" 'Core,View "s03"'
check_out "a comma and quotes inside a name (quoted in per_image.csv)" '"Core,View ""s03"""' \
  sh -c '"$@" >/dev/null 2>&1 && cat "$0/per_image.csv"' "$work/e_name_comma" "${evaluate[@]}" $(on "$d") --out "$work/e_name_comma"

# The benchmarks and scripts.
bench=$(cd "$apps/../bench" 2>/dev/null && pwd)
if [[ -x $bench/transhuman-bench-dist ]]; then
  mkdir -p "$work/q';touch pwned;'"
  check "bench-dist --data with shell code in the name" 2 "1 process, 1 thread failed (1)" \
    env TMPDIR="$work" sh -c 'cd "$0" && exec "$@"' "$work" "$bench/transhuman-bench-dist" --data "q';touch pwned;'" \
    --train-exe /bin/false --steps 1 --warmup 0 --out "$work/dist.md"
  absent "  ... the shell code did not run" "$work/pwned"
  check "bench-speed --sections with shell code" 2 "--sections: " \
    env TMPDIR="$work" sh -c 'cd "$0" && exec "$@"' "$work" "$bench/transhuman-bench-speed" --config "$work/run/config.yaml" \
    --checkpoint "$ckpt" --sections 'view;touch pwned'
  absent "  ... the shell code did not run" "$work/pwned"
  check "bench-blas --bogus (was exit 109)" 2 "transhuman-bench-blas: error: The following argument was not expected: --bogus" \
    "$bench/transhuman-bench-blas" --bogus
  check "bench-io --runs 0 (was exit 105)" 2 "transhuman-bench-io: error: --runs: " "$bench/transhuman-bench-io" --runs 0
  check "bench-loader --samples 0x10" 2 "--samples: '0x10' is not a decimal integer" "$bench/transhuman-bench-loader" --samples 0x10
  check "bench-speed without --config (was exit 106)" 2 "--config is required" "$bench/transhuman-bench-speed" --checkpoint x
  check "bench-dist --steps ten" 2 "--steps: 'ten' is not a number" "$bench/transhuman-bench-dist" --steps ten
  model_md=$(sum_of bench/results/model.md)
  check "bench-model without --out (the checkout's bench/results/model.md)" 2 \
    "--out 'bench/results/model.md' exists: --force to replace it, or --out another file" \
    "$bench/transhuman-bench-model" --quick --sections points --rounds 0
  if [[ $(sum_of bench/results/model.md) == "$model_md" ]]; then ok=ok; else ok=FAIL; failures=$((failures + 1)); fi
  rows+=("| ... bench/results/model.md unchanged | - | - | - | md5 $model_md | $ok |")
  mkfifo "$work/trace_fifo" && ln -s "$work/run/config.yaml" "$work/trace_link"
  check "bench-model --trace <a FIFO>" 2 "--trace '$work/trace_fifo' is a FIFO (named pipe): the trace is written to a new or a regular file only" \
    "$bench/transhuman-bench-model" --quick --out "$work/model.md" --trace "$work/trace_fifo"
  check "bench-model --trace <a link>" 2 "--trace '$work/trace_link' is a symbolic link" \
    "$bench/transhuman-bench-model" --quick --out "$work/model.md" --trace "$work/trace_link"
  kept "  ... the FIFO, the link and its target" "$work/trace_fifo" "$work/trace_link" "$work/run/config.yaml"
else
  rows+=("| the benchmarks (build/bench) | - | - | - | skipped: not built | skip |")
fi
"$py" - "$work" <<'EOF2'
import os, sys, torch
class Code:
    def __reduce__(self):
        return (os.system, ("touch " + sys.argv[1] + "/unpickled",))
torch.save({"lin0.model.1.weight": Code()}, sys.argv[1] + "/code.pth")
EOF2
check "export_lpips.py --lin <a pickle that runs code>" 2 "--lin '$work/code.pth' is not a weights file: it names posix.system" \
  "$py" scripts/export_lpips.py --lin "$work/code.pth" --out "$work/lpips.npz"
check "export_pretrained.py --weights <the same>" 2 "--weights '$work/code.pth' is not a weights file: it names posix.system" \
  "$py" scripts/export_pretrained.py --weights "$work/code.pth" --out "$work/resnet.npz"
absent "  ... the pickle's code did not run" "$work/unpickled"
check "export_lpips.py --lin <a text file>" 2 "is not a weights file: it is neither a torch zip archive nor a pickle" \
  "$py" scripts/export_lpips.py --lin "$work/run/config.yaml" --out "$work/lpips.npz"
echo '[{"ph": "X", "name": "aten::mm", "dur": 1}]' >"$work/trace.json"
check "compare-traces.py <missing file> (was exit 1, as 'differ')" 2 "compare-traces: error: cannot read '$work/nowhere.json'" \
  "$py" scripts/compare-traces.py "$work/trace.json" "$work/nowhere.json"
check "compare-traces.py <a config, not a trace>" 2 "compare-traces: error: '$work/run/config.yaml' is not JSON" \
  "$py" scripts/compare-traces.py "$work/trace.json" "$work/run/config.yaml"
check_out "compare-traces.py <a trace> <itself>" "the same operators" \
  "$py" scripts/compare-traces.py "$work/trace.json" "$work/trace.json"
