#!/usr/bin/env bash
# Trains and evaluates ablation rows (configs/ablations/*.yaml: the paper's rows and this
# project's, docs/ABLATIONS.md) at the same budget and writes one markdown table.
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
# wo_perceptual needs LPIPS weights (train.lpips_weights, made by scripts/export_lpips.py):
# without them the perceptual term is off in every row and it would train full again, so a
# request naming it is refused (exit 2) and `all` skips it, saying so.
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
    -h|--help) sed -n '2,18p' "$0"; exit 0 ;;
    --) shift; overrides=("$@"); break ;;
    *) rows+=("$1"); shift ;;
  esac
done
if [[ ${#rows[@]} -eq 0 ]]; then
  echo "run_ablations.sh: name at least one row (or all); rows:" $(ls configs/ablations | grep -v '^_' | sed 's/\.yaml$//') >&2
  exit 2
fi
all=0
if [[ "${rows[*]}" == all ]]; then
  all=1
  mapfile -t rows < <(ls configs/ablations | grep -v '^_' | sed 's/\.yaml$//')
fi

# The train.lpips_weights a row trains with: the last KEY=VALUE override naming it, else the
# first file of the row's parent chain that sets it (a config overrides its parent).
lpips_weights_of() {  # ROW
  local o value="" named=0 file=configs/ablations/$1.yaml line parent
  for o in "${overrides[@]}"; do
    if [[ $o == train.lpips_weights=* ]]; then value=${o#train.lpips_weights=}; named=1; fi
  done
  if ((named)); then printf '%s' "${value//[\"\']/}"; return; fi
  while [[ -f $file ]]; do
    if line=$(awk '/^[^ #]/ {section = $1}
                   section == "train:" && /^  lpips_weights:/ {
                     sub(/^  lpips_weights: */, ""); sub(/ *#.*/, ""); gsub(/["\047]/, ""); print; found = 1; exit }
                   END { exit !found }' "$file"); then
      printf '%s' "$line"
      return
    fi
    parent=$(sed -n 's/^parent: *//p' "$file" | sed 's/ *#.*//; s/["'\'']//g')
    [[ -n $parent ]] || return 0
    file=$(dirname "$file")/$parent
  done
}

kept=()
for row in "${rows[@]}"; do
  [[ -f configs/ablations/$row.yaml ]] || { echo "run_ablations.sh: no configs/ablations/$row.yaml" >&2; exit 2; }
  if [[ $row == wo_perceptual && -z $(lpips_weights_of "$row") ]]; then
    why="no LPIPS weights are configured (train.lpips_weights is empty), so the perceptual term is off in every row and wo_perceptual would train the same model as full. Make the weights once with scripts/export_lpips.py (python3 scripts/export_lpips.py --vgg VGG16.pth --lin LPIPS_VGG_V0.1.pth --out weights/lpips_vgg.npz; docs/USAGE.md, Weight files) and pass -- train.lpips_weights=weights/lpips_vgg.npz (or set it in configs/ablations/_base.yaml)"
    if ((all)); then
      echo "!!! run_ablations.sh: SKIPPING row wo_perceptual: $why" >&2
      continue
    fi
    echo "run_ablations.sh: refusing row wo_perceptual: $why" >&2
    exit 2
  fi
  kept+=("$row")
done
rows=("${kept[@]}")

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
