# Hostile cases, group checkpoints (sourced by scripts/hostile.sh; scripts/hostile/lib.sh has the helpers).
# Damaged and foreign checkpoints, weights whose output overflows, resources checked first.

# ---- 3. checkpoints ------------------------------------------------------------------------------
"$py" - "$ckpt" "$work/cut.pt" <<'EOF'
import sys, zipfile
src, dst = sys.argv[1:3]
with zipfile.ZipFile(src) as z:
    members = [(i, z.read(i)) for i in z.infolist()]
big = max((m for m in members if '/data/' in m[0].filename), key=lambda m: len(m[1]))[0].filename
with zipfile.ZipFile(dst, 'w', zipfile.ZIP_STORED) as z:
    for info, data in members:
        z.writestr(info.filename, data[: len(data) // 2] if info.filename == big else data)
EOF
check "storage record truncated inside a valid zip" 2 "cut.pt/archive/data/ && elements of 4 bytes are claimed (a truncated or corrupt record)" \
  "$apps/transhuman-eval" "${tiny[@]}" $(on "$data") --checkpoint "$work/cut.pt" --out "$work/e_cut"
"$py" - "$ckpt" "$work/garbage_code.pt" <<'EOF'
import sys, zipfile
src, dst = sys.argv[1:3]
with zipfile.ZipFile(src) as z, zipfile.ZipFile(dst, 'w', zipfile.ZIP_STORED) as out:
    for i in z.infolist():
        out.writestr(i.filename, b'def (((garbage\x00\xff' if '/code/' in i.filename else z.read(i))
EOF
check "garbage code/ entry" 2 "checkpoint '$work/garbage_code.pt' cannot be read: Expected PROTO opcode" \
  "$apps/transhuman-eval" "${tiny[@]}" $(on "$data") --checkpoint "$work/garbage_code.pt" --out "$work/e_code"
"$py" - "$ckpt" "$work/deflated.pt" <<'EOF'
import sys, zipfile
src, dst = sys.argv[1:3]
with zipfile.ZipFile(src) as z, zipfile.ZipFile(dst, 'w', zipfile.ZIP_DEFLATED) as out:
    for i in z.infolist():
        out.writestr(i.filename, z.read(i))
EOF
check "deflated (repacked) checkpoint" 2 "compressed storage record" \
  "$apps/transhuman-eval" "${tiny[@]}" $(on "$data") --checkpoint "$work/deflated.pt" --out "$work/e_defl"
"$py" - "$work" <<'EOF'
import sys, zipfile, collections, torch
work = sys.argv[1]
# A 2 MB deflate bomb that claims 2.3 GB: a zip of one compressed member.
with zipfile.ZipFile(work + '/bomb.pth', 'w', zipfile.ZIP_DEFLATED) as z:
    with z.open('archive/data.pkl', 'w', force_zip64=True) as f:
        chunk = bytes(1 << 24)
        for _ in range(140):
            f.write(chunk)
class View:  # a tensor view that torch.save pickles as _rebuild_tensor_v2(storage, ...)
    def __init__(self, storage, offset, size, stride):
        self.args = (storage, offset, size, stride)
    def __reduce__(self):
        s, o, size, stride = self.args
        return (torch._utils._rebuild_tensor_v2, (s, o, size, stride, False, collections.OrderedDict()))
storage = torch.zeros(4).storage()
torch.save({'net': {'x': View(storage, 0, (1 << 30,), (0,))}}, work + '/stride0.pth')
torch.save({'net': {'x': View(storage, 3, (4,), (-1,))}}, work + '/negative.pth')
torch.save({'net': {'x': View(storage, 0, (100,), (1,))}}, work + '/past_end.pth')
EOF
check "deflate bomb (2 MB claiming 2.3 GB)" 2 "a compressed member claiming" \
  "$apps/transhuman-eval" "${tiny[@]}" $(on "$data") --checkpoint "$work/bomb.pth" --out "$work/e_bomb"
check "stride-0 view of 2^30 elements (.pth)" 2 "overlapping" \
  "$apps/transhuman-eval" "${tiny[@]}" $(on "$data") --checkpoint "$work/stride0.pth" --out "$work/e_s0"
check "negative stride (.pth)" 2 "negative" \
  "$apps/transhuman-eval" "${tiny[@]}" $(on "$data") --checkpoint "$work/negative.pth" --out "$work/e_neg"
check "view past its storage (.pth)" 2 "needs 100 elements" \
  "$apps/transhuman-eval" "${tiny[@]}" $(on "$data") --checkpoint "$work/past_end.pth" --out "$work/e_past"
check "checkpoint of transhe.depth=2" 2 "model.transhe.depth: checkpoint 2, config 1" \
  "$apps/transhuman-eval" "${tiny[@]}" $(on "$data") --checkpoint "$work/deep/checkpoints/latest.pt" --out "$work/e_deep"
check "checkpoint of another representation (spc)" 2 "model.representation: checkpoint spc_trilinear" \
  "$apps/transhuman-eval" "${tiny[@]}" $(on "$data") --checkpoint "$work/spc/checkpoints/latest.pt" --out "$work/e_spc"
for key in model.dparf.nk=2 model.grouping.num_tokens=20 model.dparf.coordinate=absolute model.fdi.raw_rgb=false; do
  check "evaluated with $key" 2 "${key%%=*}: checkpoint" \
    "$apps/transhuman-eval" "${tiny[@]}" $(on "$data") --checkpoint "$ckpt" --out "$work/e_${key//[.=]/_}" "$key"
done
check "evaluated with model.dparf.nk=2 and eval.model_mismatch=warn" 0 \
  "was trained with other model settings: model.dparf.nk: checkpoint 3, config 2" "$apps/transhuman-eval" "${tiny[@]}" $(on "$data") --checkpoint "$ckpt" --out "$work/e_warn" model.dparf.nk=2 \
  eval.model_mismatch=warn eval.limit=1

# ---- 4. resources are checked before work starts --------------------------------------------------
check "--threads 100000" 2 "--threads: must be in [0, 4096], not 100000" "$apps/transhuman-render" --threads 100000
check "threads: 100000 in the config" 2 "config key 'threads' = 100000: must be in [0, 4096] (CPU threads for LibTorch; 0: one per core)" \
  "$apps/transhuman-train" "${tiny[@]}" $(on "$data") --dry-run threads=100000
check "mesh --voxel 1e-4 (a 10^11-point grid)" 2 "estimated peak memory" \
  "$apps/transhuman-mesh" "${tiny[@]}" $(on "$data") --checkpoint "$ckpt" --out "$work/m1" --voxel 1e-4 max_memory_gb=4
check "render 20000 x 20000" 2 "render 20000 x 20000" \
  "$apps/transhuman-render" "${tiny[@]}" $(on "$data") --checkpoint "$ckpt" --out "$work/r1" --width 20000 \
  --height 20000 max_memory_gb=4
check "mesh --threshold nan" 2 "--threshold: must be >= 0, not nan" "$apps/transhuman-mesh" --threshold nan
check "mesh --threshold -1" 2 "--threshold: must be >= 0, not -1" "$apps/transhuman-mesh" --threshold -1

# ---- 5b. finite weights whose output overflows ----------------------------------------------------
"$py" - "$ckpt" "$work/huge.pt" <<'EOF'
import sys, torch
m = torch.jit.load(sys.argv[1])
with torch.no_grad():
    for name, p in m.named_parameters():
        if name.startswith('model.heads.') and p.dim() == 2:
            p.mul_(1e30)
m.save(sys.argv[2])
EOF
check "finite weights x1e30 (output overflows)" 2 \
  "checkpoint '$work/huge.pt', $person frame && the network's output is not finite (" \
  "$apps/transhuman-eval" "${tiny[@]}" $(on "$data") --checkpoint "$work/huge.pt" --out "$work/e_huge" eval.limit=1
check "render with them" 2 "checkpoint '$work/huge.pt', $person frame && : the network's output is not finite (" \
  "$apps/transhuman-render" "${tiny[@]}" $(on "$data") --checkpoint "$work/huge.pt" --out "$work/r_huge" --orbit 1 \
  --width 16 --height 16
