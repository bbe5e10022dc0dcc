#!/usr/bin/env bash
# Trains and evaluates rows of the paper's ablation tables (configs/ablations/*.yaml) at the
# same budget and writes one markdown table.
#
#   scripts/run_ablations.sh [-o OUT] [-s SETTING] ROW... [-- KEY=VALUE...]
#
#   ROW       file names in configs/ablations without .yaml (full, fdi_wo_h, fdi_wo_a, nk_3, ...),
#             or `all`
#   -o OUT    output folder (default runs/ablations): OUT/<row>/ is each run, OUT/ablations.md
#             the table, OUT/index.html the page (rows side by side, paired against full)
#   -s SETTING evaluation setting (default identity: the unseen people)
#   KEY=VALUE overrides applied to every row (e.g. train.epochs=4 for a quick look)
#
# A row whose evaluation already exists is not run again (delete OUT/<row> to redo it); a row
# whose training was interrupted resumes from its last checkpoint. Builds the apps first.
set -euo pipefail
cd "$(dirname "$0")/.."
out=runs/ablations
setting=identity
rows=()
overrides=()
while [[ $# -gt 0 ]]; do
  case "$1" in
    -o) out=$2; shift 2 ;;
    -s) setting=$2; shift 2 ;;
    -h|--help) sed -n '2,16p' "$0"; exit 0 ;;
    --) shift; overrides=("$@"); break ;;
    *) rows+=("$1"); shift ;;
  esac
done
if [[ ${#rows[@]} -eq 0 ]]; then
  echo "run_ablations.sh: name at least one row (or all); rows:" $(ls configs/ablations | grep -v '^_' | sed 's/\.yaml$//') >&2
  exit 2
fi
if [[ "${rows[*]}" == all ]]; then
  mapfile -t rows < <(ls configs/ablations | grep -v '^_' | sed 's/\.yaml$//')
fi
for row in "${rows[@]}"; do
  [[ -f configs/ablations/$row.yaml ]] || { echo "run_ablations.sh: no configs/ablations/$row.yaml" >&2; exit 2; }
done

[[ -n "${TH_SKIP_BUILD:-}" ]] || bash scripts/build.sh transhuman-train transhuman-eval transhuman-report
bin=build/apps
mkdir -p "$out"

# One value of the evaluator's one-line summary.json.
field() { sed -n "s/.*\"$2\": *\([^,}]*\).*/\1/p" "$1" | tr -d '"'; }

for row in "${rows[@]}"; do
  run=$out/$row
  summary=$run/eval_$setting/summary.json
  if [[ -f $summary ]]; then echo "== $row: evaluated already ($summary)"; continue; fi
  echo "== $row"
  start=$SECONDS
  if [[ -f $run/checkpoints/latest.pt && ! -f $run/train_done ]]; then
    "$bin/transhuman-train" --config "configs/ablations/$row.yaml" --out "$run" --resume "${overrides[@]}"
  elif [[ ! -f $run/train_done ]]; then
    "$bin/transhuman-train" --config "configs/ablations/$row.yaml" --out "$run" --force "${overrides[@]}"
  fi
  echo $((SECONDS - start)) > "$run/train_done"
  "$bin/transhuman-eval" --config "configs/ablations/$row.yaml" --checkpoint "$run/checkpoints/latest.pt" \
    --out "$run/eval_$setting" --setting "$setting" --force "${overrides[@]}"
done

# The table, in the paper's format (one row per configuration, PSNR / SSIM / LPIPS).
table=$out/ablations.md
{
  echo "Ablations, setting '$setting', $(date -u +%F)${overrides[*]:+, overrides: ${overrides[*]}}"
  echo
  echo "| Row | What changes | PSNR ↑ | SSIM ↑ | LPIPS ↓ | train time |"
  echo "|---|---|---|---|---|---|"
  for row in "${rows[@]}"; do
    s=$out/$row/eval_$setting/summary.json
    what=$(sed -n '1s/^# *//p' "configs/ablations/$row.yaml")
    lp=$(field "$s" lpips)
    [[ $(field "$s" lpips_available) == yes ]] || lp="n/a"
    printf '| %s | %s | %.2f | %.3f | %s | %s min |\n' "$row" "$what" "$(field "$s" psnr)" "$(field "$s" ssim)" \
      "$lp" "$(( $(cat "$out/$row/train_done") / 60 ))"
  done
} > "$table"
"$bin/transhuman-report" ablations --root "$out" --setting "$setting" "${rows[@]}" >/dev/null
echo
cat "$table"
echo "Table: $table; page: $out/index.html"
