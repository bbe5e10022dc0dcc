#!/usr/bin/env bash
# configs/zju_mocap.yaml on a ZJU-MoCap-layout fixture (the tiny synthetic people, written in that
# layout): a dry run refuses the missing weight files with the command that makes each, then, with
# the files made by scripts/export_pretrained.py and scripts/export_lpips.py, prints the protocol,
# the sizes and the files it needs; eval refuses a missing eval.lpips_weights the same way.
# Usage: check_real_data_config.sh APPS_DIR TINY_DATA WORK [PYTHON]
set -uo pipefail
apps=$(cd "$1" && pwd)
data=$(cd "$2" && pwd)
work=$3
python=${4:-python3}
src=$(cd "$(dirname "$0")/../.." && pwd)
rm -rf "$work"
mkdir -p "$work"
cd "$work" || exit 1
failures=0
fail() { echo "FAIL: $*"; failures=$((failures + 1)); }

# The fixture's own split and body model (NHP's frame ranges exceed its 4 frames); the rest is the
# config's: the weight files at its relative paths, here under $work.
fixture=(data.root="$data" data.split_file="$data/split.yaml" data.smpl_model="$data/smpl_model.npz"
         model.grouping.cache_dir="$work/cache")
train() { "$apps/transhuman-train" --config "$src/configs/zju_mocap.yaml" --dry-run "${fixture[@]}" "$@"; }

out=$(train 2>&1); rc=$?
echo "--- without the weight files (exit $rc)"; echo "$out" | tail -4
[[ $rc == 2 ]] || fail "exit $rc without the encoder weights, expected 2"
grep -q "model.encoder.pretrained: 'weights/resnet18_imagenet.npz' does not exist" <<<"$out" || fail "the encoder key is not named"
grep -q "python3 scripts/export_pretrained.py --torchvision --out weights/resnet18_imagenet.npz" <<<"$out" ||
  fail "the command that makes the encoder weights is not printed"

mkdir -p weights
"$python" - <<'PY' || fail "could not write a ResNet-18 state dict"
import torch, torchvision
torch.manual_seed(0)
torch.save(torchvision.models.resnet18().state_dict(), "resnet18_random.pth")
PY
"$python" "$src/scripts/export_pretrained.py" --weights resnet18_random.pth --out weights/resnet18_imagenet.npz \
  >/dev/null || fail "export_pretrained.py failed"

out=$(train 2>&1); rc=$?
echo "--- with the encoder weights only (exit $rc)"; echo "$out" | tail -3
[[ $rc == 2 ]] || fail "exit $rc without the LPIPS weights, expected 2"
grep -q "train.lpips_weights: 'weights/lpips_vgg.npz' does not exist" <<<"$out" || fail "the LPIPS key is not named"
grep -q "python3 scripts/export_lpips.py" <<<"$out" || fail "the command that makes the LPIPS weights is not printed"

"$python" "$src/scripts/export_lpips.py" --random-seed 0 --out weights/lpips_vgg.npz >/dev/null ||
  fail "export_lpips.py failed"
out=$(train 2>&1); rc=$?
echo "--- with both files (exit $rc)"; echo "$out"
[[ $rc == 0 ]] || fail "dry run exit $rc with every file present"
for want in "data: zju_mocap" "'training': [0-9]* samples from 2 humans" "'identity': sample 0 loaded" \
            "encoder: ImageNet ResNet-18 weights from weights/resnet18_imagenet.npz" \
            "a step: one target image, 6 patches of 20 x 20 rays, 64 samples per ray" \
            "LPIPS weights: training 'weights/lpips_vgg.npz', evaluation 'weights/lpips_vgg.npz'" \
            "token groups: canonical_kmeans num_tokens=300 seed=0" "3000 epochs x 500 iters"; do
  grep -q -- "$want" <<<"$out" || fail "the dry run does not print '$want'"
done

# Evaluation needs eval.lpips_weights (and not the encoder's ImageNet file: the checkpoint has it).
rm weights/lpips_vgg.npz weights/resnet18_imagenet.npz
out=$("$apps/transhuman-eval" --config "$src/configs/zju_mocap.yaml" --dry-run "${fixture[@]}" 2>&1); rc=$?
echo "--- eval without the LPIPS weights (exit $rc)"; echo "$out" | tail -3
[[ $rc == 2 ]] || fail "eval exit $rc without the LPIPS weights, expected 2"
grep -q "eval.lpips_weights: 'weights/lpips_vgg.npz' does not exist" <<<"$out" || fail "eval does not name eval.lpips_weights"
grep -q "model.encoder.pretrained" <<<"$out" && fail "eval asks for the encoder's ImageNet weights"

echo "$((failures == 0 ? 1 : 0)) passed, $((failures > 0 ? 1 : 0)) failed"
exit $((failures > 0))
