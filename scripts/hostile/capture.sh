# Hostile cases, group capture (sourced by scripts/hostile.sh; scripts/hostile/lib.sh has the helpers).
# Captures as people hand them over: EasyMocap's layout with its own variants (1x4 distortion,
# numeric camera names, cameras in another order), masks of any depth or with alpha, nested or
# oversized files, duplicate choices, link loops, odd camera counts and image sizes.

# The tiny people in EasyMocap's layout: the test fixture beside the dataset, or made here.
em_source=${data}_easymocap
if [[ ! -f $em_source/split.yaml ]]; then
  em_source=$work/em_source
  "$apps/transhuman-synth" --config configs/synth/tiny.yaml --out "$em_source" --layout easymocap >/dev/null 2>&1 ||
    { echo "hostile: cannot generate the tiny EasyMocap capture" >&2; failures=$((failures + 1)); }
fi
# em NAME: a copy of the EasyMocap capture to damage; prints its path.
em() {
  rm -rf "$work/$1"
  cp -r "$em_source" "$work/$1"
  echo "$work/$1"
}
me=$em_source/$person
summary_psnr() { "$py" -c 'import json, sys; print(json.load(open(sys.argv[1]))["psnr"])' "$1" 2>/dev/null; }
eval_em=("${evaluate[@]}" eval.limit=2)
"${eval_em[@]}" $(on "$em_source") --out "$work/em_base" >/dev/null 2>&1
base_psnr=$(summary_psnr "$work/em_base/summary.json")
verdict "the capture as written (the baseline of this group)" "PSNR $base_psnr" $([[ -n $base_psnr ]]; echo $?)

# ---- files nested or sized to exhaust a parser -------------------------------------------------
d=$(em deep_poses)
"$py" - "$d/$person/output/smpl" <<'EOF'
import glob, json, sys
for f in sorted(glob.glob(sys.argv[1] + '/*.json')):
    people = json.load(open(f))
    text = json.dumps(people)
    deep = '[' * 1000000 + '0' + ']' * 1000000
    open(f, 'w').write(text.replace(json.dumps(people[0]['poses']), deep, 1))
EOF
fit=$(ls "$d/$person/output/smpl/"*.json | head -1)
check "SMPL JSON: 'poses' nested 1,000,000 deep" 2 "$d/$person/output/smpl/ && key 'poses' nests more than 8 levels deep" \
  "${eval_em[@]}" $(on "$d") --out "$work/e_deep_poses"
d=$(em deep_unused)
"$py" - "$d/$person/output/smpl" <<'EOF'
import glob, json, sys
for f in sorted(glob.glob(sys.argv[1] + '/*.json')):
    text = json.dumps(json.load(open(f))[0])
    open(f, 'w').write('{"junk": ' + '[' * 1000000 + ']' * 1000000 + ', ' + text[1:])
EOF
check "SMPL JSON: an unused key nested 1,000,000 deep" 2 "key 'junk' nests more than 8 levels deep" \
  "${eval_em[@]}" $(on "$d") --out "$work/e_deep_unused"
d=$(em big_fit)
for f in "$d/$person/output/smpl/"*.json; do truncate -s 170M "$f"; done
check "SMPL JSON of 170 MB (refused before it is read)" 2 "bytes, more than an SMPL fit file may be (8388608)" \
  "${eval_em[@]}" $(on "$d") --out "$work/e_big_fit"
d=$(em deep_intri)
"$py" - "$d/$person/intri.yml" <<'EOF'
import sys
text = open(sys.argv[1]).read()
open(sys.argv[1], 'w').write(text + 'junk: ' + '[' * 200000 + ']' * 200000 + '\n')
EOF
check "intri.yml: a key nested 200,000 deep (OpenCV's parser would recurse)" 2 "intri.yml' nests 200000 levels deep, more than a calibration file may (64" \
  "${eval_em[@]}" $(on "$d") --out "$work/e_deep_intri"
d=$(em deep_block)
"$py" - "$d/$person/extri.yml" <<'EOF'
import sys
text = open(sys.argv[1]).read()
open(sys.argv[1], 'w').write(text + 'junk:\n' + ''.join(' ' * i + 'a:\n' for i in range(1, 300)) + ' ' * 300 + 'a: 1\n')
EOF
check "extri.yml: block nesting 300 deep" 2 "extri.yml' nests 300 levels deep" \
  "${eval_em[@]}" $(on "$d") --out "$work/e_deep_block"
d=$(em big_intri)
truncate -s 2M "$d/$person/intri.yml"
check "intri.yml of 2 MiB" 2 "intri.yml' is 2097152 bytes, more than a calibration file may be (1048576)" \
  "${eval_em[@]}" $(on "$d") --out "$work/e_big_intri"

# ---- masks: any bit depth, alpha, and none ----------------------------------------------------
# masks D KIND: rewrite the person's masks: u16_255, u16_1, rgba (alpha only), blank (camera 00 of
# the first frame all zero).
masks() {
  "$py" - "$1/$person/mask" "$2" <<'EOF'
import glob, sys, numpy as np, cv2
root, kind = sys.argv[1:3]
files = sorted(glob.glob(root + '/*/*.png'))
for f in files:
    m = cv2.imread(f, cv2.IMREAD_UNCHANGED)
    on = m != 0
    if kind == 'u16_255':
        cv2.imwrite(f, (on * 255).astype(np.uint16))
    elif kind == 'u16_1':
        cv2.imwrite(f, on.astype(np.uint16))
    elif kind == 'rgba':
        out = np.zeros(on.shape + (4,), np.uint8)
        out[..., 3] = on * 255
        cv2.imwrite(f, out)
if kind == 'blank':
    for f in glob.glob(root + '/*/*.png'):
        m = cv2.imread(f, cv2.IMREAD_UNCHANGED)
        cv2.imwrite(f, np.zeros_like(m))
EOF
}
for kind in u16_255 u16_1 rgba; do
  d=$(em "mask_$kind") && masks "$d" "$kind"
  "${eval_em[@]}" $(on "$d") --out "$work/e_mask_$kind" >"$work/e_mask_$kind.log" 2>&1
  psnr=$(summary_psnr "$work/e_mask_$kind/summary.json")
  verdict "masks as $kind PNGs: the same scores as 8-bit masks" "PSNR ${psnr:-none} (8-bit: $base_psnr)" \
    $([[ -n $psnr && $psnr == "$base_psnr" ]]; echo $?)
done
d=$(em mask_blank) && masks "$d" blank
check "reference masks marking no person pixel" 2 "its mask '$d/$person/mask/ && marks no person pixel" \
  "${eval_em[@]}" $(on "$d") --out "$work/e_mask_blank"
d=$(em mask_loop)
mask=$(ls "$d/$person/mask/"*/*.png | head -1)
rm "$mask" && ln -s "$(basename "$mask")" "$mask"
check "a mask that is a link to itself (a loop)" 2 "cannot use '$mask': Too many levels of symbolic links" \
  "${eval_em[@]}" $(on "$d") --out "$work/e_mask_loop" eval.limit=0
d=$(em smpl_loop)
fit=$(ls "$d/$person/output/smpl/"*.json | head -1)
rm "$fit" && ln -s "$(basename "$fit")" "$fit"
check "an SMPL fit that is a link to itself" 2 "cannot use '$fit': Too many levels of symbolic links" \
  "${eval_em[@]}" $(on "$d") --out "$work/e_smpl_loop"

# ---- EasyMocap's own variants: read as EasyMocap reads them -------------------------------------
# calib D KIND: dist4 (1x4 distortion, k3 dropped), numbers (cameras named 1..N, written as bare
# numbers), shuffled (extri.yml lists the cameras in another order).
calib() {
  "$py" - "$1/$person" "$2" <<'EOF'
import os, sys, random, cv2
folder, kind = sys.argv[1:3]
def read(name):
    fs = cv2.FileStorage(os.path.join(folder, name), cv2.FILE_STORAGE_READ)
    names = [fs.getNode('names').at(i).string() for i in range(fs.getNode('names').size())]
    mats = {k: fs.getNode(k).mat() for k in fs.root().keys() if k != 'names'}
    return names, mats
def write(name, names, mats, numeric=False):
    fs = cv2.FileStorage(os.path.join(folder, name), cv2.FILE_STORAGE_WRITE)
    fs.startWriteStruct('names', cv2.FileNode_SEQ)
    for n in names:
        fs.write('', int(n) if numeric else n)
    fs.endWriteStruct()
    for k, m in mats.items():
        fs.write(k, m)
    fs.release()
inames, intri = read('intri.yml')
enames, extri = read('extri.yml')
if kind == 'dist4':
    for k in list(intri):
        if k.startswith('dist_'):
            intri[k] = intri[k].reshape(-1)[:4].reshape(1, 4)
    write('intri.yml', inames, intri)
elif kind == 'shuffled':
    random.Random(3).shuffle(enames)
    write('extri.yml', enames, extri)
elif kind == 'numbers':
    new = {n: str(i + 1) for i, n in enumerate(inames)}
    def rename(mats):
        out = {}
        for k, m in mats.items():
            head, _, cam = k.rpartition('_')
            out[head + '_' + new[cam]] = m
        return out
    write('intri.yml', [new[n] for n in inames], rename(intri), numeric=True)
    write('extri.yml', [new[n] for n in enames], rename(extri), numeric=True)
    for sub in ('images', 'mask', 'masks'):
        for n in inames:
            p = os.path.join(folder, sub, n)
            if os.path.isdir(p):
                os.rename(p, os.path.join(folder, sub, '_' + new[n]))
        for n in inames:
            p = os.path.join(folder, sub, '_' + new[n])
            if os.path.isdir(p):
                os.rename(p, os.path.join(folder, sub, new[n]))
EOF
}
d=$(em dist4) && calib "$d" dist4
check_out "dist_<c> written as 1x4 (EasyMocap's write_intri allows it): read as k3 = 0" "eval: " \
  "${eval_em[@]}" $(on "$d") --out "$work/e_dist4"
d=$(em shuffled) && calib "$d" shuffled
"${eval_em[@]}" $(on "$d") --out "$work/e_shuffled" >/dev/null 2>&1
psnr=$(summary_psnr "$work/e_shuffled/summary.json")
verdict "extri.yml listing the cameras in another order: the same scores" "PSNR ${psnr:-none} (as written: $base_psnr)" \
  $([[ -n $psnr && $psnr == "$base_psnr" ]]; echo $?)
d=$(em numbers) && calib "$d" numbers
grep -q -- '- 1$' "$d/$person/intri.yml"
verdict "  ... names written as bare numbers (- 1)" "$(grep -m1 -- '- 1$' "$d/$person/intri.yml")" $?
"${eval_em[@]}" $(on "$d") data.split_file= eval.setting=identity --out "$work/e_numbers" >"$work/e_numbers.log" 2>&1
verdict "cameras named 1..23 as bare numbers: read" "exit $?, $(grep -o 'reference cameras [^:]*' "$work/e_numbers.log" | head -1)" \
  $([[ -f $work/e_numbers/summary.json ]]; echo $?)

# ---- duplicate choices --------------------------------------------------------------------------
check "--reference-views 0,1,2 with cameras named 1..23 (index 0 is camera '1')" 2 \
  "camera '1' is chosen twice as a reference view (entry 0 '0' is index 0, entry 1 '1' is its name)" \
  "${eval_em[@]}" $(on "$d") --out "$work/e_dup012" --reference-views 0,1,2
check "--reference-views 00,00,08" 2 "camera '00' is chosen twice as a reference view (entry 0 '00' is its name, entry 1 '00' is its name)" \
  "${eval_em[@]}" $(on "$em_source") --out "$work/e_dup00" --reference-views 00,00,08
check "data.reference_views=[&a \"03\", *a, \"09\"] (a YAML alias)" 2 "data.reference_views: && camera '03' is chosen twice" \
  "${eval_em[@]}" $(on "$em_source") --out "$work/e_alias" 'data.reference_views=[&a "03", *a, "09"]'
d=$(copy split_dup)
"$py" - "$d/split.yaml" <<'EOF'
import re, sys
text = open(sys.argv[1]).read()
text, n = re.subn(r'reference_views: \[(\w+), (\w+), (\w+)\]', r'reference_views: [\1, \1, \3]', text)
assert n > 0, 'no fixed reference_views in the split'
open(sys.argv[1], 'w').write(text)
EOF
check "a split file naming a reference camera twice" 2 "reference_views: && is chosen twice as a reference view" \
  "${evaluate[@]}" $(on "$d") --out "$work/e_split_dup"
d=$(em same_ids)
"$py" - "$d/$person/output/smpl" <<'EOF'
import glob, json, sys
for f in glob.glob(sys.argv[1] + '/*.json'):
    people = json.load(open(f))
    people.append(dict(people[0]))
    json.dump(people, open(f, 'w'))
EOF
check "two people with the same id in the SMPL fit" 2 "people [0] and [1] have the same id" \
  "${eval_em[@]}" $(on "$d") --out "$work/e_same_ids" data.person_id=0

# ---- the options that choose cameras -----------------------------------------------------------
check "--reference-views '' (no camera)" 2 "--reference-views '': no camera named" \
  "${eval_em[@]}" $(on "$em_source") --out "$work/e_refs_empty" --reference-views ''
check "--reference-views under a setting that draws references at random" 2 \
  "data.reference_views (--reference-views) fixes the reference cameras, but && draws 3 at random per sample" \
  "${eval_em[@]}" $(on "$em_source") --out "$work/e_refs_random" --setting training --reference-views 00,08,15
check "data.num_reference_views=64 on 21-23 cameras (no split)" 2 "config key 'data.num_reference_views' = 64 && has only 2" \
  "${eval_em[@]}" $(on "$em_source") data.split_file= --out "$work/e_refs_64" data.num_reference_views=64
render_em=("$apps/transhuman-render" "${tiny[@]}" --checkpoint "$ckpt" --width 16 --height 16)
check_out "render --camera 04 (a camera's name): the log names the camera" "camera '04' (index 4)" \
  "${render_em[@]}" $(on "$em_source") --camera 04 --out "$work/r_camera04"
check "render --dry-run --camera nobody" 2 "--camera: CoreView_s03 has no camera 'nobody' (its cameras: 00, 01" \
  "${render_em[@]}" $(on "$em_source") --camera nobody --dry-run

# ---- few cameras, cameras of another size -------------------------------------------------------
# keep D N: only the first N cameras of the capture (no split file).
keep() {
  "$py" - "$1/$person" "$2" <<'EOF'
import os, sys, shutil, cv2
folder, n = sys.argv[1], int(sys.argv[2])
for name in ('intri.yml', 'extri.yml'):
    fs = cv2.FileStorage(os.path.join(folder, name), cv2.FILE_STORAGE_READ)
    names = [fs.getNode('names').at(i).string() for i in range(fs.getNode('names').size())]
    mats = {k: fs.getNode(k).mat() for k in fs.root().keys() if k != 'names'}
    out = cv2.FileStorage(os.path.join(folder, name), cv2.FILE_STORAGE_WRITE)
    out.write('names', names[:n])
    for k, m in mats.items():
        if k.rpartition('_')[2] in names[:n]:
            out.write(k, m)
    out.release()
    for c in names[n:]:
        for sub in ('images', 'mask', 'masks'):
            shutil.rmtree(os.path.join(folder, sub, c), ignore_errors=True)
EOF
  rm -f "$1/split.yaml"
  find "$1" -mindepth 1 -maxdepth 1 -type d ! -name "$person" -exec rm -rf {} +
}
d=$(em two_cameras) && keep "$d" 2
check_out "render --orbit 2 on a 2-camera capture (2 references)" "2 frames (2 rendered" \
  "${render_em[@]}" data.root="$d" data.split_file= data.num_reference_views=2 --orbit 2 --view 0 --out "$work/r_two"
d=$(em three_cameras) && keep "$d" 3
check_out "render --orbit 2 on a 3-camera capture (every camera a reference)" "2 frames (2 rendered" \
  "${render_em[@]}" data.root="$d" data.split_file= --orbit 2 --view 0 --out "$work/r_three"
check "eval on it: no target view" 2 "has no camera left as a target besides its 3 reference views" \
  "${eval_em[@]}" data.root="$d" data.split_file= --out "$work/e_three"
d=$(em sizes)
"$py" - "$d/$person" <<'EOF'
import glob, os, sys, numpy as np, cv2
folder = sys.argv[1]
fs = cv2.FileStorage(os.path.join(folder, 'intri.yml'), cv2.FILE_STORAGE_READ)
names = [fs.getNode('names').at(i).string() for i in range(fs.getNode('names').size())]
mats = {k: fs.getNode(k).mat() for k in fs.root().keys() if k != 'names'}
for cam in names[:1]:
    for f in glob.glob(os.path.join(folder, 'images', cam, '*')) + glob.glob(os.path.join(folder, 'mask', cam, '*')):
        im = cv2.imread(f, cv2.IMREAD_UNCHANGED)
        cv2.imwrite(f, cv2.resize(im, (im.shape[1] * 2, im.shape[0] * 2), interpolation=cv2.INTER_NEAREST))
    mats['K_' + cam][:2] *= 2
out = cv2.FileStorage(os.path.join(folder, 'intri.yml'), cv2.FILE_STORAGE_WRITE)
out.write('names', names)
for k, m in mats.items():
    out.write(k, m)
out.release()
EOF
check "a reference camera of another image size" 2 "reference view && (camera '08') is && but reference view && (camera '00') is && share one image size" \
  "${eval_em[@]}" $(on "$d") --out "$work/e_sizes" --reference-views 00,08,15
