# Hostile cases, group runs (sourced by scripts/hostile.sh; scripts/hostile/lib.sh has the helpers).
# Run folders: never overwritten, --force never removes an input, one writer, no write through a link.

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


# ---- 5. disk full: tests/apps/check_disk_full.sh (a 1 MB tmpfs; needs root) ----------------------
if bash tests/apps/check_disk_full.sh "$apps" "$data" >"$work/disk_full.log" 2>&1; then
  rows+=("| disk full while writing a checkpoint (1 MB tmpfs) | 2 | 2 | - | $(grep -o 'last stderr line: .*' "$work/disk_full.log" | cut -c 19-240 | sed "s|$work|…|g") | ok |")
elif grep -q SKIP "$work/disk_full.log"; then
  rows+=("| disk full while writing a checkpoint | 2 | - | - | skipped: no tmpfs can be mounted (not root) | skip |")
else
  rows+=("| disk full while writing a checkpoint | 2 | ? | - | $(tail -1 "$work/disk_full.log") | FAIL |")
  failures=$((failures + 1))
fi

# ---- 5. run folders: --force never removes an input; one writer per folder ------------------------
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
  "$apps/transhuman-eval" --config "$work/run/config.yaml" model.grouping.cache_dir="$kmeans" $(on "$data") \
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

# ---- links, parents and dry runs: what --force and the writers may touch ----------------------------
# The config's parent inside --out: every config file read is an input.
mkdir -p "$work/parented/cfg"
cp tests/configs/tiny_train.yaml "$work/parented/cfg/base.yaml"
sed -i "s|parent: ../../configs/default.yaml|parent: $repo/configs/default.yaml|" "$work/parented/cfg/base.yaml"
printf 'parent: parented/cfg/base.yaml\n' >"$work/child.yaml"
echo keep >"$work/parented/results.md"
check "--force with the config's parent inside --out" 2 \
  "--force would delete the config's parent (child.yaml) '$work/parented/cfg/base.yaml'" \
  "$apps/transhuman-train" --config "$work/child.yaml" $(on "$data") model.grouping.cache_dir="$kmeans" \
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
