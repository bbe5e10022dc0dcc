#!/usr/bin/env bash
# Hostile input, reproduced: crafts every bad file and request it checks by itself,
# runs the executables on it and checks the exit code (2: a user error) and the one stderr line
# naming the file, key or value. Prints a Markdown table of the cases and their outcomes.
#
#   scripts/hostile.sh [APPS_DIR] [TINY_DATASET]     (default build/apps; a fresh tiny dataset)
#
# Needs the built executables and Debian's python3 with numpy, torch and opencv (the packages of
# scripts/install-deps.sh), which write the bad files. Also run by CTest (app_hostile_input).
# Exit status 0 when every case behaves. TH_HOSTILE_TABLE=FILE also writes the table there.
set -u
repo=$(cd "$(dirname "$0")/.." && pwd)
apps=$(cd "${1:-$repo/build/apps}" && pwd)
py=${TH_PYTHON:-/usr/bin/python3}
work=$(mktemp -d "${TMPDIR:-/tmp}/th-hostile.XXXXXX")
trap 'rm -rf "$work"' EXIT
cd "$repo"

if [[ -n ${2:-} ]]; then
  data=$(cd "$2" && pwd)
else
  data=$work/tiny
  "$apps/transhuman-synth" --config configs/synth/tiny.yaml --out "$data" >/dev/null 2>&1 ||
    { echo "hostile: cannot generate the tiny dataset"; exit 1; }
fi

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

tiny=(--config tests/configs/tiny_train.yaml model.grouping.cache_dir="$work/kmeans" train.val_views=0)
on() { echo "data.root=$1" "data.split_file=$1/split.yaml"; }
# A copy of the dataset to damage.
copy() {
  rm -rf "$work/$1"
  cp -r "$data" "$work/$1"
  echo "$work/$1"
}
person=CoreView_s03  # the identity setting's person (what eval, render and mesh use)

# The checkpoints the cases need: ours (two steps) and other models' ones.
"$apps/transhuman-train" "${tiny[@]}" $(on "$data") --out "$work/run" --max-steps 2 >/dev/null 2>&1 ||
  { echo "hostile: cannot train the tiny checkpoint"; exit 1; }
ckpt=$work/run/checkpoints/latest.pt
"$apps/transhuman-train" "${tiny[@]}" $(on "$data") --out "$work/deep" --max-steps 1 model.transhe.depth=2 >/dev/null 2>&1
"$apps/transhuman-train" "${tiny[@]}" $(on "$data") --out "$work/spc" --max-steps 1 \
  model.representation=spc_trilinear model.transhe.enabled=true >/dev/null 2>&1
# Evaluating the checkpoint (one image): append data.root=... and --out.
evaluate=("$apps/transhuman-eval" "${tiny[@]}" --checkpoint "$ckpt" eval.limit=1)

# ---- 1. numbers in data: finite where they are read ----------------------------------------------
d=$(copy nan_ref_R)
"$py" - "$d/$person/annots.npy" <<'EOF'
import sys, numpy as np
a = np.load(sys.argv[1], allow_pickle=True).item()
a['cams']['R'][0][0][0] = np.nan
np.save(sys.argv[1], a)
EOF
check "NaN in a reference camera's R (annots.npy)" 2 "cams['R'][0] holds nan" "${evaluate[@]}" $(on "$d") --out "$work/e1"
d=$(copy nan_target_T)
"$py" - "$d/$person/annots.npy" <<'EOF'
import sys, numpy as np
a = np.load(sys.argv[1], allow_pickle=True).item()
a['cams']['T'][3][1][0] = np.nan
np.save(sys.argv[1], a)
EOF
check "NaN in the target camera's T" 2 "cams['T'][3] holds nan" "${evaluate[@]}" $(on "$d") --out "$work/e2"
d=$(copy nan_vertices)
"$py" - "$d/$person/new_vertices" <<'EOF'
import sys, glob, numpy as np
for f in glob.glob(sys.argv[1] + '/*.npy'):
    v = np.load(f); v[5, 1] = np.nan; np.save(f, v)
EOF
check "NaN in new_vertices/*.npy" 2 "the vertices holds nan" "${evaluate[@]}" $(on "$d") --out "$work/e3"
d=$(copy nan_th)
"$py" - "$d/$person/new_params" <<'EOF'
import sys, glob, numpy as np
for f in glob.glob(sys.argv[1] + '/*.npy'):
    p = np.load(f, allow_pickle=True).item(); p['Th'][0][1] = np.nan; np.save(f, p)
EOF
check "NaN in new_params Th" 2 "'Th' holds nan" "${evaluate[@]}" $(on "$d") --out "$work/e4"
check "NaN in a camera, in training" 2 "cams['R'][0] holds nan" \
  "$apps/transhuman-train" "${tiny[@]}" $(on "$work/nan_ref_R") --out "$work/t_nan" --max-steps 1 \
  data.train_setting=identity

# ---- 2. run folders are never silently overwritten ------------------------------------------------
check "train into a folder holding a run" 2 "or --resume to continue the run" \
  "$apps/transhuman-train" "${tiny[@]}" $(on "$data") --out "$work/run" --max-steps 1
check "--resume with another model key" 2 "model.dparf.nk (run: 3, now: 1)" \
  "$apps/transhuman-train" "${tiny[@]}" $(on "$data") --out "$work/run" --resume model.dparf.nk=1
check "--resume with another seed" 2 "with other model, seed or data settings: seed (run: 42, now: 7)" \
  "$apps/transhuman-train" "${tiny[@]}" $(on "$data") --out "$work/run" --resume seed=7
cp -r "$work/run" "$work/run_badcfg" && echo "model: [unclosed" >"$work/run_badcfg/config.yaml"
check "--resume with a corrupt config.yaml" 2 "cannot resume in '$work/run_badcfg': its config.yaml cannot be read (" \
  "$apps/transhuman-train" "${tiny[@]}" $(on "$data") --out "$work/run_badcfg" --resume
"${evaluate[@]}" $(on "$data") --out "$work/e_used" >/dev/null 2>&1
check "eval into a folder holding results" 2 "--out '$work/e_used' already holds && : choose another folder, --force to replace its contents" "${evaluate[@]}" $(on "$data") --out "$work/e_used"

# ---- 3. checkpoints ------------------------------------------------------------------------------
"$py" - "$ckpt" "$work/cut.pt" <<'EOF'
import sys, zipfile
src, dst = sys.argv[1:3]
with zipfile.ZipFile(src) as z:
    members = [(i, z.read(i)) for i in z.infolist()]
big = max((m for m in members if '/data/' in m[0].filename), key=lambda m: len(m[1]))[0].filename
with zipfile.ZipFile(dst, 'w', zipfile.ZIP_STORED) as z:
    for info, data in members:
        z.writestr(info.filename, data[: len(data) // 2] if info.filename == big else data)
EOF
check "storage record truncated inside a valid zip" 2 "cut.pt/archive/data/ && elements of 4 bytes are claimed (a truncated or corrupt record)" \
  "$apps/transhuman-eval" "${tiny[@]}" $(on "$data") --checkpoint "$work/cut.pt" --out "$work/e_cut"
"$py" - "$ckpt" "$work/garbage_code.pt" <<'EOF'
import sys, zipfile
src, dst = sys.argv[1:3]
with zipfile.ZipFile(src) as z, zipfile.ZipFile(dst, 'w', zipfile.ZIP_STORED) as out:
    for i in z.infolist():
        out.writestr(i.filename, b'def (((garbage\x00\xff' if '/code/' in i.filename else z.read(i))
EOF
check "garbage code/ entry" 2 "checkpoint '$work/garbage_code.pt' cannot be read: Expected PROTO opcode" \
  "$apps/transhuman-eval" "${tiny[@]}" $(on "$data") --checkpoint "$work/garbage_code.pt" --out "$work/e_code"
"$py" - "$ckpt" "$work/deflated.pt" <<'EOF'
import sys, zipfile
src, dst = sys.argv[1:3]
with zipfile.ZipFile(src) as z, zipfile.ZipFile(dst, 'w', zipfile.ZIP_DEFLATED) as out:
    for i in z.infolist():
        out.writestr(i.filename, z.read(i))
EOF
check "deflated (repacked) checkpoint" 2 "compressed storage record" \
  "$apps/transhuman-eval" "${tiny[@]}" $(on "$data") --checkpoint "$work/deflated.pt" --out "$work/e_defl"
"$py" - "$work" <<'EOF'
import sys, zipfile, collections, torch
work = sys.argv[1]
# A 2 MB deflate bomb that claims 2.3 GB: a zip of one compressed member.
with zipfile.ZipFile(work + '/bomb.pth', 'w', zipfile.ZIP_DEFLATED) as z:
    with z.open('archive/data.pkl', 'w', force_zip64=True) as f:
        chunk = bytes(1 << 24)
        for _ in range(140):
            f.write(chunk)
class View:  # a tensor view that torch.save pickles as _rebuild_tensor_v2(storage, ...)
    def __init__(self, storage, offset, size, stride):
        self.args = (storage, offset, size, stride)
    def __reduce__(self):
        s, o, size, stride = self.args
        return (torch._utils._rebuild_tensor_v2, (s, o, size, stride, False, collections.OrderedDict()))
storage = torch.zeros(4).storage()
torch.save({'net': {'x': View(storage, 0, (1 << 30,), (0,))}}, work + '/stride0.pth')
torch.save({'net': {'x': View(storage, 3, (4,), (-1,))}}, work + '/negative.pth')
torch.save({'net': {'x': View(storage, 0, (100,), (1,))}}, work + '/past_end.pth')
EOF
check "deflate bomb (2 MB claiming 2.3 GB)" 2 "a compressed member claiming" \
  "$apps/transhuman-eval" "${tiny[@]}" $(on "$data") --checkpoint "$work/bomb.pth" --out "$work/e_bomb"
check "stride-0 view of 2^30 elements (.pth)" 2 "overlapping" \
  "$apps/transhuman-eval" "${tiny[@]}" $(on "$data") --checkpoint "$work/stride0.pth" --out "$work/e_s0"
check "negative stride (.pth)" 2 "negative" \
  "$apps/transhuman-eval" "${tiny[@]}" $(on "$data") --checkpoint "$work/negative.pth" --out "$work/e_neg"
check "view past its storage (.pth)" 2 "needs 100 elements" \
  "$apps/transhuman-eval" "${tiny[@]}" $(on "$data") --checkpoint "$work/past_end.pth" --out "$work/e_past"
check "checkpoint of transhe.depth=2" 2 "model.transhe.depth: checkpoint 2, config 1" \
  "$apps/transhuman-eval" "${tiny[@]}" $(on "$data") --checkpoint "$work/deep/checkpoints/latest.pt" --out "$work/e_deep"
check "checkpoint of another representation (spc)" 2 "model.representation: checkpoint spc_trilinear" \
  "$apps/transhuman-eval" "${tiny[@]}" $(on "$data") --checkpoint "$work/spc/checkpoints/latest.pt" --out "$work/e_spc"
for key in model.dparf.nk=2 model.grouping.num_tokens=20 model.dparf.coordinate=absolute model.fdi.raw_rgb=false; do
  check "evaluated with $key" 2 "${key%%=*}: checkpoint" \
    "$apps/transhuman-eval" "${tiny[@]}" $(on "$data") --checkpoint "$ckpt" --out "$work/e_${key//[.=]/_}" "$key"
done
check "evaluated with model.dparf.nk=2 and eval.model_mismatch=warn" 0 \
  "was trained with other model settings: model.dparf.nk: checkpoint 3, config 2" "$apps/transhuman-eval" "${tiny[@]}" $(on "$data") --checkpoint "$ckpt" --out "$work/e_warn" model.dparf.nk=2 \
  eval.model_mismatch=warn eval.limit=1

# ---- 4. resources are checked before work starts --------------------------------------------------
check "--threads 100000" 2 "--threads: must be in [0, 4096], not 100000" "$apps/transhuman-render" --threads 100000
check "threads: 100000 in the config" 2 "config key 'threads' = 100000: must be in [0, 4096] (CPU threads for LibTorch; 0: one per core)" \
  "$apps/transhuman-train" "${tiny[@]}" $(on "$data") --dry-run threads=100000
check "mesh --voxel 1e-4 (a 10^11-point grid)" 2 "estimated peak memory" \
  "$apps/transhuman-mesh" "${tiny[@]}" $(on "$data") --checkpoint "$ckpt" --out "$work/m1" --voxel 1e-4 max_memory_gb=4
check "render 20000 x 20000" 2 "render 20000 x 20000" \
  "$apps/transhuman-render" "${tiny[@]}" $(on "$data") --checkpoint "$ckpt" --out "$work/r1" --width 20000 \
  --height 20000 max_memory_gb=4
check "mesh --threshold nan" 2 "--threshold: must be >= 0, not nan" "$apps/transhuman-mesh" --threshold nan
check "mesh --threshold -1" 2 "--threshold: must be >= 0, not -1" "$apps/transhuman-mesh" --threshold -1

# ---- 5. disk full: tests/apps/check_disk_full.sh (a 1 MB tmpfs; needs root) ----------------------
if bash tests/apps/check_disk_full.sh "$apps" "$data" >"$work/disk_full.log" 2>&1; then
  rows+=("| disk full while writing a checkpoint (1 MB tmpfs) | 2 | 2 | - | $(grep -o 'last stderr line: .*' "$work/disk_full.log" | cut -c 19-240 | sed "s|$work|…|g") | ok |")
elif grep -q SKIP "$work/disk_full.log"; then
  rows+=("| disk full while writing a checkpoint | 2 | - | - | skipped: no tmpfs can be mounted (not root) | skip |")
else
  rows+=("| disk full while writing a checkpoint | 2 | ? | - | $(tail -1 "$work/disk_full.log") | FAIL |")
  failures=$((failures + 1))
fi

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

# ---- 7. images -----------------------------------------------------------------------------------
d=$(copy truncated_jpeg)
for f in "$d/$person"/Camera_B1/*.jpg; do head -c "$(($(stat -c %s "$f") / 2))" "$f" >"$f.cut" && mv "$f.cut" "$f"; done
check "truncated JPEG" 2 "is truncated" "${evaluate[@]}" $(on "$d") --out "$work/e_jpeg"
d=$(copy mask_sizes)
"$py" - "$d/$person/mask_cihp/Camera_B1" <<'EOF'
import sys, glob, cv2
for f in glob.glob(sys.argv[1] + '/*.png'):
    m = cv2.imread(f, cv2.IMREAD_UNCHANGED)
    cv2.imwrite(f, cv2.resize(m, (m.shape[1] // 2, m.shape[0] // 2), interpolation=cv2.INTER_NEAREST))
EOF
check "mask and mask_cihp of different sizes" 2 "mask_cihp/Camera_B1/000000.png' is 64x64 but '$d/$person/mask/Camera_B1/000000.png' is 128x128" "${evaluate[@]}" $(on "$d") --out "$work/e_mask"

# ---- 5. run folders: --force never removes an input; one writer per folder ------------------------
# kept NAME PATH...: every PATH is still on disk (a row of its own).
kept() {
  local name=$1 ok=ok missing=
  shift
  for p in "$@"; do [[ -e $p ]] || { ok=FAIL; missing+=" ${p//$work/…}"; }; done
  [[ $ok == ok ]] || failures=$((failures + 1))
  rows+=("| $name | - | - | - | ${missing:-all still there} | $ok |")
}
sum_of() { md5sum "$1" | cut -d' ' -f1; }
run_config=$(sum_of "$work/run/config.yaml")
check "eval --out <the checkpoint's run> --force" 2 \
  "--force would delete the checkpoint (--checkpoint) '$ckpt', an input of this command, which lies in --out '$work/run'" \
  "${evaluate[@]}" $(on "$data") --out "$work/run" --force
kept "  ... the run and its checkpoint" "$ckpt" "$work/run/config.yaml" "$work/run/metrics.jsonl"
d=$(copy force_data)
check "eval --out <the data root> --force" 2 "--force would delete the data root (data.root) '$d'" \
  "${evaluate[@]}" $(on "$d") --out "$d" --force
check "eval --out <a folder inside the data root> --force" 2 \
  "--force would delete part of the data root (data.root) '$d', an input of this command: --out '$d/$person' lies inside it" \
  "${evaluate[@]}" $(on "$d") --out "$d/$person" --force
kept "  ... the data" "$d/$person/annots.npy" "$d/split.yaml"
check "eval --config <run>/config.yaml --out <run> --force" 2 "--force would delete the config '$work/run/config.yaml'" \
  "$apps/transhuman-eval" --config "$work/run/config.yaml" model.grouping.cache_dir="$work/kmeans" $(on "$data") \
  --checkpoint "$ckpt" --out "$work/run" --force
check "render --out <a training run>" 2 "--out '$work/run' already holds && that this command does not write" \
  "$apps/transhuman-render" "${tiny[@]}" $(on "$data") --checkpoint "$ckpt" --out "$work/run" --orbit 2 --width 16 --height 16
check "mesh --out <a training run> (and a failing mesh)" 2 "that this command does not write: choose another folder, --force" \
  "$apps/transhuman-mesh" "${tiny[@]}" $(on "$data") --checkpoint "$ckpt" --out "$work/run" --threshold 1e9
if [[ $(sum_of "$work/run/config.yaml") == "$run_config" ]]; then ok=ok; else ok=FAIL; failures=$((failures + 1)); fi
rows+=("| ... the run's config.yaml unchanged | - | - | - | md5 $run_config | $ok |")
# A second writer while the first holds the folder's lock.
cp -r "$work/run" "$work/locked"
"$apps/transhuman-train" "${tiny[@]}" $(on "$data") --out "$work/locked" --resume train.epochs=1000 >/dev/null 2>&1 &
first=$!
for _ in $(seq 600); do grep -q "pid $first" "$work/locked/.lock" 2>/dev/null && break; sleep 0.1; done
check "a second train --resume on a folder in use" 2 "run folder '$work/locked' is in use by transhuman-train (pid $first on " \
  "$apps/transhuman-train" "${tiny[@]}" $(on "$data") --out "$work/locked" --resume train.epochs=1000
check "train --force on a folder in use" 2 "is in use by transhuman-train (pid $first on " \
  "$apps/transhuman-train" "${tiny[@]}" $(on "$data") --out "$work/locked" --force
kill "$first" 2>/dev/null; wait "$first" 2>/dev/null
kept "  ... the folder in use" "$work/locked/checkpoints/latest.pt" "$work/locked/config.yaml"
check_ok "train --resume once its writer has gone" \
  "$apps/transhuman-train" "${tiny[@]}" $(on "$data") --out "$work/locked" --resume --max-steps 1
# The killed writer logged steps after its last checkpoint: the resumed run logs each step once.
if "$py" - "$work/locked/metrics.jsonl" <<'EOF'; then ok=ok; else ok=FAIL; failures=$((failures + 1)); fi
import json, sys
rows = [json.loads(l) for l in open(sys.argv[1]) if l.strip()]
steps = [r['step'] for r in rows if 'loss' in r]
sys.exit(len(steps) != len(set(steps)))
EOF
rows+=("| ... metrics.jsonl holds each training step once after the resume | - | - | - | | $ok |")

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

# ---- 5a. calibration that cannot be right -----------------------------------------------------------
# annots D KIND: KIND metres (every T given in metres), focal (camera 0's fx = 0), singular (the
# target camera 3's K with last row 0), rotation (camera 0's R doubled).
annots() {
  "$py" - "$1/$person/annots.npy" "$2" <<'EOF'
import sys, numpy as np
a = np.load(sys.argv[1], allow_pickle=True).item()
c = a['cams']
if sys.argv[2] == 'metres':
    c['T'] = [np.asarray(t) / 1000.0 for t in c['T']]
elif sys.argv[2] == 'focal':
    c['K'][0] = np.array(c['K'][0], dtype=float); c['K'][0][0][0] = 0.0
elif sys.argv[2] == 'singular':
    c['K'][3] = np.array(c['K'][3], dtype=float); c['K'][3][2] = 0.0
else:
    c['R'][0] = np.array(c['R'][0], dtype=float) * 2
np.save(sys.argv[1], a)
EOF
}
d=$(copy calib_metres) && annots "$d" metres
check "T in metres, not millimetres" 2 "$d/$person/annots.npy': reference camera && (data.calibration_check: warn to go on anyway)" \
  "${evaluate[@]}" $(on "$d") --out "$work/e_metres"
check "... with data.calibration_check=warn" 0 "annots.npy': reference camera && (data.calibration_check: warn; going on)" \
  "${evaluate[@]}" $(on "$d") --out "$work/e_metres_warn" data.calibration_check=warn
d=$(copy calib_focal) && annots "$d" focal
check "a camera with focal length 0" 2 "$d/$person/annots.npy': camera 0: K has focal lengths fx = 0" \
  "${evaluate[@]}" $(on "$d") --out "$work/e_focal"
d=$(copy calib_singular) && annots "$d" singular
check "a singular K (the target camera's last row 0)" 2 "$d/$person/annots.npy': camera 3: K is not an intrinsic matrix (" \
  "${evaluate[@]}" $(on "$d") --out "$work/e_singular"
check "... also with data.calibration_check=warn" 2 "$d/$person/annots.npy': camera 3: K is not an intrinsic matrix (" \
  "${evaluate[@]}" $(on "$d") --out "$work/e_singular_warn" data.calibration_check=warn
d=$(copy calib_rotation) && annots "$d" rotation
check "a camera whose R is not a rotation" 2 "$d/$person/annots.npy': camera 0: R is not a rotation (" \
  "${evaluate[@]}" $(on "$d") --out "$work/e_rotation"

# ---- 5b. finite weights whose output overflows ----------------------------------------------------
"$py" - "$ckpt" "$work/huge.pt" <<'EOF'
import sys, torch
m = torch.jit.load(sys.argv[1])
with torch.no_grad():
    for name, p in m.named_parameters():
        if name.startswith('model.heads.') and p.dim() == 2:
            p.mul_(1e30)
m.save(sys.argv[2])
EOF
check "finite weights x1e30 (output overflows)" 2 \
  "checkpoint '$work/huge.pt', $person frame && the network's output is not finite (" \
  "$apps/transhuman-eval" "${tiny[@]}" $(on "$data") --checkpoint "$work/huge.pt" --out "$work/e_huge" eval.limit=1
check "render with them" 2 "checkpoint '$work/huge.pt', $person frame && : the network's output is not finite (" \
  "$apps/transhuman-render" "${tiny[@]}" $(on "$data") --checkpoint "$work/huge.pt" --out "$work/r_huge" --orbit 1 \
  --width 16 --height 16

# ---- 6. special files where a file is expected: refused by name, never read -----------------------
mkfifo "$work/fifo"
check "a FIFO as --config" 2 "config file '$work/fifo' is a FIFO (named pipe), not a file" \
  "$apps/transhuman-train" --dry-run --config "$work/fifo"
check "a FIFO as --checkpoint" 2 "checkpoint '$work/fifo' is a FIFO (named pipe), not a file" \
  "$apps/transhuman-eval" "${tiny[@]}" $(on "$data") --checkpoint "$work/fifo" --out "$work/e_fifo"
check "a FIFO as the split file" 2 "split file '$work/fifo' is a FIFO (named pipe), not a file" \
  "${evaluate[@]}" data.root="$data" data.split_file="$work/fifo" --out "$work/e_fifo_split"
check "a FIFO as --path (camera path)" 2 "camera path file '$work/fifo' is a FIFO (named pipe), not a file" \
  "$apps/transhuman-render" "${tiny[@]}" $(on "$data") --checkpoint "$ckpt" --out "$work/r_fifo" --path "$work/fifo"
check "/dev/zero as --checkpoint" 2 "checkpoint '/dev/zero' is a character device, not a file" \
  "$apps/transhuman-eval" "${tiny[@]}" $(on "$data") --checkpoint /dev/zero --out "$work/e_zero"
d=$(copy fifo_image)
img="$d/$person/Camera_B1/000000.jpg"
rm "$img" && mkfifo "$img"
check "a FIFO in place of an image" 2 "image '$img' is a FIFO (named pipe), not a file" \
  "${evaluate[@]}" $(on "$d") --out "$work/e_fifo_image"
d=$(copy fifo_annots)
rm "$d/$person/annots.npy" && mkfifo "$d/$person/annots.npy"
check "a FIFO in place of annots.npy" 2 "annotations '$d/$person/annots.npy' is a FIFO (named pipe), not a file" \
  "${evaluate[@]}" $(on "$d") --out "$work/e_fifo_annots"

# ---- 9. paths the system refuses, images too small, report inputs, dry runs that check all -------
ln -s loop "$work/loop"
check "a symlink loop in --out" 2 "'$work/loop/e': Too many levels of symbolic links" \
  "${evaluate[@]}" $(on "$data") --out "$work/loop/e"
check "a symlink loop in --checkpoint" 2 "cannot use '$work/loop/x.pt': Too many levels of symbolic links" \
  "$apps/transhuman-eval" "${tiny[@]}" $(on "$data") --checkpoint "$work/loop/x.pt" --out "$work/e_loop"
check "a symlink loop as data.root" 2 "cannot use '$work/loop/smpl_model.npz': Too many levels of symbolic links" \
  "${evaluate[@]}" $(on "$work/loop") --out "$work/e_loop_data"
long=$(printf 'x%.0s' $(seq 300))
check "an --out whose name is too long" 2 "$long' && File name too long" \
  "${evaluate[@]}" $(on "$data") --out "$work/$long"
d=$(copy one_pixel)
"$py" - "$d/$person/Camera_B1/000000.jpg" <<'EOF2'
import sys, numpy as np, cv2
cv2.imwrite(sys.argv[1], np.full((1, 1, 3), 128, np.uint8))
EOF2
check "a 1x1 image" 2 "image '$d/$person/Camera_B1/000000.jpg' is 1x1 pixels; at data.ratio" \
  "${evaluate[@]}" $(on "$d") --out "$work/e_one_pixel"
d=$(copy body_away)
"$py" - "$d" <<'EOF2'
import sys, glob, numpy as np
for f in glob.glob(sys.argv[1] + '/*/new_vertices/*.npy'):
    v = np.load(f); v[:, 0] += 50.0; np.save(f, v)
for f in glob.glob(sys.argv[1] + '/*/new_params/*.npy'):
    p = np.load(f, allow_pickle=True).item(); p['Th'] = np.asarray(p['Th']) + np.array([[50.0, 0, 0]]); np.save(f, p)
EOF2
check "training with the body out of every view (calibration_check=warn)" 2 "error: sample 'CoreView_ && , target view && : the body's box is outside the image, no training patch can be sampled" \
  "$apps/transhuman-train" "${tiny[@]}" $(on "$d") --out "$work/t_away" --max-steps 1 data.calibration_check=warn
check "data.patch.size larger than the image" 2 "config key 'data.patch.size' = 200: larger than the 32x32 target image of '" \
  "$apps/transhuman-train" "${tiny[@]}" $(on "$data") --out "$work/t_patch" --max-steps 1 data.patch.size=200
if [[ -e "$work/t_patch" ]]; then ok=FAIL; failures=$((failures + 1)); else ok=ok; fi
rows+=("| ... no run folder written (the first training sample is loaded before it) | - | - | - | | $ok |")
check "--dry-run with data.patch.size larger than the image" 2 "config key 'data.patch.size' = 200: larger than the" \
  "$apps/transhuman-train" "${tiny[@]}" $(on "$data") --dry-run data.patch.size=200
"${evaluate[@]}" $(on "$data") --out "$work/e_good" >/dev/null 2>&1 || echo "hostile: the tiny evaluation failed" >&2
cp -r "$work/e_good" "$work/e_badjson"
printf '{"setting": "identity", "psnr": 20.' >"$work/e_badjson/summary.json"
check "report of a cut-short summary.json" 2 "evaluation summary '$work/e_badjson/summary.json' is not JSON" \
  "$apps/transhuman-report" page --out "$work/rep_badjson" --eval "$work/e_badjson"
printf '{"setting": "identity", "images": 1, "psnr": NaN, "ssim": 0.5, "lpips": null}\n' >"$work/e_badjson/summary.json"
check "report of a summary.json with psnr NaN" 2 "'$work/e_badjson/summary.json': 'psnr' = 'NaN' is not a finite number (or null)" \
  "$apps/transhuman-report" page --out "$work/rep_badjson" --eval "$work/e_badjson"
: >"$work/e_badjson/summary.json"
check "report of an empty summary.json" 2 "evaluation summary '$work/e_badjson/summary.json' is not a JSON object" \
  "$apps/transhuman-report" page --out "$work/rep_badjson" --eval "$work/e_badjson"
cp -r "$work/e_good" "$work/e_other"
page_sum=$(sum_of "$work/e_other/index.html")
check "report --out <another evaluation's folder>" 2 "'$work/e_other' is another evaluation's folder" \
  "$apps/transhuman-report" page --out "$work/e_other" --eval "$work/e_good"
mkdir -p "$work/site" && echo '<html>my own page</html>' >"$work/site/index.html"
check "report --out <a folder with someone else's index.html>" 2 "'$work/site/index.html' exists and was not written by TransHuman" \
  "$apps/transhuman-report" page --out "$work/site" --eval "$work/e_good"
if [[ $(sum_of "$work/e_other/index.html") == "$page_sum" && $(cat "$work/site/index.html") == '<html>my own page</html>' ]]; then
  ok=ok; else ok=FAIL; failures=$((failures + 1)); fi
rows+=("| ... both pages unchanged | - | - | - | | $ok |")
check_ok "report of an evaluation into its own folder" \
  "$apps/transhuman-report" page --out "$work/e_good" --eval "$work/e_good"
# The online cores, as the executables count them (coreutils' nproc would follow OMP_NUM_THREADS).
many=$(($(getconf _NPROCESSORS_ONLN) * 8 + 1))
if ((many <= 1024)); then
  check "train --nproc $many (more than 8 ranks per core)" 2 "--nproc $many is more than 8 ranks per core (this machine has" \
    "$apps/transhuman-train" "${tiny[@]}" $(on "$data") --out "$work/t_nproc" --nproc "$many"
  check "eval --nproc $many (more than 8 ranks per core)" 2 "--nproc $many is more than 8 ranks per core (this machine has" \
    "${evaluate[@]}" $(on "$data") --out "$work/e_nproc" --nproc "$many"
fi
check "render --nproc 0" 2 "--nproc: must be in [1, 1024], not 0" \
  "$apps/transhuman-render" "${tiny[@]}" $(on "$data") --checkpoint "$ckpt" --out "$work/r_nproc" --nproc 0
check "train --nproc 100000" 2 "--nproc: must be in [1, 1024], not 100000" \
  "$apps/transhuman-train" "${tiny[@]}" $(on "$data") --out "$work/t_nproc" --nproc 100000
check "render --dry-run --human <nobody>" 2 "nobody" \
  "$apps/transhuman-render" "${tiny[@]}" $(on "$data") --checkpoint "$ckpt" --dry-run --human nobody
check "render --dry-run --camera 99" 2 "camera 99 out of range" \
  "$apps/transhuman-render" "${tiny[@]}" $(on "$data") --checkpoint "$ckpt" --dry-run --camera 99
check "render --dry-run --path <missing>" 2 "camera path file '$work/missing.yaml' does not exist" \
  "$apps/transhuman-render" "${tiny[@]}" $(on "$data") --checkpoint "$ckpt" --dry-run --path "$work/missing.yaml"
check "mesh --dry-run --view 99" 2 "camera 99 out of range" \
  "$apps/transhuman-mesh" "${tiny[@]}" $(on "$data") --checkpoint "$ckpt" --dry-run --view 99

# ---- 10. numbers are decimal, names are names, the helper programs run no shell -------------------
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
# absent NAME PATH: PATH was not made (a row of its own).
absent() {
  if [[ -e $2 ]]; then rows+=("| $1 | - | - | - | ${2//$work/…} exists | FAIL |"); failures=$((failures + 1))
  else rows+=("| $1 | - | - | - | not there | ok |"); fi
}
# rows_of CSV: the data rows of an evaluation's per_image.csv.
rows_of() { echo $(($(wc -l <"$1") - 1)); }
for how in "--limit 010" "eval.limit=010"; do
  "${evaluate[@]}" $(on "$data") --out "$work/e_limit" --force $how >/dev/null 2>&1
  n=$(rows_of "$work/e_limit/per_image.csv" 2>/dev/null || echo 0)
  if [[ $n == 10 ]]; then ok=ok; else ok=FAIL; failures=$((failures + 1)); fi
  rows+=("| eval $how: ten images, not octal eight | 0 | - | - | per_image.csv holds $n rows | $ok |")
done
check "render --dry-run --camera 0100 (decimal 100, not octal 64)" 2 "camera 100 out of range" \
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

# ---- links, parents and dry runs: what --force and the writers may touch ----------------------------
# unchanged NAME FILE SUM: FILE still holds what md5 SUM says.
unchanged() {
  if [[ -f $2 && $(sum_of "$2") == "$3" ]]; then rows+=("| $1 | - | - | - | unchanged | ok |")
  else rows+=("| $1 | - | - | - | ${2//$work/…} changed or gone | FAIL |"); failures=$((failures + 1)); fi
}
# The config's parent inside --out: every config file read is an input.
mkdir -p "$work/parented/cfg"
cp tests/configs/tiny_train.yaml "$work/parented/cfg/base.yaml"
sed -i "s|parent: ../../configs/default.yaml|parent: $repo/configs/default.yaml|" "$work/parented/cfg/base.yaml"
printf 'parent: parented/cfg/base.yaml\n' >"$work/child.yaml"
echo keep >"$work/parented/results.md"
check "--force with the config's parent inside --out" 2 \
  "--force would delete the config's parent (child.yaml) '$work/parented/cfg/base.yaml'" \
  "$apps/transhuman-train" --config "$work/child.yaml" $(on "$data") model.grouping.cache_dir="$work/kmeans" \
  --out "$work/parented" --force --max-steps 0
kept "  ... the parent config and the folder" "$work/parented/cfg/base.yaml" "$work/parented/results.md"
# Inputs reached through a link inside --out: compared as given, not only resolved.
mkdir -p "$work/linked"
ln -s "$data" "$work/linked/data"
check "--force with data.root reached through a link inside --out" 2 \
  "--force would delete the data root (data.root) '$work/linked/data'" \
  "$apps/transhuman-train" "${tiny[@]}" $(on "$work/linked/data") --out "$work/linked" --force --max-steps 0
kept "  ... the link" "$work/linked/data"
ln -s "$ckpt" "$work/linked/ckpt.pt"
check "--force with --checkpoint reached through a link inside --out" 2 \
  "--force would delete the checkpoint (--checkpoint) '$work/linked/ckpt.pt'" \
  "$apps/transhuman-eval" "${tiny[@]}" $(on "$data") --checkpoint "$work/linked/ckpt.pt" --out "$work/linked" --force
# A dry run writes nothing, --force or not.
mkdir -p "$work/dry" && echo keep >"$work/dry/results.md"
for app in train eval; do
  check_out "$app --dry-run --force --out <a folder>" "dry run: --out '$work/dry' is not touched" \
    "$apps/transhuman-$app" "${tiny[@]}" $(on "$data") --dry-run --force --out "$work/dry"
done
kept "  ... the folder's file" "$work/dry/results.md"
absent "  ... no lock or config written" "$work/dry/config.yaml"
absent "  ... no lock file" "$work/dry/.lock"
check_out "render --dry-run --out <a new folder>" "dry run: --out '$work/dry_render' is not touched" \
  "$apps/transhuman-render" "${tiny[@]}" $(on "$data") --checkpoint "$ckpt" --dry-run --out "$work/dry_render"
absent "  ... the folder not made" "$work/dry_render"
# The run lock is created without following links; a link in its place is refused.
echo secret >"$work/outside.txt"
outside=$(sum_of "$work/outside.txt")
mkdir -p "$work/symlock" "$work/hardlock"
ln -s "$work/outside.txt" "$work/symlock/.lock"
check "a .lock that is a symbolic link" 2 "the run folder's lock file '$work/symlock/.lock' is a symbolic link" \
  "$apps/transhuman-train" "${tiny[@]}" $(on "$data") --out "$work/symlock" --max-steps 0
ln "$work/outside.txt" "$work/hardlock/.lock"
check "a .lock that is a hard link" 2 "the run folder's lock file '$work/hardlock/.lock' is a hard link to another file" \
  "$apps/transhuman-train" "${tiny[@]}" $(on "$data") --out "$work/hardlock" --max-steps 0
unchanged "  ... the linked file" "$work/outside.txt" "$outside"
# Outputs are never written through a link the command did not make: the video and the files
# written through a temporary file are renamed over the name, replacing a planted link.
mkdir -p "$work/orbit_linked"
ln -s "$work/outside.txt" "$work/orbit_linked/video.mp4"
ln -s "$work/outside.txt" "$work/orbit_linked/config.yaml"
check "render --out <a folder of its outputs, video.mp4 and config.yaml links>" 2 \
  "orbit_linked' holds ' && a symbolic link this command did not make" \
  "$apps/transhuman-render" "${tiny[@]}" $(on "$data") --checkpoint "$ckpt" --out "$work/orbit_linked" \
  --orbit 2 --width 16 --height 16
mkdir -p "$work/run_linked" && cp -r "$work/run/." "$work/run_linked/" && rm -f "$work/run_linked/.lock"
ln -sf "$work/outside.txt" "$work/run_linked/metrics.jsonl"
check "train --resume in a run whose metrics.jsonl is a link" 2 "holds 'metrics.jsonl', a symbolic link" \
  "$apps/transhuman-train" "${tiny[@]}" $(on "$data") --out "$work/run_linked" --resume
unchanged "  ... the file the links pointed at" "$work/outside.txt" "$outside"

# ---- report folders, render requests and failing ranks ---------------------------------------------
# Names derived from --eval paths: normalised (trailing separator, ".."), unique, inside --out.
cp -r "$work/run" "$work/rep_run" && rm -f "$work/rep_run/.lock"
run_cfg=$(sum_of "$work/rep_run/config.yaml")
check_ok "report --eval <folder>/ --out <a training run>" \
  "$apps/transhuman-report" page --out "$work/rep_run" --eval "$work/e_good/"
unchanged "  ... the run's config.yaml (the copy went to rep_run/e_good/)" "$work/rep_run/config.yaml" "$run_cfg"
kept "  ... the evaluation's copy in its own folder" "$work/rep_run/e_good/config.yaml" "$work/rep_run/e_good/summary.json"
mkdir -p "$work/twin_a" "$work/twin_b"
cp -r "$work/e_good" "$work/twin_a/e" && cp -r "$work/e_good" "$work/twin_b/e"
"$py" -c "import sys, numpy as np, cv2; cv2.imwrite(sys.argv[1], np.zeros((8, 8, 3), np.uint8))" \
  "$(ls "$work/twin_b/e/images/"*.png | head -1)"
check_ok "report with two --eval folders of the same name" \
  "$apps/transhuman-report" page --out "$work/rep_twins" --eval "$work/twin_a/e" --eval "$work/twin_b/e"
panel=$(basename "$(ls "$work/twin_a/e/images/"*.png | head -1)")
unchanged "  ... e/ holds the first one's panel" "$work/rep_twins/e/images/$panel" "$(sum_of "$work/twin_a/e/images/$panel")"
unchanged "  ... e-2/ holds the second one's" "$work/rep_twins/e-2/images/$panel" "$(sum_of "$work/twin_b/e/images/$panel")"
mkdir -p "$work/dotdot"
check_ok "report --eval <folder>/images/.. --out <a new folder>" \
  "$apps/transhuman-report" page --out "$work/dotdot/page" --eval "$work/e_good/images/.."
if [[ $(ls -A "$work/dotdot") == page && -f $work/dotdot/page/e_good/summary.json ]]; then ok=ok; else ok=FAIL; failures=$((failures + 1)); fi
rows+=("| ... nothing beside --out; the copy in page/e_good/ | - | - | - | $(ls -A "$work/dotdot" | tr '\n' ' ') | $ok |")
mkdir -p "$work/rep_link" "$work/rep_outside" && echo keep >"$work/rep_outside/summary.json"
ln -s "$work/rep_outside" "$work/rep_link/e_good"
check "report --out <a folder whose e_good/ is a link out of it>" 2 "'$work/rep_link/e_good' in --out is a symbolic link" \
  "$apps/transhuman-report" page --out "$work/rep_link" --eval "$work/e_good"
unchanged "  ... the folder the link points at" "$work/rep_outside/summary.json" "$(echo keep | md5sum | cut -d' ' -f1)"
# A running evaluation holds its folder: the report neither writes there nor reads it half-done.
"${evaluate[@]}" $(on "$data") --out "$work/e_running" eval.limit=0 render.samples=2048 render.progressive=false \
  >/dev/null 2>&1 &
evaluating=$!
for _ in $(seq 600); do grep -q "pid $evaluating" "$work/e_running/.lock" 2>/dev/null && break; sleep 0.1; done
check "report --out <the folder of a running evaluation>" 2 "run folder '$work/e_running' is in use by transhuman-eval (pid $evaluating on " \
  "$apps/transhuman-report" page --out "$work/e_running" --eval "$work/e_good"
check "report --eval <the folder of a running evaluation>" 2 "evaluation folder (--eval) '$work/e_running' is in use by transhuman-eval (pid $evaluating" \
  "$apps/transhuman-report" page --out "$work/rep_running" --eval "$work/e_running"
absent "  ... no page written into it" "$work/e_running/report.js"
kill "$evaluating" 2>/dev/null; wait "$evaluating" 2>/dev/null

# A render resumes only the frames of the same request, every setting that changes pixels included.
render_into=("$apps/transhuman-render" "${tiny[@]}" $(on "$data") --checkpoint "$ckpt" --orbit 3 --width 16 --height 16
             --out)
orbit=("${render_into[@]}" "$work/r_settings")
"${orbit[@]}" >/dev/null 2>&1
frames_sum=$(cat "$work/r_settings/frames/"*.png | md5sum | cut -d' ' -f1)
check "render --precision bf16 over fp32 frames" 2 "holds frames of another request: precision (frames: fp32" "${orbit[@]}" --precision bf16
check "render render.samples=64 over frames of 8 samples" 2 "holds frames of another request: render.samples (frames: 8, now: 64)" \
  "${orbit[@]}" render.samples=64
check "render render.progressive=false over progressive frames" 2 "render.progressive (frames: true, now: false)" \
  "${orbit[@]}" render.progressive=false
check "render --setting pose over identity frames" 2 "eval.setting (frames: identity, now: pose)" "${orbit[@]}" --setting pose
if [[ $(cat "$work/r_settings/frames/"*.png | md5sum | cut -d' ' -f1) == "$frames_sum" ]]; then ok=ok; else ok=FAIL; failures=$((failures + 1)); fi
rows+=("| ... the frames unchanged | - | - | - | md5 $frames_sum | $ok |")
check_out "render threads=2 (no pixel changes): resumed" "3 frames (0 rendered, 3 resumed)" "${orbit[@]}" threads=2
check_out "render render.samples=64 --force: rendered again" "3 frames (3 rendered, 0 resumed)" "${orbit[@]}" render.samples=64 --force
cp -r "$work/r_settings" "$work/r_unknown" && rm "$work/r_unknown/request.yaml"
check "render into frames/ without request.yaml" 2 "holds frames/ without the request.yaml that says what made them" \
  "${render_into[@]}" "$work/r_unknown"

# A user error only rank 0 sees ends every --nproc rank at once, its own line last (the others
# would wait train.dist_timeout_s = 300 s at the rendezvous).
t0=$(date +%s)
check "train --nproc 2 --out <a training run> (only rank 0 claims --out)" 2 \
  "transhuman-train[rank 0]: error: --out '$work/run' already holds" \
  "$apps/transhuman-train" "${tiny[@]}" $(on "$data") --out "$work/run" --nproc 2
secs=$(($(date +%s) - t0))
if ((secs < 30)); then ok=ok; else ok=FAIL; failures=$((failures + 1)); fi
rows+=("| ... ended in $secs s, not train.dist_timeout_s (300 s) | - | - | - | | $ok |")
check "eval --nproc 2 --out <a folder holding results>" 2 "transhuman-eval[rank 0]: error: --out '$work/e_used' already holds" \
  "${evaluate[@]}" $(on "$data") --out "$work/e_used" --nproc 2
check "render --nproc 2 over another request's frames (after the rendezvous)" 2 \
  "transhuman-render[rank 0]: error: '$work/r_settings' holds frames of another request: render.samples (frames: 64, now: 8)" \
  "${orbit[@]}" --nproc 2
check "train --nproc 2 with a data.root every rank misses" 2 "[rank " \
  "$apps/transhuman-train" "${tiny[@]}" data.root="$work/nowhere" data.split_file="$data/split.yaml" --out "$work/t_nowhere" --nproc 2

table=$(
  echo "| case | expected exit | exit | seconds | last stderr line | |"
  echo "|---|---|---|---|---|---|"
  printf '%s\n' "${rows[@]}"
)
echo "$table"
[[ -n ${TH_HOSTILE_TABLE:-} ]] && echo "$table" >"$TH_HOSTILE_TABLE"
echo
echo "hostile: ${#rows[@]} cases, $failures failed"
exit $((failures > 0))
