#!/usr/bin/env bash
# Two builds' speed, alternating in one session (docs/PERFORMANCE.md, "two builds compared").
#
# Usage: scripts/bench-builds.sh BEFORE_DIR AFTER_DIR PAIRS OUT_MD [CONFIG CHECKPOINT]
#   BEFORE_DIR, AFTER_DIR: folders holding each build's transhuman-bench-model and
#   transhuman-bench-speed (copy them out of build/bench/ before rebuilding);
#   PAIRS: how many before/after pairs (even: the order alternates per pair);
#   OUT_MD: the table is appended there (bench/results/...); the raw logs go beside it in
#   OUT_MD.logs/ (a folder this script creates and refuses to reuse);
#   CONFIG, CHECKPOINT: the trained run bench-speed times (default: the demo's).
# Per pair and build, on one thread with glibc's heap on transparent huge pages and its top pad
# drawn per pair (the same for both builds of the pair):
#   transhuman-bench-model --sections points --chunks 4096 --rounds 3 --precision P (fp32, bf16):
#     forward, density-first forward, forward+backward and training-path points/s (best round);
#   transhuman-bench-speed --sections view train --paths default: the 512x512 view at 64 samples
#     (render + frame preparation) and the seconds per training step.
# Environment: TH_BENCH_THREADS (default 1: OMP_NUM_THREADS and --threads), TH_BENCH_CHUNK
# (default 4096), TH_BENCH_PATHS (default "default": bench-speed's paths, e.g. "fp32 bf16").
# Prints and appends, per measure, the after/before ratio of each pair (throughput, or
# before/after for times) and their median.
set -euo pipefail

if [[ $# -lt 4 ]]; then
  sed -n '2,18p' "$0" >&2
  exit 2
fi
before="$1" after="$2" pairs="$3" out="$4"
config="${5:-runs/demo/config.yaml}" checkpoint="${6:-runs/demo/checkpoints/latest.pt}"
for dir in "$before" "$after"; do
  for exe in transhuman-bench-model transhuman-bench-speed; do
    [[ -x "$dir/$exe" ]] || { echo "bench-builds: '$dir/$exe' is not an executable" >&2; exit 1; }
  done
done
[[ "$pairs" =~ ^[1-9][0-9]*$ ]] || { echo "bench-builds: PAIRS '$pairs' is not a count" >&2; exit 1; }
for f in "$config" "$checkpoint"; do
  [[ -f "$f" ]] || { echo "bench-builds: '$f' does not exist (train the demo first)" >&2; exit 1; }
done
logs="$out.logs"
mkdir "$logs" || { echo "bench-builds: '$logs' exists; name another OUT_MD" >&2; exit 1; }

threads="${TH_BENCH_THREADS:-1}" chunk="${TH_BENCH_CHUNK:-4096}"
read -r -a paths <<<"${TH_BENCH_PATHS:-default}"
export OMP_NUM_THREADS="$threads" OPENBLAS_NUM_THREADS=1
run_build() {  # build-dir tag pad
  local dir="$1" tag="$2" pad="$3"
  export GLIBC_TUNABLES="glibc.malloc.hugetlb=1:glibc.malloc.top_pad=$pad"
  for p in fp32 bf16; do
    "$dir/transhuman-bench-model" --threads "$threads" --sections points --chunks "$chunk" \
      --precision "$p" --rounds 3 --out '' >"$logs/$tag.model.$p.txt" 2>&1
  done
  "$dir/transhuman-bench-speed" --config "$config" --checkpoint "$checkpoint" \
    --sections view train --paths "${paths[@]}" --threads "$threads" --out '' \
    >"$logs/$tag.speed.txt" 2>&1
  unset GLIBC_TUNABLES
}
echo "threads $threads, chunk $chunk, bench-speed paths: ${paths[*]}"
for ((i = 1; i <= pairs; i++)); do
  pad=$(( (RANDOM % 33) * 1048576 ))
  if ((i % 2)); then order=(before after); else order=(after before); fi
  for which in "${order[@]}"; do
    dir="$before"
    [[ "$which" == after ]] && dir="$after"
    echo "pair $i: $which (top_pad $pad), load $(cut -d' ' -f1-3 /proc/loadavg)"
    run_build "$dir" "$i.$which" "$pad"
  done
done

python3 - "$logs" "$pairs" "$out" "$threads" "$chunk" "${paths[@]}" <<'EOF'
import re, statistics, sys, os, datetime
logs, pairs, out = sys.argv[1], int(sys.argv[2]), sys.argv[3]
threads, chunk, paths = sys.argv[4], sys.argv[5], sys.argv[6:]

def model(tag, p):
    best = None
    for line in open(os.path.join(logs, f"{tag}.model.{p}.txt")):
        m = re.match(r"\s*round \d+ chunk \d+ \S+: ([\d,]+) ([\d,]+) ([\d,]+) ([\d,]+)", line)
        if m:
            v = [float(x.replace(",", "")) for x in m.groups()]
            best = v if best is None else [max(a, b) for a, b in zip(best, v)]
    if best is None:
        sys.exit(f"bench-builds: no rates in {tag}.model.{p}.txt")
    return best

def speed(tag, path):
    view = step = None
    for line in open(os.path.join(logs, f"{tag}.speed.txt")):
        c = [x.strip() for x in line.strip().strip("|").split("|")]
        if len(c) > 5 and c[0] == "64" and c[1] == path:
            view = float(c[4])
        if len(c) >= 4 and c[0] == path and re.match(r"^[\d.]+$", c[1]):
            step = float(c[1])
    if view is None or step is None:
        sys.exit(f"bench-builds: no view or training row of path {path} in {tag}.speed.txt")
    return view, step

names = ["forward, points/s", "density-first forward, points/s", "forward+backward, points/s",
         "training path, points/s"]
rows = []
for p in ("fp32", "bf16"):
    for k, name in enumerate(names):
        b = [model(f"{i}.before", p)[k] for i in range(1, pairs + 1)]
        a = [model(f"{i}.after", p)[k] for i in range(1, pairs + 1)]
        rows.append((p, name, b, a, [x / y for x, y in zip(a, b)]))
for path in paths:
    for k, name in enumerate(["512x512 view at 64 samples, s", "training step at the config, s"]):
        b = [speed(f"{i}.before", path)[k] for i in range(1, pairs + 1)]
        a = [speed(f"{i}.after", path)[k] for i in range(1, pairs + 1)]
        rows.append((f"config ({path})", name, b, a, [x / y for x, y in zip(b, a)]))

fmt = lambda v: ", ".join(f"{x:,.0f}" if x > 100 else f"{x:.3f}" for x in v)
lines = [f"### {pairs} pairs, {datetime.date.today()}, {threads} thread(s), chunk {chunk}, load at the end {open('/proc/loadavg').read().split()[0]}", "",
         "| precision | measure | before | after | after/before per pair (times: before/after) | median | lower after |",
         "|---|---|---|---|---|---|---|"]
for p, name, b, a, r in rows:
    lines.append(f"| {p} | {name} | {fmt(b)} | {fmt(a)} | {', '.join(f'{x:.3f}' for x in r)} | "
                 f"{statistics.median(r):.3f} | {sum(x < 1 for x in r)} of {len(r)} |")
text = "\n".join(lines) + "\n\n"
print(text)
with open(out, "a") as f:
    f.write(text)
EOF
