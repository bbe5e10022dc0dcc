# Hostile cases, group reports (sourced by scripts/hostile.sh; scripts/hostile/lib.sh has the helpers).
# Paths the system refuses, report inputs and folders, render requests, failing ranks.

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
check "render --dry-run --camera 99" 2 "--camera: camera 99 does not exist for" \
  "$apps/transhuman-render" "${tiny[@]}" $(on "$data") --checkpoint "$ckpt" --dry-run --camera 99
check "render --dry-run --path <missing>" 2 "camera path file '$work/missing.yaml' does not exist" \
  "$apps/transhuman-render" "${tiny[@]}" $(on "$data") --checkpoint "$ckpt" --dry-run --path "$work/missing.yaml"
check "mesh --dry-run --view 99" 2 "camera 99 out of range" \
  "$apps/transhuman-mesh" "${tiny[@]}" $(on "$data") --checkpoint "$ckpt" --dry-run --view 99

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
check "eval --nproc 2 --out <a folder holding results>" 2 "transhuman-eval[rank 0]: error: --out '$work/e_good' already holds" \
  "${evaluate[@]}" $(on "$data") --out "$work/e_good" --nproc 2
check "render --nproc 2 over another request's frames (after the rendezvous)" 2 \
  "transhuman-render[rank 0]: error: '$work/r_settings' holds frames of another request: render.samples (frames: 64, now: 8)" \
  "${orbit[@]}" --nproc 2
check "train --nproc 2 with a data.root every rank misses" 2 "[rank " \
  "$apps/transhuman-train" "${tiny[@]}" data.root="$work/nowhere" data.split_file="$data/split.yaml" --out "$work/t_nowhere" --nproc 2
