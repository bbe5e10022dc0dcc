# Sourced by scripts/hostile.sh: what every group of cases uses. A group file (scripts/hostile/
# <group>.sh) sees $apps, $data (the tiny dataset), $work (a folder of its own), $repo, $py, $ckpt
# (a two-step tiny checkpoint in $work/run), $kmeans, $person, the arrays tiny and evaluate, and
# the functions below; it appends table rows to `rows` and counts failures in `failures`.

rows=() failures=0
# holds LINE FRAGMENTS: LINE holds every part of FRAGMENTS, parts separated by " && ".
holds() {
  local line=$1 rest=$2 part
  while [[ -n $rest ]]; do
    part=${rest%% && *}
    [[ $line == *"$part"* ]] || return 1
    [[ $rest == *" && "* ]] && rest=${rest#* && } || rest=
  done
}
# check NAME CODE FRAGMENTS COMMAND...: the exit code, and for a failure the last stderr line
# "<app>: error: ..." holding FRAGMENTS (see holds), with no other error line (the log above it
# is fine), no internal error and no crash, within 120 s. For success (code 0) with FRAGMENTS,
# a "warning" line of stderr holds them.
check() {
  local name=$1 code=$2 fragment=$3
  shift 3
  local t0 err rc errors last ok=ok
  t0=$(date +%s%N)
  err=$(timeout 120 "$@" 2>&1 >/dev/null)
  rc=$?
  local ms=$((($(date +%s%N) - t0) / 1000000))
  local secs=$((ms / 1000)).$((ms % 1000 / 100))
  errors=$(printf '%s\n' "$err" | grep -c -E ': error:|internal error|terminate called|Segmentation|Aborted|AddressSanitizer')
  last=$(printf '%s\n' "$err" | grep . | tail -1)
  if [[ $rc -ne $code ]]; then
    ok=FAIL
  elif [[ $code -ne 0 ]] && { [[ $errors -ne 1 || "$last" != *": error: "* ]] || ! holds "$last" "$fragment"; }; then
    ok=FAIL
  elif [[ $code -eq 0 && -n $fragment ]]; then
    last=$(printf '%s\n' "$err" | grep ' warning ' | while IFS= read -r l; do holds "$l" "$fragment" && { echo "$l"; break; }; done)
    [[ -n $last ]] || ok=FAIL
  fi
  [[ $ok == ok ]] || failures=$((failures + 1))
  last=${last//$work/…}
  last=${last//|/\\|}
  ((${#last} > 240)) && last="${last:0:237}..."
  rows+=("| $name | $code | $rc | $secs | $last | $ok |")
  [[ $ok == ok ]] || echo "FAIL: $name: exit $rc (expected $code), $errors error line(s): $last" >&2
}
# check_ok NAME COMMAND...: must succeed (exit 0).
check_ok() {
  local name=$1
  shift
  check "$name" 0 "" "$@"
}
# check_out NAME FRAGMENT COMMAND...: succeeds, and a line of its output (stdout or stderr) holds
# FRAGMENT.
check_out() {
  local name=$1 fragment=$2 out rc line ok=ok
  shift 2
  out=$(timeout 120 "$@" 2>&1)
  rc=$?
  line=$(printf '%s\n' "$out" | grep -F -- "$fragment" | tail -1)
  [[ $rc -eq 0 && -n $line ]] || { ok=FAIL; failures=$((failures + 1)); echo "FAIL: $name: exit $rc" >&2; }
  line=${line//$work/…}
  rows+=("| $name | 0 | $rc | - | ${line//|/\\|} | $ok |")
}
# verdict NAME DETAIL STATUS: a row for a condition the group tested itself (STATUS: 0 holds).
verdict() {
  local ok=ok
  [[ $3 -eq 0 ]] || { ok=FAIL; failures=$((failures + 1)); echo "FAIL: $1: $2" >&2; }
  rows+=("| $1 | - | - | - | ${2//$work/…} | $ok |")
}
# kept NAME PATH...: every PATH is still on disk (a row of its own).
kept() {
  local name=$1 ok=ok missing=
  shift
  for p in "$@"; do [[ -e $p ]] || { ok=FAIL; missing+=" ${p//$work/…}"; }; done
  [[ $ok == ok ]] || failures=$((failures + 1))
  rows+=("| $name | - | - | - | ${missing:-all still there} | $ok |")
}
# absent NAME PATH: PATH was not made (a row of its own).
absent() {
  if [[ -e $2 ]]; then rows+=("| $1 | - | - | - | ${2//$work/…} exists | FAIL |"); failures=$((failures + 1))
  else rows+=("| $1 | - | - | - | not there | ok |"); fi
}
sum_of() { md5sum "$1" | cut -d' ' -f1; }
# unchanged NAME FILE SUM: FILE still holds what md5 SUM says.
unchanged() {
  if [[ -f $2 && $(sum_of "$2") == "$3" ]]; then rows+=("| $1 | - | - | - | unchanged | ok |")
  else rows+=("| $1 | - | - | - | ${2//$work/…} changed or gone | FAIL |"); failures=$((failures + 1)); fi
}
# rows_of CSV: the data rows of an evaluation's per_image.csv.
rows_of() { echo $(($(wc -l <"$1") - 1)); }

# The k-means labels are shared by every group (the runs were trained with them; resuming compares
# the key), written atomically.
kmeans=$runs/kmeans
tiny=(--config tests/configs/tiny_train.yaml model.grouping.cache_dir="$kmeans" train.val_views=0)
on() { echo "data.root=$1" "data.split_file=$1/split.yaml"; }
# copy NAME: a copy of the dataset to damage; prints its path.
copy() {
  rm -rf "$work/$1"
  cp -r "$data" "$work/$1"
  echo "$work/$1"
}
person=CoreView_s03  # the identity setting's person (what eval, render and mesh use)
ckpt=$work/run/checkpoints/latest.pt
# Evaluating the checkpoint (one image): append data.root=... and --out.
evaluate=("$apps/transhuman-eval" "${tiny[@]}" --checkpoint "$ckpt" eval.limit=1)
