# Hostile cases, group bake (sourced by scripts/hostile.sh; scripts/hostile/lib.sh has the helpers).
# Bake files and bake options of transhuman-render and transhuman-view (METHOD 7.1), and the
# fine-tuning start of transhuman-train (--init): special files, sizes, memory, the request a
# folder's frames were made by, destinations that are not new files, foreign bakes, dry runs.

small=(--orbit 2 --width 16 --height 16)
render=("$apps/transhuman-render" "${tiny[@]}" $(on "$data") --checkpoint "$ckpt" "${small[@]}")
# A bake of frame 0 at 5 cm, and one at 4 cm, written by renders of their own.
"${render[@]}" --baked --bake-voxel 0.05 --bake-out "$work/b05.thbake" --out "$work/r_b05" >"$work/b05.log" 2>&1
"${render[@]}" --baked --bake-voxel 0.04 --bake-out "$work/b04.thbake" --out "$work/r_b04" >"$work/b04.log" 2>&1
verdict "the bakes the cases read (5 cm and 4 cm)" "$(stat -c %s "$work/b05.thbake" "$work/b04.thbake" 2>/dev/null | tr '\n' ' ')bytes" \
  $([[ -s $work/b05.thbake && -s $work/b04.thbake ]]; echo $?)

# ---- bake files that are not files, or larger than memory -----------------------------------------
mkfifo "$work/fifo.thbake"
check "render --bake-in <a FIFO> (a read would block)" 2 "--bake-in '$work/fifo.thbake' is a FIFO (named pipe), not a file" \
  "${render[@]}" --bake-in "$work/fifo.thbake" --out "$work/r_fifo"
absent "  ... no --out written" "$work/r_fifo"
check "render --bake-in /dev/zero (a read would never end)" 2 "--bake-in '/dev/zero' is a character device, not a file" \
  "${render[@]}" --bake-in /dev/zero --out "$work/r_zero"
"$py" - "$work/b05.thbake" "$work/long_header.thbake" "$work/huge.thbake" <<'EOF'
import json, os, struct, sys
b = open(sys.argv[1], 'rb').read()
n = struct.unpack('<I', b[12:16])[0]
open(sys.argv[2], 'wb').write(b[:12] + struct.pack('<I', 1 << 31) + b[16:])
# A header describing 512^3 cells in bricks of 8, every brick stored: a sparse file of that size.
h = json.loads(b[16:16 + n])
h['cells'] = [512, 512, 512]
h['brick'] = 8
h['stored_bricks'] = 64 ** 3
t = json.dumps(h).encode()
with open(sys.argv[3], 'wb') as f:
    f.write(b[:12] + struct.pack('<I', len(t)) + t)
    f.truncate(16 + len(t) + 64 ** 3 * 4 + 64 ** 3 * 9 ** 3 * 4 * 4)
EOF
check "render --bake-in <a header claiming 2 GiB>" 2 "baked frame '$work/long_header.thbake': a header of 2147483648 bytes, more than a baked frame's" \
  "${render[@]}" --bake-in "$work/long_header.thbake" --out "$work/r_long"
check "render --bake-in <a sparse 2.8 GiB bake> max_memory_gb=2 (refused before it is read)" 2 \
  "baked frame '$work/huge.thbake': its arrays take 2.8 GiB, above the memory limit of 2.0 GiB (max_memory_gb)" \
  "${render[@]}" --bake-in "$work/huge.thbake" --out "$work/r_huge" max_memory_gb=2
head -c -100 "$work/b05.thbake" >"$work/short.thbake"
check "render --dry-run --bake-in <a bake missing its last 100 bytes>" 2 "baked frame '$work/short.thbake': && bytes, its header describes" \
  "${render[@]}" --bake-in "$work/short.thbake" --out "$work/r_short" --dry-run

# ---- the memory of a bake, estimated from the body's box before anything is allocated --------------
check "render --baked --bake-voxel 0.001 max_memory_gb=2" 2 \
  "bake of $person frame && at --bake-voxel 0.001 m (lattice && estimated peak memory && (max_memory_gb=2)" \
  "${render[@]}" --baked --bake-voxel 0.001 --out "$work/r_mm" max_memory_gb=2
check "render --dry-run --baked --bake-voxel 0.001 max_memory_gb=2" 2 \
  "at --bake-voxel 0.001 m (lattice && estimated peak memory && (max_memory_gb=2)" \
  "${render[@]}" --baked --bake-voxel 0.001 --out "$work/r_mm_dry" max_memory_gb=2 --dry-run
check "view --bake-voxel 0.001 max_memory_gb=2 (at start-up, before it serves)" 2 \
  "at --bake-voxel 0.001 m (lattice && estimated peak memory && (max_memory_gb=2)" \
  "$apps/transhuman-view" "${tiny[@]}" $(on "$data") --checkpoint "$ckpt" --port 7391 --bake-voxel 0.001 max_memory_gb=2
check "view --dry-run --bake-voxel 0.001 max_memory_gb=2" 2 "at --bake-voxel 0.001 m && (max_memory_gb=2)" \
  "$apps/transhuman-view" "${tiny[@]}" $(on "$data") --checkpoint "$ckpt" --bake-voxel 0.001 max_memory_gb=2 --dry-run

# ---- bake options ----------------------------------------------------------------------------------
check "render --baked --bake-voxel nan --dry-run" 2 "--bake-voxel: must be in [0.001, 0.2], not nan" \
  "${render[@]}" --baked --bake-voxel nan --out "$work/r_nan" --dry-run
check "view --bake-voxel nan --dry-run" 2 "--bake-voxel: must be in [0.001, 0.2], not nan" \
  "$apps/transhuman-view" "${tiny[@]}" $(on "$data") --checkpoint "$ckpt" --bake-voxel nan --dry-run
check "render --bake-voxel 0.04 without --baked" 2 "--bake-voxel sets the grid of a bake: it needs --baked (or --bake-in)" \
  "${render[@]}" --bake-voxel 0.04 --out "$work/r_novoxel"
check "render --bake-in <a 5 cm bake> --bake-voxel 0.04" 2 "--bake-voxel 0.04: baked frame '$work/b05.thbake' has its own grid of 0.05 m" \
  "${render[@]}" --bake-in "$work/b05.thbake" --bake-voxel 0.04 --out "$work/r_voxel_in"
check "render --baked --bake-out <a folder that does not exist>/f" 2 \
  "--bake-out '$work/missing/dir/f.thbake': its folder '$work/missing/dir' does not exist" \
  "${render[@]}" --baked --bake-out "$work/missing/dir/f.thbake" --out "$work/r_missing"
absent "  ... refused before --out was written" "$work/r_missing"
check "render --baked --bake-out <--out>/config.yaml" 2 "--bake-out '$work/r_cfg/config.yaml' lies in --out '$work/r_cfg'" \
  "${render[@]}" --baked --bake-out "$work/r_cfg/config.yaml" --out "$work/r_cfg"
absent "  ... refused before --out was written" "$work/r_cfg"
check "render --baked --bake-out <the checkpoint>" 2 "--bake-out '$ckpt' exists: name a new file" \
  "${render[@]}" --baked --bake-out "$ckpt" --out "$work/r_ckpt"
d=$(copy bake_into_data)
check "render --baked --bake-out <inside the data root>" 2 "--bake-out '$d/$person/f.thbake' lies in the data root (data.root) '$d'" \
  "$apps/transhuman-render" "${tiny[@]}" $(on "$d") --checkpoint "$ckpt" "${small[@]}" --baked \
  --bake-out "$d/$person/f.thbake" --out "$work/r_data"
absent "  ... nothing written into the dataset" "$d/$person/f.thbake"
# Two renders writing one new bake file: one writes it, the other is refused.
"${render[@]}" --baked --bake-voxel 0.05 --bake-out "$work/twice.thbake" --out "$work/r_twice_a" >"$work/twice_a.log" 2>&1 &
first=$!
"${render[@]}" --baked --bake-voxel 0.05 --bake-out "$work/twice.thbake" --out "$work/r_twice_b" >"$work/twice_b.log" 2>&1
rc_b=$?
wait "$first"
rc_a=$?
lost=$(grep -h "error:" "$work/twice_a.log" "$work/twice_b.log" | tail -1)
verdict "two renders --bake-out <one new file> at once: one writes it, one is refused (exits $rc_a, $rc_b)" "$lost" \
  $([[ $((rc_a + rc_b)) -eq 2 && ($rc_a -eq 0 || $rc_b -eq 0) && $lost == *"twice.thbake"* ]]; echo $?)
check_ok "  ... the file written is a whole bake" "${render[@]}" --bake-in "$work/twice.thbake" --out "$work/r_twice_c"

# ---- a bake of another frame or person --------------------------------------------------------------
check "render --bake-in <a bake of frame 0> --frames 1" 2 "baked frame '$work/b05.thbake' is a bake of frame && , not 1 (--frames)" \
  "${render[@]}" --bake-in "$work/b05.thbake" --frames 1 --out "$work/r_frame1"
"$py" - "$work/b05.thbake" "$work/other_person.thbake" <<'EOF'
import json, struct, sys
b = open(sys.argv[1], 'rb').read()
n = struct.unpack('<I', b[12:16])[0]
h = json.loads(b[16:16 + n])
h['human'] = 'CoreView_313'
t = json.dumps(h).encode()
open(sys.argv[2], 'wb').write(b[:12] + struct.pack('<I', len(t)) + t + b[16 + n:])
EOF
check "render --bake-in <a bake of another person>" 2 "baked frame '$work/other_person.thbake' is a bake of person CoreView_313, not $person" \
  "${render[@]}" --bake-in "$work/other_person.thbake" --out "$work/r_person" --dry-run

# ---- a folder's frames are resumed only under the bake that made them --------------------------------
check "render --baked --bake-voxel 0.04 over frames of a 5 cm bake" 2 \
  "holds frames of another request: bake.voxel (frames: 0.05, now: 0.04)" \
  "${render[@]}" --baked --bake-voxel 0.04 --out "$work/r_b05"
check "render --bake-in <the 5 cm bake's file> over frames it was written beside" 2 \
  "holds frames of another request: bake.file (frames: not recorded, now: && bake.source (frames: this run, now: $work/b05.thbake)" \
  "${render[@]}" --bake-in "$work/b05.thbake" --out "$work/r_b05"
"${render[@]}" --bake-in "$work/b05.thbake" --out "$work/r_in05" >/dev/null 2>&1
check "render --bake-in <the 4 cm bake> over frames of the 5 cm file" 2 \
  "holds frames of another request: bake.file (frames: && bake.source (frames: $work/b05.thbake, now: $work/b04.thbake), bake.voxel (frames: 0.05, now: 0.04)" \
  "${render[@]}" --bake-in "$work/b04.thbake" --out "$work/r_in05"
check_out "render --bake-in <the same file>: resumed" "2 frames (0 rendered, 2 resumed)" \
  "${render[@]}" --bake-in "$work/b05.thbake" --out "$work/r_in05"

# ---- fine-tuning from --init: checked whole before --out is written --------------------------------
train=("$apps/transhuman-train" "${tiny[@]}" $(on "$data") --max-steps 1)
check "train --init <missing>" 2 "checkpoint '$work/missing.pt' does not exist" \
  "${train[@]}" --init "$work/missing.pt" --out "$work/t_init"
absent "  ... no --out written" "$work/t_init"
check_ok "  ... the corrected rerun into the same --out" "${train[@]}" --init "$ckpt" --out "$work/t_init"
head -c 20000 "$ckpt" >"$work/cut_init.pt"
check "train --dry-run --init <a truncated checkpoint>" 2 "$work/cut_init.pt" \
  "${train[@]}" --init "$work/cut_init.pt" --out "$work/t_cut" --dry-run
mkfifo "$work/fifo.pt"
check "train --init <a FIFO>" 2 "'$work/fifo.pt' is a FIFO (named pipe), not a file" \
  "${train[@]}" --init "$work/fifo.pt" --out "$work/t_fifo"
absent "  ... no --out written" "$work/t_fifo"
cp "$ckpt" "$work/ours.pth"
check "train --init <our .pt renamed .pth>" 2 "$work/ours.pth && this file is one of ours, written by transhuman-train: name it .pt" \
  "${train[@]}" --init "$work/ours.pth" --out "$work/t_pth" --dry-run
check "train --init <a checkpoint of another model> (refused before --out)" 2 "$work/deep/checkpoints/latest.pt" \
  "${train[@]}" --init "$work/deep/checkpoints/latest.pt" --out "$work/t_deep"
absent "  ... no --out written" "$work/t_deep"
