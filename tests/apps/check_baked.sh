#!/usr/bin/env bash
# transhuman-render --baked (METHOD 7.1) on the trained tiny checkpoint: a baked orbit is written,
# its bake saved with --bake-out; --bake-in of that file renders the same frames byte for byte
# without baking; request.yaml records the bake (its voxel, or the file and its digest); the
# exact orbit's request is not resumed by a baked one (request.yaml differs);
# a damaged bake file, or one naming another checkpoint, is refused with exit 2 naming it.
#
#   tests/apps/check_baked.sh APPS_DIR TINY_DATASET CHECKPOINT
set -euo pipefail
apps=$1 data=$2 ckpt=$3
repo=$(cd "$(dirname "$0")/../.." && pwd)
work=$(mktemp -d "${TMPDIR:-/tmp}/th-baked.XXXXXX")
trap 'rm -rf "$work"' EXIT
cd "$repo"
common=(--config tests/configs/tiny_surface.yaml --checkpoint "$ckpt" --threads 1 --orbit 4
        "data.root=$data" "data.split_file=$data/split.yaml" "model.grouping.cache_dir=$work/kmeans")
render="$apps/transhuman-render"
fail() { echo "check_baked: FAIL: $*" >&2; exit 1; }

"$render" "${common[@]}" --baked --bake-voxel 0.04 --bake-out "$work/frame.thbake" --out "$work/a" > "$work/a.log" 2>&1 ||
  { cat "$work/a.log"; fail "render --baked --bake-out"; }
grep -q "bake: .* frame .* in .* s" "$work/a.log" || fail "the bake's time is not logged"
[[ -s "$work/frame.thbake" ]] || fail "--bake-out wrote nothing"
grep -q "renderer: baked" "$work/a/request.yaml" || fail "request.yaml does not record the baked renderer"
grep -q "bake.voxel: 0.04" "$work/a/request.yaml" || fail "request.yaml does not record the bake's voxel"
"$render" "${common[@]}" --bake-in "$work/frame.thbake" --bake-voxel 0.04 --out "$work/b" > "$work/b.log" 2>&1 ||
  { cat "$work/b.log"; fail "render --bake-in"; }
if grep -q "bake: .* frame .* in .* s" "$work/b.log"; then fail "--bake-in baked again"; fi
grep -q "bake.source: $work/frame.thbake" "$work/b/request.yaml" || fail "request.yaml does not record the bake file"
grep -q "bake.file: .* bytes, FNV-1a 64 " "$work/b/request.yaml" || fail "request.yaml does not record the bake file's digest"
for f in "$work/a/frames/"*.png; do cmp "$f" "$work/b/frames/$(basename "$f")" || fail "frame $(basename "$f") differs"; done
echo "baked orbit: $(ls "$work/a/frames" | wc -l) frames identical from the bake and from its file ($(stat -c %s "$work/frame.thbake") bytes)"

# The exact renderer does not resume the baked frames: another request.
set +e
"$render" "${common[@]}" --out "$work/a" > "$work/c.log" 2>&1; rc=$?
set -e
[[ $rc -eq 2 ]] && grep -q "renderer" "$work/c.log" || { cat "$work/c.log"; fail "exact render over baked frames: exit $rc"; }

# Damaged or foreign bakes.
head -c 100 "$work/frame.thbake" > "$work/short.thbake"
set +e
"$render" "${common[@]}" --bake-in "$work/short.thbake" --out "$work/d" > "$work/d.log" 2>&1; rc=$?
set -e
[[ $rc -eq 2 ]] && grep -q "short.thbake" "$work/d.log" || { cat "$work/d.log"; fail "truncated bake: exit $rc"; }
python3 - "$work/frame.thbake" "$work/foreign.thbake" <<'PY'
import json, struct, sys
b = open(sys.argv[1], 'rb').read()
n = struct.unpack('<I', b[12:16])[0]
h = json.loads(b[16:16 + n])
h['checkpoint'] = 'another.pt (1 bytes, modified 0)'
t = json.dumps(h).encode()
open(sys.argv[2], 'wb').write(b[:12] + struct.pack('<I', len(t)) + t + b[16 + n:])
PY
set +e
"$render" "${common[@]}" --bake-in "$work/foreign.thbake" --out "$work/e" > "$work/e.log" 2>&1; rc=$?
set -e
[[ $rc -eq 2 ]] && grep -q "another.pt" "$work/e.log" || { cat "$work/e.log"; fail "foreign bake: exit $rc"; }
echo "check_baked: ok"
