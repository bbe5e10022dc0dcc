#!/usr/bin/env bash
# Hostile input, reproduced: crafts every bad file and request it checks by itself,
# runs the executables on it and checks the exit code (2: a user error) and the one stderr line
# naming the file, key or value. Prints a Markdown table of the cases and their outcomes.
#
#   scripts/hostile.sh [APPS_DIR] [TINY_DATASET] [GROUP...]
#
# APPS_DIR defaults to build/apps, TINY_DATASET to a fresh tiny dataset. The cases come in groups,
# one file each in scripts/hostile/ (data, runs, checkpoints, values, reports, capture, bake); no
# GROUP runs them all, one after another. Each group works in a folder of its own on copies of
# the checkpoints it needs, so groups run side by side (CTest runs one test per group).
# TH_HOSTILE_RUNS=DIR keeps those checkpoints in DIR, trained there once when missing (the group
# name `prepare` trains them anew and runs no case). Needs the built executables and Debian's
# python3 with numpy, torch and opencv (the packages of scripts/install-deps.sh), which write the
# bad files.
# Exit status 0 when every case behaves. TH_HOSTILE_TABLE=FILE also writes the table there.
set -u
repo=$(cd "$(dirname "$0")/.." && pwd)
apps=$(cd "${1:-$repo/build/apps}" && pwd)
py=${TH_PYTHON:-/usr/bin/python3}
base=$(mktemp -d "${TMPDIR:-/tmp}/th-hostile.XXXXXX")
trap 'rm -rf "$base"' EXIT
cd "$repo"
shift $(($# > 0 ? 1 : 0))

if [[ -n ${1:-} ]]; then
  data=$(cd "$1" && pwd)
  shift
else
  data=$base/tiny
  "$apps/transhuman-synth" --config configs/synth/tiny.yaml --out "$data" >/dev/null 2>&1 ||
    { echo "hostile: cannot generate the tiny dataset"; exit 1; }
fi
groups=("$@")
if ((${#groups[@]} == 0)); then
  for f in scripts/hostile/*.sh; do [[ $f == */lib.sh ]] || groups+=("$(basename "$f" .sh)"); done
fi
for g in "${groups[@]}"; do
  [[ $g == prepare || -f scripts/hostile/$g.sh ]] || { echo "hostile: no group '$g' (scripts/hostile/$g.sh)"; exit 1; }
done

# The checkpoints the cases need, trained once: ours (two steps) and other models' ones.
runs=${TH_HOSTILE_RUNS:-$base/runs}
mkdir -p "$runs"
(
  flock 9
  [[ " ${groups[*]} " == *" prepare "* ]] && rm -rf "$runs/run" "$runs/deep" "$runs/spc" "$runs/kmeans"
  train=("$apps/transhuman-train" --config tests/configs/tiny_train.yaml model.grouping.cache_dir="$runs/kmeans"
         train.val_views=0 data.root="$data" data.split_file="$data/split.yaml")
  [[ -f $runs/run/checkpoints/latest.pt ]] ||
    { rm -rf "$runs/run" && "${train[@]}" --out "$runs/run" --max-steps 2 >/dev/null 2>&1; } ||
    { echo "hostile: cannot train the tiny checkpoint"; exit 1; }
  [[ -f $runs/deep/checkpoints/latest.pt ]] ||
    { rm -rf "$runs/deep" && "${train[@]}" --out "$runs/deep" --max-steps 1 model.transhe.depth=2 >/dev/null 2>&1; }
  [[ -f $runs/spc/checkpoints/latest.pt ]] ||
    { rm -rf "$runs/spc" && "${train[@]}" --out "$runs/spc" --max-steps 1 model.representation=spc_trilinear \
        model.transhe.enabled=true >/dev/null 2>&1; }
  exit 0
) 9>"$runs/.prepare.lock" || exit 1

all_rows=() all_failures=0
for group in "${groups[@]}"; do
  [[ $group == prepare ]] && continue
  work=$base/$group
  mkdir -p "$work"
  for r in run deep spc; do cp -r "$runs/$r" "$work/$r" && rm -f "$work/$r/.lock"; done
  # shellcheck source=hostile/lib.sh
  source scripts/hostile/lib.sh
  # shellcheck disable=SC1090
  source "scripts/hostile/$group.sh"
  all_rows+=("| **$group** | | | | | |" "${rows[@]}")
  all_failures=$((all_failures + failures))
  echo "hostile: group $group: ${#rows[@]} cases, $failures failed" >&2
  rm -rf "$work"
done
[[ ${#all_rows[@]} -gt 0 ]] || exit 0

table=$(
  echo "| case | expected exit | exit | seconds | last stderr line | |"
  echo "|---|---|---|---|---|---|"
  printf '%s\n' "${all_rows[@]}"
)
echo "$table"
[[ -n ${TH_HOSTILE_TABLE:-} ]] && echo "$table" >"$TH_HOSTILE_TABLE"
cases=$(printf '%s\n' "${all_rows[@]}" | grep -vc '^| \*\*')
echo
echo "hostile: $cases cases, $all_failures failed"
exit $((all_failures > 0))
