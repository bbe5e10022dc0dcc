#!/usr/bin/env bash
# transhuman-eval --baked (METHOD 7.1) on the trained tiny checkpoint, against the exact renderer:
#   - every row, summary.json and results.md say the renderer ("exact", "baked 2 cm");
#   - each baked row's PSNR is within BOUND_DB of the exact row's, and SSIM within BOUND_SSIM
#     (the bound the docs state for this check: docs/TESTING.md);
#   - one bake per frame: the log counts the frames baked;
#   - over 2 ranks the baked rows equal one process's, resumed over 2 ranks too;
#   - --resume continues an evaluation cut short (rows.jsonl) with the same rows, and is refused
#     (exit 2, naming the renderer, the folder untouched) when the folder's rows were made by
#     another renderer; a used folder without --resume is refused and the message offers
#     --resume; a NaN row and an oversized rows.jsonl are refused naming the file.
#
#   tests/apps/check_eval_baked.sh APPS_DIR TINY_DATASET CHECKPOINT
set -euo pipefail
apps=$1 data=$2 ckpt=$3
BOUND_DB=0.3 BOUND_SSIM=0.03
repo=$(cd "$(dirname "$0")/../.." && pwd)
work=$(mktemp -d "${TMPDIR:-/tmp}/th-eval-baked.XXXXXX")
trap 'rm -rf "$work"' EXIT
cd "$repo"
common=(--config tests/configs/tiny_surface.yaml --checkpoint "$ckpt" --threads 1 --limit 6
        "data.root=$data" "data.split_file=$data/split.yaml" "model.grouping.cache_dir=$work/kmeans")
eval=("$apps/transhuman-eval" "${common[@]}")
fail() { echo "check_eval_baked: FAIL: $*" >&2; exit 1; }
refused() {  # refused LOG PATTERN WHAT: exit 2 and the pattern in the message
  local rc=$1 log=$2 pattern=$3 what=$4
  [[ $rc -eq 2 ]] && grep -q -- "$pattern" "$log" || { cat "$log"; fail "$what: exit $rc"; }
}

"${eval[@]}" --out "$work/exact" > "$work/exact.log" 2>&1 || { cat "$work/exact.log"; fail "exact eval"; }
"${eval[@]}" --baked --out "$work/baked" > "$work/baked.log" 2>&1 || { cat "$work/baked.log"; fail "eval --baked"; }
grep -q "frames baked for 6 views (baked 2 cm)" "$work/baked.log" || fail "the log does not count the bakes"
head -1 "$work/baked/per_image.csv" | grep -q ",renderer$" || fail "per_image.csv has no renderer column"
[[ $(tail -n +2 "$work/baked/per_image.csv" | grep -c ",baked 2 cm$") -eq 6 ]] || fail "a baked row does not say 'baked 2 cm'"
[[ $(tail -n +2 "$work/exact/per_image.csv" | grep -c ",exact$") -eq 6 ]] || fail "an exact row does not say 'exact'"
grep -q '"renderer": "baked 2 cm"' "$work/baked/summary.json" || fail "summary.json does not say the renderer"
grep -q "| identity | baked 2 cm | 6 |" "$work/baked/results.md" || fail "results.md does not say the renderer"
python3 - "$work/exact/per_image.csv" "$work/baked/per_image.csv" "$BOUND_DB" "$BOUND_SSIM" <<'PY'
import csv, sys
exact = {(r['human'], r['frame'], r['view']): r for r in csv.DictReader(open(sys.argv[1]))}
baked = {(r['human'], r['frame'], r['view']): r for r in csv.DictReader(open(sys.argv[2]))}
assert exact.keys() == baked.keys(), 'the two evaluations scored other views'
bound_db, bound_ssim = float(sys.argv[3]), float(sys.argv[4])
dp = [float(baked[k]['psnr']) - float(exact[k]['psnr']) for k in exact]
ds = [float(baked[k]['ssim']) - float(exact[k]['ssim']) for k in exact]
print(f'baked 2 cm - exact over {len(dp)} views: PSNR mean {sum(dp) / len(dp):+.3f} dB, worst {max(dp, key=abs):+.3f} dB; '
      f'SSIM mean {sum(ds) / len(ds):+.4f}, worst {max(ds, key=abs):+.4f}')
assert max(map(abs, dp)) <= bound_db, f'a baked PSNR is more than {bound_db} dB from the exact one'
assert max(map(abs, ds)) <= bound_ssim, f'a baked SSIM is more than {bound_ssim} from the exact one'
PY

# Two ranks: the same baked rows (every column but seconds, the 7th).
"${eval[@]}" --baked --nproc 2 --out "$work/baked2" > "$work/baked2.log" 2>&1 || { cat "$work/baked2.log"; fail "eval --baked --nproc 2"; }
rows() { cut -d, -f1-6,8- "$1"; }
diff <(rows "$work/baked/per_image.csv") <(rows "$work/baked2/per_image.csv") || fail "baked rows differ over 2 ranks"
# ... and resumed over 2 ranks after a stop: rank 0 reads the rows, the ranks share the rest.
head -2 "$work/baked2/rows.jsonl" > "$work/rows" && mv "$work/rows" "$work/baked2/rows.jsonl"
"${eval[@]}" --baked --nproc 2 --resume --out "$work/baked2" > "$work/baked2r.log" 2>&1 || { cat "$work/baked2r.log"; fail "eval --baked --nproc 2 --resume"; }
grep -q "resumed: 2 of 6 views already scored, 4 left" "$work/baked2r.log" || { cat "$work/baked2r.log"; fail "the 2-rank resume did not keep 2 rows"; }
diff <(rows "$work/baked/per_image.csv") <(rows "$work/baked2/per_image.csv") || fail "baked rows resumed over 2 ranks differ"

# Resumed after a stop: three rows kept, one line cut short, the rest evaluated again.
head -3 "$work/exact/rows.jsonl" > "$work/rows" && head -c 40 <(sed -n 4p "$work/exact/rows.jsonl") >> "$work/rows"
mv "$work/rows" "$work/exact/rows.jsonl"
cp "$work/exact/per_image.csv" "$work/exact.csv"
rm "$work/exact/per_image.csv" "$work/exact/summary.json"
"${eval[@]}" --resume --out "$work/exact" > "$work/resume.log" 2>&1 || { cat "$work/resume.log"; fail "eval --resume"; }
grep -q "resumed: 3 of 6 views already scored, 3 left" "$work/resume.log" || { cat "$work/resume.log"; fail "the resume did not keep 3 rows"; }
grep -q "cut short" "$work/resume.log" || fail "the line cut short is not reported"
diff <(rows "$work/exact.csv") <(rows "$work/exact/per_image.csv") || fail "resumed rows differ"

# Rows that are not scores: a PSNR of null (NaN), a journal far larger than the setting's rows.
cp -r "$work/exact" "$work/nan" && sed -i '1s/"psnr": [^,]*/"psnr": null/' "$work/nan/rows.jsonl"
set +e
"${eval[@]}" --resume --out "$work/nan" > "$work/nan.log" 2>&1; rc=$?
set -e
refused "$rc" "$work/nan.log" "rows.jsonl' line 1: its PSNR or SSIM is not a finite number" "a NaN row"
cp -r "$work/exact" "$work/huge" && truncate -s 100M "$work/huge/rows.jsonl"
set +e
"${eval[@]}" --resume --out "$work/huge" > "$work/huge.log" 2>&1; rc=$?
set -e
refused "$rc" "$work/huge.log" "holds 104857600 bytes, more than" "a 100 MB rows.jsonl"

# Another renderer's rows are not resumed; a used folder needs --resume (or --force).
set +e
"${eval[@]}" --baked --resume --out "$work/exact" > "$work/mixed.log" 2>&1; rc=$?
set -e
refused "$rc" "$work/mixed.log" "renderer (rows: exact, now: baked 2 cm)" "a baked resume of exact rows"
grep -q "^  renderer: exact" "$work/exact/config.yaml" || fail "the refused resume rewrote the folder's config.yaml"
set +e
"${eval[@]}" --out "$work/exact" > "$work/used.log" 2>&1; rc=$?
set -e
refused "$rc" "$work/used.log" "or --resume to continue the evaluation" "eval into a used folder"
set +e
"${eval[@]}" --bake-voxel 0.01 --out "$work/voxel" > "$work/voxel.log" 2>&1; rc=$?
set -e
refused "$rc" "$work/voxel.log" "needs --baked" "--bake-voxel without --baked"
echo "check_eval_baked: ok"
