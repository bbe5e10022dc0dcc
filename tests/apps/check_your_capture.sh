#!/usr/bin/env bash
# Runs the commands of docs/YOUR_CAPTURE.md on a synthetic capture in EasyMocap's layout, so the
# document cannot rot. Its fenced ```sh blocks marked `<!-- run -->` are run in order, the one
# marked `<!-- run: server -->` in the background until its page answers, with the document's
# `<!-- settings -->` block replaced by this capture, the tiny checkpoint and its config.
#
#   tests/apps/check_your_capture.sh APPS_DIR EASYMOCAP_DATASET CHECKPOINT PYTHON
set -euo pipefail
apps=$(cd "$1" && pwd) easymocap=$(cd "$2" && pwd) ckpt=$(realpath "$3") python=$4
repo=$(cd "$(dirname "$0")/../.." && pwd)
work=$(mktemp -d "${TMPDIR:-/tmp}/th-capture.XXXXXX")
server=""
# The viewer runs in its own process group ($server is its leader), stopped as a whole.
trap '[[ -n $server ]] && kill -- "-$server" 2>/dev/null; rm -rf "$work"' EXIT
fail() { echo "check_your_capture: FAIL: $*" >&2; exit 1; }

# The capture: one person of the synthetic dataset, as a user's folder would hold it.
mkdir -p "$work/data/capture"
cp -r "$easymocap/CoreView_s03" "$work/data/capture/me"
ln -s "$repo/configs" "$work/configs"
ln -s "$repo/tests" "$work/tests"
cat > "$work/settings.sh" <<SETTINGS
capture=$work/data/capture
smpl=$easymocap/smpl_model.npz
ckpt=$ckpt
config=tests/configs/tiny_capture.yaml
SETTINGS

# The document's blocks: kind (settings, run, server) and text, one file each.
"$python" - "$repo/docs/YOUR_CAPTURE.md" "$work/blocks" <<'PY'
import os, re, sys
text = open(sys.argv[1]).read()
os.makedirs(sys.argv[2])
pattern = re.compile(r"<!-- (settings|run|run: server) -->\n```sh\n(.*?)```", re.S)
for i, (kind, body) in enumerate(pattern.findall(text)):
    kind = {"run: server": "server"}.get(kind, kind)
    open(os.path.join(sys.argv[2], f"{i:02d}.{kind}"), "w").write(body)
PY
ls "$work/blocks" | grep -q settings || fail "the document has no settings block"
runs=$(ls "$work/blocks" | grep -c '\.run$' || true)
((runs >= 4)) || fail "the document has $runs runnable blocks, expected at least 4"

cd "$work"
export PATH="$apps:$PATH" OMP_NUM_THREADS=1
port=$("$python" -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
for block in "$work"/blocks/*; do
  kind=${block##*.}
  [[ $kind == settings ]] && continue
  echo "--- $(basename "$block"): $(head -1 "$block")"
  if [[ $kind == server ]]; then
    sed -E "s/--port [0-9]+/--port $port/" "$block" > "$work/server.sh"
    setsid bash -c "set -euo pipefail; source '$work/settings.sh'; source '$work/server.sh'" > "$work/server.log" 2>&1 &
    server=$!
    "$python" - "$port" <<'PY' || { cat "$work/server.log"; fail "the viewer did not answer"; }
import json, sys, time, urllib.request
for _ in range(240):
    try:
        with urllib.request.urlopen(f"http://127.0.0.1:{sys.argv[1]}/api/info", timeout=5) as r:
            info = json.load(r)
            print("viewer answered /api/info:", sorted(info)[:6])
            sys.exit(0)
    except OSError:
        time.sleep(0.5)
sys.exit(1)
PY
    kill -- "-$server"; wait "$server" 2>/dev/null || true
    for _ in $(seq 50); do pgrep -g "$server" > /dev/null || break; sleep 0.2; done
    if pgrep -g "$server" > /dev/null; then kill -9 -- "-$server"; fail "the viewer did not stop within 10 s of SIGTERM"; fi
    server=""
    continue
  fi
  bash -c "set -euo pipefail; source '$work/settings.sh'; source '$block'" > "$work/block.log" 2>&1 ||
    { cat "$work/block.log"; fail "block $(basename "$block") failed"; }
  cat "$work/block.log" >> "$work/all.log"
  grep -E "layout \(data.layout|reference cameras|identity: [0-9]|trained [0-9]+ steps|fine-tuning|wrote '" "$work/block.log" | sed 's/^/    /' || true
done

# What the document promises.
grep -q "me: reference cameras .*: the 3 most evenly spread around the body" "$work/all.log" ||
  fail "no log line naming the chosen reference cameras"
grep -q "easymocap layout (data.layout: auto)" "$work/all.log" || fail "the layout was not named"
grep -q "me: reference cameras 00, 08, 15 (data.reference_views)" "$work/all.log" || fail "--reference-views was not used"
[[ $(find runs/capture_orbit -name '*.png' | wc -l) -ge 8 ]] || fail "the orbit has fewer than 8 frames"
[[ -s runs/capture_eval/per_image.csv && -s runs/capture_finetune/checkpoints/latest.pt &&
   -s runs/capture_finetune_eval/per_image.csv ]] || fail "an output is missing"
grep -q "fine-tuning: weights and token groups from" "$work/all.log" || fail "--init was not used"
echo "check_your_capture: $runs blocks and the viewer ran as docs/YOUR_CAPTURE.md writes them"
