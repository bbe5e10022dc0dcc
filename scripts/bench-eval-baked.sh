#!/usr/bin/env bash
# Baked evaluation against exact evaluation on the demo's trained checkpoint (trained first, as
# scripts/demo.sh trains it, when runs/demo has none), each run a transhuman-eval process of its
# own, writing bench/results/eval_baked.md:
#   1. accuracy: the identity setting (108 views) scored exact and baked at 4, 2 and 1 cm, at the
#      demo's 128x128, 16 samples per ray: per grid the mean and worst per-image difference to
#      exact (PSNR, SSIM, LPIPS when eval.lpips_weights is given);
#   2. speed of the demo's evaluation: exact and baked 2 cm alternating, twice;
#   3. the paper's identity protocol at 512x512, 64 samples per ray: 438 views, 73 frames of 6
#      target views (the setting `protocol_438` added to a copy of the split: the 3 unseen people,
#      every second frame), as ZJU-MoCap's identity set has them; baked 2 cm on all 438; exact fp32
#      on the first TH_BENCH_EXACT_VIEWS views (default 36), exact bf16 on the first
#      TH_BENCH_EXACT_BF16_VIEWS (default 12) and baked 1.5 and 1 cm on the first 108, each
#      projected to 438 views from its measured times; the baked-minus-exact difference on the
#      views both scored;
#   4. validation while training: the demo's saved checkpoints ranked by exact and by baked 2 cm
#      identity scores, and what one validation (train.val_views views) costs each way.
# Runs for about 40 minutes on 2 cores; measure on an otherwise idle machine.
#   scripts/bench-eval-baked.sh [SECTION...]   sections: accuracy speed protocol validation
#   (`report` alone: write the report again from the runs already made)
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install-deps.sh
bash scripts/build.sh transhuman-synth transhuman-train transhuman-eval
data=data/synthetic
run=${TH_DEMO_RUN:-runs/demo}
work=${TH_BENCH_WORK:-runs/bench_eval_baked}
exact_views=${TH_BENCH_EXACT_VIEWS:-36}
bf16_views=${TH_BENCH_EXACT_BF16_VIEWS:-12}
sections=("$@")
((${#sections[@]})) || sections=(accuracy speed protocol validation)
build/apps/transhuman-synth --config configs/synth/default.yaml --out "$data"
if [[ ! -f "$run/checkpoints/latest.pt" ]]; then
  build/apps/transhuman-train --config configs/demo.yaml --out "$run" --force
fi
ckpt=$run/checkpoints/latest.pt
mkdir -p "$work"
# name, seconds, folder: one line per evaluation; a section run again replaces its lines (the
# report takes each name's last line), so sections can be run in separate invocations.
log=$work/runs.tsv
touch "$log"
load() { cut -d' ' -f1-3 /proc/loadavg; }
[[ "${sections[*]}" == report ]] || echo "start ${sections[*]}	$(load)" >>"$work/load.txt"
setting=identity

# evaluate NAME CHECKPOINT [transhuman-eval options and overrides...]: one timed evaluation.
evaluate() {
  local name=$1 checkpoint=$2
  shift 2
  local t0 t1
  t0=$(date +%s.%N)
  OMP_WAIT_POLICY=passive build/apps/transhuman-eval --config configs/demo.yaml --checkpoint "$checkpoint" \
    --setting "$setting" --out "$work/$name" --force "$@" >"$work/$name.log" 2>&1 ||
    { tail -20 "$work/$name.log"; echo "bench-eval-baked: $name failed" >&2; exit 1; }
  t1=$(date +%s.%N)
  printf '%s\t%s\t%s\n' "$name" "$(echo "$t1 - $t0" | bc)" "$work/$name" >>"$log"
  echo "$name: $(echo "$t1 - $t0" | bc | cut -c1-7) s" >&2
}
has() { [[ " ${sections[*]} " == *" $1 "* ]]; }

if has accuracy; then
  evaluate a128_exact "$ckpt"
  for v in 0.04 0.02 0.01; do evaluate "a128_baked_$v" "$ckpt" --baked --bake-voxel $v; done
fi
if has speed; then
  for round in 1 2; do
    evaluate "s128_exact_$round" "$ckpt"
    evaluate "s128_baked_$round" "$ckpt" --baked
  done
fi
if has protocol; then
  # The split with the 438-view setting beside the dataset's own.
  /usr/bin/python3 - "$data/split.yaml" "$work/split.yaml" <<'SPLIT'
import sys
text = open(sys.argv[1]).read()
people = [('CoreView_s08', 48), ('CoreView_s09', 48), ('CoreView_s10', 50)]  # 24 + 24 + 25 frames
text += '  protocol_438:\n    reference_views: [0, 7, 15]\n    target_views: [3, 5, 10, 12, 18, 20]\n    humans:\n'
text += ''.join(f'      - {{name: {n}, begin: 0, ni: {k}, interval: 2}}\n' for n, k in people)
open(sys.argv[2], 'w').write(text)
SPLIT
  setting=protocol_438
  p=(data.ratio=1 render.samples=64 "data.split_file=$work/split.yaml")
  evaluate p_exact_fp32 "$ckpt" "${p[@]}" --limit "$exact_views" --precision fp32
  evaluate p_exact_bf16 "$ckpt" "${p[@]}" --limit "$bf16_views" --precision bf16
  evaluate p_baked_0.02 "$ckpt" "${p[@]}" --baked --bake-voxel 0.02
  evaluate p_baked_0.015 "$ckpt" "${p[@]}" --baked --bake-voxel 0.015 --limit 108
  evaluate p_baked_0.01 "$ckpt" "${p[@]}" --baked --bake-voxel 0.01 --limit 108
  setting=identity
fi
if has validation; then
  for c in "$run"/checkpoints/epoch_*.pt; do
    e=$(basename "$c" .pt)
    evaluate "v_exact_$e" "$c"
    evaluate "v_baked_$e" "$c" --baked
  done
fi
[[ "${sections[*]}" == report ]] || echo "end ${sections[*]}	$(load)" >>"$work/load.txt"

/usr/bin/python3 - "$work" "$exact_views" "$bf16_views" "$(git rev-parse --short HEAD)$(git diff --quiet || echo +)" <<'PY'
import csv, json, os, statistics, sys, time
work, exact_views, bf16_views, commit = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
runs = {}
for line in open(os.path.join(work, 'runs.tsv')):
    name, seconds, folder = line.rstrip('\n').split('\t')
    runs[name] = {'seconds': float(seconds), 'folder': folder}
load = [l.rstrip('\n').split('\t') for l in open(os.path.join(work, 'load.txt'))]
def rows(name):
    return {(r['human'], r['frame'], r['view']): r for r in csv.DictReader(open(os.path.join(runs[name]['folder'], 'per_image.csv')))}
def summary(name):
    return json.load(open(os.path.join(runs[name]['folder'], 'summary.json')))
def num(v):
    try:
        return float(v)
    except ValueError:
        return float('nan')
def diff(a, b, key):
    """Per-image b - a over the views both scored: mean, worst (largest magnitude)."""
    ra, rb = rows(a), rows(b)
    d = [num(rb[k][key]) - num(ra[k][key]) for k in ra if k in rb]
    d = [x for x in d if x == x]
    if not d:
        return 'n/a', 'n/a', 0
    return statistics.fmean(d), max(d, key=abs), len(d)
def f(v, digits):
    return v if isinstance(v, str) else f'{v:+.{digits}f}'
cpu = next((l.split(':', 1)[1].strip() for l in open('/proc/cpuinfo') if l.startswith('model name')), 'unknown')
out = [f'# Baked evaluation against exact ({time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())})', '',
       f'Checkpoint runs/demo/checkpoints/latest.pt (configs/demo.yaml); setting identity; commit {commit}; '
       f'processor {cpu}, {os.cpu_count()} cores; load averages (1, 5, 15 min) at the start and end of each invocation: '
       + '; '.join(f'{what}: {value}' for what, value in load) + '. '
       'Each figure is one transhuman-eval process (scripts/bench-eval-baked.sh); seconds are wall time, '
       'start-up (loading the data and the checkpoint) included. A baked evaluation bakes each frame once, its colours '
       'seen from the cameras of the views scored of it (METHOD 7.1).', '']
lp = any(summary(n).get('lpips_available') == 'yes' for n in runs)
if 'a128_exact' in runs:
    out += ['## Accuracy: baked minus exact, per image, 16 samples per ray', '',
            '| size | renderer | views | PSNR | PSNR diff: mean | worst | SSIM | SSIM diff: mean | worst | LPIPS diff: mean | worst | seconds |',
            '|---|---|---|---|---|---|---|---|---|---|---|---|']
    for size in ('128',):
        e = f'a{size}_exact'
        s = summary(e)
        out.append(f'| {size}x{size} | exact | {s["images"]} | {s["psnr"]:.2f} | - | - | {s["ssim"]:.4f} | - | - | - | - | {runs[e]["seconds"]:.0f} |')
        for v in ('0.04', '0.02', '0.01'):
            b = f'a{size}_baked_{v}'
            s = summary(b)
            pm, pw, n = diff(e, b, 'psnr')
            sm, sw, _ = diff(e, b, 'ssim')
            lm, lw, _ = diff(e, b, 'lpips')
            out.append(f'| {size}x{size} | {s["renderer"]} | {n} | {s["psnr"]:.2f} | {f(pm, 3)} | {f(pw, 3)} | {s["ssim"]:.4f} | '
                       f'{f(sm, 4)} | {f(sw, 4)} | {f(lm, 4)} | {f(lw, 4)} | {runs[b]["seconds"]:.0f} |')
    out += ['', 'LPIPS: ' + ('scored with eval.lpips_weights.' if lp else
            'n/a: no LPIPS weights here (scripts/export_lpips.py needs torchvision\'s pretrained VGG), so only PSNR and SSIM are compared.'), '']
if 's128_exact_1' in runs:
    out += ['## Speed: the identity evaluation (108 views), 16 samples per ray, runs alternating', '',
            '| size | renderer | round 1 s | round 2 s | median s | speed-up |', '|---|---|---|---|---|---|']
    def med(names):
        return statistics.median(runs[n]['seconds'] for n in names if n in runs)
    e128 = med(['s128_exact_1', 's128_exact_2'])
    b128 = med(['s128_baked_1', 's128_baked_2'])
    g = lambda n: f'{runs[n]["seconds"]:.1f}' if n in runs else '-'
    out.append(f'| 128x128 (the demo) | exact | {g("s128_exact_1")} | {g("s128_exact_2")} | {e128:.1f} | 1x |')
    out.append(f'| 128x128 (the demo) | baked 2 cm | {g("s128_baked_1")} | {g("s128_baked_2")} | {b128:.1f} | {e128 / b128:.1f}x |')
    bake = [r for r in rows('s128_baked_1').values()]
    out += ['', f'A baked run spends its time on 18 bakes (one per frame; a row\'s seconds hold its frame\'s bake on the frame\'s first view): '
            f'{sum(num(r["seconds"]) for r in bake):.1f} s of rows at 128x128. The bake costs the same at any image size, '
            'the exact render grows with the pixels and the samples: at 128x128 and 16 samples a frame\'s 6 exact views ask '
            'the network for about as many points as its bake (the 512x512 protocol below for the other end).', '']
if 'p_exact_fp32' in runs:
    out += [f'## The paper\'s identity protocol: 438 views at 512x512, 64 samples per ray (73 frames x 6 views), projected', '',
            '| renderer | precision | views run | seconds run | per view s (rows) | bake per frame s | march per view s | 438 views | PSNR diff to exact fp32: mean | worst | SSIM diff: mean |',
            '|---|---|---|---|---|---|---|---|---|---|---|']
    for name, prec in (('p_exact_fp32', 'fp32'), ('p_exact_bf16', 'bf16'), ('p_baked_0.02', 'fp32'),
                       ('p_baked_0.015', 'fp32'), ('p_baked_0.01', 'fp32')):
        if name not in runs:
            continue
        s = summary(name)
        r = list(rows(name).values())
        wall = runs[name]['seconds']
        row_seconds = sum(num(x['seconds']) for x in r)
        if name.startswith('p_exact'):
            # Each view's own seconds scale with the views; the rest (start-up, loading, scoring)
            # is taken as it was, a lower bound of the projection's overhead.
            projected = (wall - row_seconds) + 438 * row_seconds / len(r)
            bake_s, march_s = '-', '-'
        else:
            firsts, rest = {}, []
            for x in r:  # the first view of a frame holds its bake (and its frame's preparation)
                k = (x['human'], x['frame'])
                if k not in firsts:
                    firsts[k] = num(x['seconds'])
                else:
                    rest.append(num(x['seconds']))
            march = statistics.fmean(rest)
            bake = statistics.fmean(firsts.values()) - march
            # Frames and views both grow by 438 / views here (6 views a frame): the whole run is
            # scaled, start-up included (an upper bound).
            projected = wall * 438 / len(r)
            bake_s, march_s = f'{bake:.2f}', f'{march:.3f}'
        per_view = row_seconds / len(r)
        if name == 'p_exact_fp32':
            dm = dw = sm = '-'
        else:
            dm, dw, _ = diff('p_exact_fp32', name, 'psnr')
            sm, _, _ = diff('p_exact_fp32', name, 'ssim')
            dm, dw, sm = f(dm, 3), f(dw, 3), f(sm, 4)
        measured = len(r) == 438
        out.append(f'| {s["renderer"]} | {prec} | {s["images"]} | {wall:.0f} | {per_view:.2f} | {bake_s} | {march_s} | '
                   f'{wall / 60 if measured else projected / 60:.1f} min{" (measured)" if measured else ""} | {dm} | {dw} | {sm} |')
    if 'p_exact_bf16' in runs:
        both = [k for k in rows('p_exact_bf16') if k in rows('p_exact_fp32')]
        seconds = {n: statistics.fmean(num(rows(n)[k]['seconds']) for k in both) for n in ('p_exact_fp32', 'p_exact_bf16')}
        out += ['', f'Exact fp32 and bf16 on the {len(both)} views both scored: {seconds["p_exact_fp32"]:.2f} and '
                f'{seconds["p_exact_bf16"]:.2f} s per view (rows).']
    out += ['', f'Setting protocol_438: the 3 unseen people, every second frame (24 + 24 + 25 frames), 6 target views each. '
            f'Exact fp32 scores its first {exact_views} views ({exact_views // 6} frames), exact bf16 its first {bf16_views}, baked 1.5 and 1 cm its first 108 (18 frames), baked 2 cm all 438. '
            'Projection of a partial run: its rows\' seconds scaled to 438 views plus the rest of its wall time as it was (exact), '
            'or its whole wall time scaled by 438 / views (baked: frames and views grow alike). A baked row\'s seconds on a '
            'frame\'s first view hold the frame\'s preparation (encoder, painting, TransHE at 512x512) and its bake; "bake per '
            'frame" is that minus a march. The differences are over the views both renderers scored. '
            'The paper: 17 minutes on one V100 (64 samples), 9 minutes at 16.', '']
val = sorted(n[len('v_exact_'):] for n in runs if n.startswith('v_exact_'))
if val:
    out += ['## Validation while training: ranking the demo\'s checkpoints', '',
            '| checkpoint | exact PSNR | exact s | baked 2 cm PSNR | baked s | PSNR diff |', '|---|---|---|---|---|---|']
    for e in val:
        se, sb = summary('v_exact_' + e), summary('v_baked_' + e)
        out.append(f'| {e} | {se["psnr"]:.2f} | {runs["v_exact_" + e]["seconds"]:.0f} | {sb["psnr"]:.2f} | {runs["v_baked_" + e]["seconds"]:.0f} | {sb["psnr"] - se["psnr"]:+.3f} |')
    order = lambda kind: [e for e in sorted(val, key=lambda e: -summary(f'v_{kind}_{e}')['psnr'])]
    same = order('exact') == order('baked')
    out += ['', f'Ranking by exact PSNR: {", ".join(order("exact"))}; by baked: {", ".join(order("baked"))} '
            f'({"the same" if same else "different"}).', '']
    # One validation: train.val_views views spread over the split, each of another frame, so each
    # view pays its frame: exact, a first view's seconds (its frame prepared); baked, a bake and a march.
    def first_views(name):
        seen, out_ = set(), []
        for x in rows(name).values():
            k = (x['human'], x['frame'])
            if k not in seen:
                seen.add(k)
                out_.append(num(x['seconds']))
        return statistics.fmean(out_)
    last = val[-1]
    ev, bv = first_views('v_exact_' + last), first_views('v_baked_' + last)
    out += [f'One validation of the demo (train.val_views 2, each view of another frame), from the rows of {last}: '
            f'exact {2 * ev:.2f} s, baked 2 cm {2 * bv:.2f} s.', '']
open('bench/results/eval_baked.md', 'w').write('\n'.join(out) + '\n')
print('\n'.join(out))
PY
