#!/usr/bin/env python3
"""Converts LPIPS-VGG v0.1 weights into the .npz that transhuman-train/-eval load (METHOD 5, 6).

Run once, where torchvision's VGG16 ImageNet weights and the LPIPS v0.1 linear layers exist:

    python3 scripts/export_lpips.py --vgg vgg16-397923af.pth --lin lpips/weights/v0.1/vgg.pth \
        --out weights/lpips_vgg.npz

--vgg: torchvision's vgg16 state dict (default: torchvision's cache, if the weights are there).
--lin: the lpips package's weights/v0.1/vgg.pth (keys lin{0..4}.model.1.weight).
--random-seed N: random weights instead (tests: VGG16 init of torchvision + uniform lin layers).
Both files are read as weights only (scripts/weights_file.py): a file that holds anything but
tensors is refused with one line and exit status 2, and nothing of it is run.
Also usable as a module: reference_lpips() is the plain formula the C++ test compares against.
"""
import argparse

import numpy as np
import torch
import torchvision

from weights_file import fail, load_weights

CONV_INDICES = [0, 2, 5, 7, 10, 12, 14, 17, 19, 21, 24, 26, 28]
SLICE_ENDS = [4, 9, 16, 23, 30]  # features[:4] -> relu1_2, ..., features[23:30] -> relu5_3
CHANNELS = [64, 128, 256, 512, 512]


def build(vgg_path=None, lin_path=None, random_seed=None):
    if random_seed is not None:
        torch.manual_seed(random_seed)
        vgg = torchvision.models.vgg16(weights=None)
        lins = [torch.rand(1, c, 1, 1) for c in CHANNELS]
    else:
        lin_state = load_weights(lin_path, "--lin")
        keys = [f"lin{i}.model.1.weight" for i in range(5)]
        if not isinstance(lin_state, dict) or any(not isinstance(lin_state.get(k), torch.Tensor) for k in keys):
            fail(f"--lin '{lin_path}' is not the LPIPS v0.1 vgg.pth: it needs the tensors {', '.join(keys)}")
        lins = [lin_state[k] for k in keys]
        if vgg_path:
            vgg = torchvision.models.vgg16(weights=None)
            state = load_weights(vgg_path, "--vgg")
            try:
                vgg.load_state_dict(state)
            except (RuntimeError, TypeError, AttributeError) as e:
                fail(f"--vgg '{vgg_path}' is not torchvision's vgg16 state dict: {str(e).strip().splitlines()[0]}")
        else:
            try:
                vgg = torchvision.models.vgg16(weights=torchvision.models.VGG16_Weights.IMAGENET1K_V1)
            except Exception as e:  # noqa: BLE001: no network, no cache
                fail(f"cannot get torchvision's VGG16 weights (give them with --vgg): {str(e).strip().splitlines()[0]}")
    return vgg.features.eval(), lins


def export(features, lins, out):
    arrays = {}
    for i in CONV_INDICES:
        arrays[f"features.{i}.weight"] = features[i].weight.detach().numpy().astype(np.float32)
        arrays[f"features.{i}.bias"] = features[i].bias.detach().numpy().astype(np.float32)
    for i, w in enumerate(lins):
        arrays[f"lin{i}.weight"] = w.detach().numpy().astype(np.float32)
    np.savez(out, **arrays)


def reference_lpips(features, lins, a, b):
    """LPIPS v0.1 of (B, 3, H, W) images in [-1, 1]: the formula of METHOD 5."""
    shift = torch.tensor([-.030, -.088, -.188]).view(1, 3, 1, 1)
    scale = torch.tensor([.458, .448, .450]).view(1, 3, 1, 1)
    x, y = (a - shift) / scale, (b - shift) / scale
    total, start = 0, 0
    for end, lin in zip(SLICE_ENDS, lins):
        for layer in features[start:end]:
            x, y = layer(x), layer(y)
        start = end
        nx = x / (torch.sqrt((x ** 2).sum(1, keepdim=True) + 1e-10) + 1e-10)
        ny = y / (torch.sqrt((y ** 2).sum(1, keepdim=True) + 1e-10) + 1e-10)
        total = total + torch.nn.functional.conv2d((nx - ny) ** 2, lin).mean((1, 2, 3))
    return total


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--vgg")
    p.add_argument("--lin")
    p.add_argument("--random-seed", type=int)
    p.add_argument("--out", required=True)
    args = p.parse_args()
    if args.random_seed is None and not args.lin:
        p.error("--lin (the LPIPS v0.1 vgg.pth) is required unless --random-seed is given")
    features, lins = build(args.vgg, args.lin, args.random_seed)
    try:
        export(features, lins, args.out)
    except OSError as e:
        fail(f"cannot write --out '{args.out}': {e.strerror or e}")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
