#!/usr/bin/env bash
# transhuman-eval and transhuman-render over 2 ranks (--nproc 2) write what one process writes:
# per_image.csv rows equal but for the timing column, summary.json's scores, byte-identical
# panels and video frames. A rank that fails makes every rank exit 2 naming it, and no
# summary is left behind.
#
#   tests/apps/check_sharded.sh APPS_DIR TINY_DATASET CHECKPOINT
set -euo pipefail
apps=$1 data=$2 ckpt=$3
repo=$(cd "$(dirname "$0")/../.." && pwd)
work=$(mktemp -d "${TMPDIR:-/tmp}/th-sharded.XXXXXX")
trap 'rm -rf "$work"' EXIT
cd "$repo"
common=(--config tests/configs/tiny_surface.yaml --checkpoint "$ckpt" --threads 1
        "data.root=$data" "data.split_file=$data/split.yaml" "model.grouping.cache_dir=$work/kmeans")
fail() { echo "check_sharded: FAIL: $*" >&2; exit 1; }

# Evaluation: one process, then two ranks.
"$apps/transhuman-eval" "${common[@]}" --out "$work/one" > "$work/one.log" 2>&1 || { cat "$work/one.log"; fail "eval (1 process)"; }
"$apps/transhuman-eval" "${common[@]}" --nproc 2 --out "$work/two" > "$work/two.log" 2>&1 || { cat "$work/two.log"; fail "eval --nproc 2"; }
grep -q "views over 2 ranks" "$work/two.log" || fail "eval --nproc 2 did not split the views"
# Every column but seconds (the 7th).
rows() { cut -d, -f1-6,8- "$1"; }
diff <(rows "$work/one/per_image.csv") <(rows "$work/two/per_image.csv") > "$work/rows.diff" ||
  { cat "$work/rows.diff"; fail "per_image.csv rows differ"; }
n=$(($(wc -l < "$work/one/per_image.csv") - 1))
((n >= 2)) || fail "only $n evaluated views: nothing to split"
scores() { sed -E 's/"seconds_per_image": [^,}]*//' "$1"; }
diff <(scores "$work/one/summary.json") <(scores "$work/two/summary.json") || fail "summary.json differs"
cmp "$work/one/results.md" "$work/two/results.md" || fail "results.md differs"
for f in "$work/one/images/"*.png; do
  cmp "$f" "$work/two/images/$(basename "$f")" || fail "panel $(basename "$f") differs"
done
[[ $(ls "$work/one/images" | wc -l) -eq $(ls "$work/two/images" | wc -l) ]] || fail "panel counts differ"
echo "eval: $n views, rows, summary and $(ls "$work/one/images" | wc -l) panels identical with 1 and 2 ranks"

# Video: an orbit of 5 views.
render=("$apps/transhuman-render" "${common[@]}" --orbit 5)
"${render[@]}" --out "$work/v1" > "$work/v1.log" 2>&1 || { cat "$work/v1.log"; fail "render (1 process)"; }
"${render[@]}" --nproc 2 --out "$work/v2" > "$work/v2.log" 2>&1 || { cat "$work/v2.log"; fail "render --nproc 2"; }
grep -q "frames to render over 2 ranks" "$work/v2.log" || fail "render --nproc 2 did not split the frames"
for k in 0 1 2 3 4; do
  f=$(printf 'frame_%04d.png' "$k")
  cmp "$work/v1/frames/$f" "$work/v2/frames/$f" || fail "video frame $f differs"
done
cmp "$work/v1/contact_sheet.png" "$work/v2/contact_sheet.png" || fail "contact sheet differs"
echo "render: 5 frames and the contact sheet identical with 1 and 2 ranks"

# A rank that fails: rank 1 is given a checkpoint that does not exist. Both ranks exit 2,
# rank 0 naming rank 1 well within the timeout (rank 1 announces its failure); no summary is
# written.
port=$((20000 + RANDOM % 20000))
env_of() { echo "RANK=$1 WORLD_SIZE=2 LOCAL_RANK=$1 LOCAL_WORLD_SIZE=2 MASTER_ADDR=127.0.0.1 MASTER_PORT=$port"; }
mkdir -p "$work/bad"
t0=$(date +%s)
# shellcheck disable=SC2046
env $(env_of 0) "$apps/transhuman-eval" "${common[@]}" --out "$work/bad/out" train.dist_timeout_s=60 \
  > "$work/bad/r0.log" 2>&1 & r0=$!
# shellcheck disable=SC2046
env $(env_of 1) "$apps/transhuman-eval" "${common[@]/#$ckpt/$work/missing.pt}" train.dist_timeout_s=60 \
  > "$work/bad/r1.log" 2>&1 & r1=$!
s0=0 s1=0
wait $r0 || s0=$?
wait $r1 || s1=$?
secs=$(($(date +%s) - t0))
[[ $s0 -eq 2 && $s1 -eq 2 ]] || { cat "$work/bad/"*.log; fail "a failing rank: exit codes $s0 and $s1 (expected 2 and 2)"; }
grep -q "rank 1 of 2 failed" "$work/bad/r0.log" || { cat "$work/bad/r0.log"; fail "rank 0 does not name rank 1"; }
grep -q "missing.pt" "$work/bad/r1.log" || { cat "$work/bad/r1.log"; fail "rank 1 does not name its checkpoint"; }
((secs < 50)) || fail "the ranks took $secs s to stop (the timeout is 60 s)"
[[ ! -e $work/bad/out/summary.json && ! -e $work/bad/out/per_image.csv ]] || fail "a failed sharded evaluation left a summary"
echo "failing rank 1 (exit 2 and 2 after $secs s):"
echo "  rank 0: $(tail -1 "$work/bad/r0.log")"
echo "  rank 1: $(tail -1 "$work/bad/r1.log")"
