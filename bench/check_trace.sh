#!/usr/bin/env bash
# The benchmark's operator trace and scripts/compare-traces.py: a trace compared with itself is
# "the same operators" (exit 0); with one operator call removed, the script reports it (exit 1).
#   bench/check_trace.sh BENCH_MODEL_BINARY
set -euo pipefail
bench=$1
here=$(cd "$(dirname "$0")/.." && pwd)
work=$(mktemp -d "${TMPDIR:-/tmp}/th-trace.XXXXXX")
trap 'rm -rf "$work"' EXIT
trace=$work/trace.json
"$bench" --quick --threads 1 --sections points --chunks 1024 --rounds 0 --trace "$trace" --out "$work/model.md"
python3 "$here/scripts/compare-traces.py" "$trace" "$trace"
python3 - "$trace" "$work/one_less.json" <<'PY'
import json, sys
data = json.load(open(sys.argv[1]))
events = data["traceEvents"] if isinstance(data, dict) else data
i = next(i for i, e in enumerate(events) if e.get("ph") == "X" and e["name"] == "aten::mm")
del events[i]
json.dump(data, open(sys.argv[2], "w"))
PY
if python3 "$here/scripts/compare-traces.py" "$trace" "$work/one_less.json" >"$work/compare.txt"; then
  echo "compare-traces.py did not report the removed aten::mm call" >&2
  exit 1
fi
grep -q "aten::mm: before" "$work/compare.txt" || { cat "$work/compare.txt" >&2; exit 1; }
# A trace that cannot be written is an error naming the file, not a silent skip.
if "$bench" --quick --threads 1 --sections points --chunks 1024 --rounds 0 --trace "$work/no/such/dir/t.json" \
    --out "$work/model.md" --force >"$work/unwritable.log" 2>&1; then
  echo "an unwritable --trace file was accepted" >&2
  exit 1
fi
grep -q "no/such/dir/t.json" "$work/unwritable.log" || { cat "$work/unwritable.log" >&2; exit 1; }
echo "check_trace: the trace equals itself; a removed aten::mm call is reported"
