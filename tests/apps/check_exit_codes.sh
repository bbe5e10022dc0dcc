#!/usr/bin/env bash
# Exit codes and messages of the executables for user errors (README: one line, exit 2).
# Usage: check_exit_codes.sh <build/apps dir> <tiny dataset dir>
set -u
apps=$1 data=$2
failures=0
# expect <code> <message fragment> <command...>: exit code, one line on stderr holding the fragment.
expect() {
  local code=$1 fragment=$2
  shift 2
  local err rc
  err=$("$@" 2>&1 >/dev/null)
  rc=$?
  local lines
  lines=$(printf '%s\n' "$err" | grep -c .)
  if [[ $rc -ne $code || $lines -ne 1 || "$err" != *"$fragment"* ]]; then
    echo "FAIL: $* -> exit $rc, $lines line(s): $err (expected exit $code, one line with '$fragment')"
    failures=$((failures + 1))
  else
    echo "ok: $* -> exit $rc: $err"
  fi
}
tiny=(data.root="$data" data.split_file="$data/split.yaml" model.grouping.cache_dir="$data/../kmeans_cache")
expect 2 "transhuman-train: error: The following argument was not expected: --bogus-flag" "$apps/transhuman-train" --bogus-flag
expect 2 "--max-steps: 1 required" "$apps/transhuman-train" --max-steps
expect 2 "transhuman-eval: error: --limit: 'notanumber' is not a number" "$apps/transhuman-eval" --limit notanumber
expect 2 "--threads: must be in [0, 4096], not 100000" "$apps/transhuman-render" --threads 100000
expect 2 "transhuman-mesh: error: The following argument was not expected: --no-such-option" "$apps/transhuman-mesh" --no-such-option
expect 2 "transhuman-synth: error: --out is required" "$apps/transhuman-synth"
expect 2 "unknown config key 'model.dparf.nkk' (did you mean 'model.dparf.nk'?)" "$apps/transhuman-train" --dry-run "${tiny[@]}" model.dparf.nkk=1
expect 2 "config file '/nonexistent/config.yaml' does not exist" "$apps/transhuman-train" --dry-run --config /nonexistent/config.yaml
expect 2 "--checkpoint is required" "$apps/transhuman-eval" "${tiny[@]}"
# A value out of its declared range names the key, the range and what the key does.
expect 2 "config key 'render.samples' = 1: must be in [2, 4096] (samples per ray" "$apps/transhuman-train" --dry-run "${tiny[@]}" render.samples=1
# --config-keys lists every key (on stdout) and exits 0.
keys=$("$apps/transhuman-eval" --config-keys)
if [[ $? -eq 0 && "$keys" == *"render.termination_transmittance"*"in [0, 1)"* && $(printf '%s\n' "$keys" | grep -c .) -ge 90 ]]; then
  echo "ok: transhuman-eval --config-keys lists $(printf '%s\n' "$keys" | grep -c .) keys"
else
  echo "FAIL: transhuman-eval --config-keys: $keys"
  failures=$((failures + 1))
fi
# Precision: a bad value is refused by name, on the command line and in the config.
expect 2 "--precision: fp16 not in {fp32,bf16,auto}" "$apps/transhuman-render" --precision fp16
expect 2 "config key 'precision': 'half' is not one of" "$apps/transhuman-train" --dry-run "${tiny[@]}" precision=half
expect 2 "config key 'fp32_products': 'mkl' is not one of" "$apps/transhuman-eval" --dry-run "${tiny[@]}" fp32_products=mkl
# Run folders are never silently overwritten (training and evaluation).
scratch=$(mktemp -d)
trap 'rm -rf "$scratch"' EXIT
mkdir -p "$scratch/used" && echo old > "$scratch/used/results.md"
expect 2 "already holds 1 entry (results.md)" "$apps/transhuman-eval" --checkpoint x.pt --out "$scratch/used" "${tiny[@]}"
expect 2 "already holds 1 entry (results.md)" "$apps/transhuman-train" --dry-run --out "$scratch/used" "${tiny[@]}"
"$apps/transhuman-train" --max-steps 0 --out "$scratch/run" "${tiny[@]}" train.val_views=0 >/dev/null 2>&1
expect 2 "model.dparf.nk (run: 7, now: 1)" "$apps/transhuman-train" --dry-run --resume --out "$scratch/run" "${tiny[@]}" model.dparf.nk=1
if "$apps/transhuman-train" --dry-run --resume --out "$scratch/run" "${tiny[@]}" train.lr=1e-4 >/dev/null 2>&1; then
  echo "ok: --resume with an unchanged model section"
else
  echo "FAIL: --resume with only a training key changed was refused"; failures=$((failures + 1))
fi
# A dry run writes nothing, --force or not; a run with --force replaces the folder's contents.
if "$apps/transhuman-train" --dry-run --force --out "$scratch/used" "${tiny[@]}" >/dev/null 2>&1 &&
   [[ -e "$scratch/used/results.md" && ! -e "$scratch/used/.lock" && ! -e "$scratch/used/config.yaml" ]]; then
  echo "ok: --dry-run --force leaves the folder as it was"
else
  echo "FAIL: --dry-run --force touched the folder"; failures=$((failures + 1))
fi
if "$apps/transhuman-train" --max-steps 0 --force --out "$scratch/used" "${tiny[@]}" train.val_views=0 >/dev/null 2>&1 &&
   [[ ! -e "$scratch/used/results.md" ]]; then
  echo "ok: --force replaces the folder's contents"
else
  echo "FAIL: --force"; failures=$((failures + 1))
fi
# Values are checked, never replaced by a default.
expect 2 "--orbit: must be >= 1, not 0" "$apps/transhuman-render" --orbit 0
expect 2 "--width: must be >= 1, not -10" "$apps/transhuman-render" --width -10
expect 2 "--frame: must be >= 0, not -1" "$apps/transhuman-mesh" --frame -1
expect 2 "--threshold: must be >= 0, not nan" "$apps/transhuman-mesh" --threshold nan
expect 2 "--limit: must be >= 0, not -5" "$apps/transhuman-eval" --limit -5
expect 2 "--max-steps: must be >= 0, not -1" "$apps/transhuman-train" --max-steps -1
: > "$scratch/empty.yaml"
expect 2 "config file '$scratch/empty.yaml' is empty" "$apps/transhuman-train" --dry-run --config "$scratch/empty.yaml"
printf 'parent: %s\ntrain:\n  lr:\n' "$PWD/configs/default.yaml" > "$scratch/null.yaml"
expect 2 "'train.lr' has no value" "$apps/transhuman-train" --dry-run --config "$scratch/null.yaml"
printf 'parent: %s\nseed: 1\nseed: 2\n' "$PWD/configs/default.yaml" > "$scratch/twice.yaml"
expect 2 "'seed' appears twice" "$apps/transhuman-train" --dry-run --config "$scratch/twice.yaml"
expect 2 "config file '$scratch' is a folder, not a file" "$apps/transhuman-train" --dry-run --config "$scratch"
if "$apps/transhuman-train" --help >/dev/null; then echo "ok: --help exits 0"; else echo "FAIL: --help"; failures=$((failures + 1)); fi
echo "$failures failed"
exit $((failures > 0))
