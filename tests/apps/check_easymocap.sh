#!/usr/bin/env bash
# One checkpoint evaluated on the same synthetic people in ZJU-MoCap's layout and in EasyMocap's
# (transhuman-synth --layout easymocap): per_image.csv rows identical but for the timing column,
# and summary.json's scores equal.
#
#   tests/apps/check_easymocap.sh APPS_DIR ZJU_DATASET EASYMOCAP_DATASET CHECKPOINT
set -euo pipefail
apps=$1 zju=$2 easymocap=$3 ckpt=$4
repo=$(cd "$(dirname "$0")/../.." && pwd)
work=$(mktemp -d "${TMPDIR:-/tmp}/th-easymocap.XXXXXX")
trap 'rm -rf "$work"' EXIT
cd "$repo"
fail() { echo "check_easymocap: FAIL: $*" >&2; exit 1; }
for layout in zju easymocap; do
  data=${!layout}
  "$apps/transhuman-eval" --config tests/configs/tiny_surface.yaml --checkpoint "$ckpt" --threads 2 \
    "data.root=$data" "data.split_file=$data/split.yaml" "model.grouping.cache_dir=$work/kmeans" \
    --out "$work/$layout" > "$work/$layout.log" 2>&1 || { cat "$work/$layout.log"; fail "eval on the $layout layout"; }
done
grep -q "easymocap layout (data.layout: auto)" "$work/easymocap.log" || fail "the EasyMocap layout was not detected"
grep -q "zju_mocap layout (data.layout: auto)" "$work/zju.log" || fail "the ZJU-MoCap layout was not detected"
rows() { cut -d, -f1-6,8- "$1"; }  # every column but seconds (the 7th)
diff <(rows "$work/zju/per_image.csv") <(rows "$work/easymocap/per_image.csv") > "$work/rows.diff" ||
  { cat "$work/rows.diff"; fail "per_image.csv rows differ between the layouts"; }
n=$(($(wc -l < "$work/zju/per_image.csv") - 1))
((n >= 4)) || fail "only $n evaluated views"
scores() { sed -E 's/"seconds_per_image": ?[^,}]*//' "$1"; }
diff <(scores "$work/zju/summary.json") <(scores "$work/easymocap/summary.json") || fail "summary.json differs"
echo "check_easymocap: $n per_image.csv rows identical in ZJU-MoCap's and EasyMocap's layouts (timing aside):"
rows "$work/easymocap/per_image.csv"
