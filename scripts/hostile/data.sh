# Hostile cases, group data (sourced by scripts/hostile.sh; scripts/hostile/lib.sh has the helpers).
# Numbers, calibration, images and special files in a ZJU-MoCap-layout dataset.

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
