#!/usr/bin/python3
"""Converts torchvision's ImageNet ResNet-18 weights into the file TransHuman-C++ loads as
model.encoder.pretrained (METHOD 3.1): an .npz of torchvision's state dict names (conv1.weight,
bn1.running_mean, layer1.0.conv1.weight, ...; float32, num_batches_tracked int64). Only conv1,
bn1, layer1 and layer2 are used; the rest is written too and ignored.

Usage (Debian's python3 with python3-torch and python3-torchvision):
  scripts/export_pretrained.py --weights resnet18-f37072fd.pth --out data/resnet18_imagenet.npz
  scripts/export_pretrained.py --torchvision --out data/resnet18_imagenet.npz
--weights: a resnet18 state dict saved by torch (e.g. torchvision's download, found in
~/.cache/torch/hub/checkpoints/); --torchvision: let torchvision load (and, if needed, download)
the IMAGENET1K_V1 weights. --weights is read as weights only (scripts/weights_file.py): a file
that holds anything but tensors is refused with one line and exit status 2, and nothing of it is run.
"""
import argparse
import sys

import numpy as np
import torchvision

from weights_file import fail, load_weights


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("--weights", help="resnet18 state dict (.pth)")
    source.add_argument("--torchvision", action="store_true", help="use torchvision's IMAGENET1K_V1 weights")
    parser.add_argument("--out", required=True, help="output .npz")
    args = parser.parse_args()

    model = torchvision.models.resnet18()
    if args.weights:
        state = load_weights(args.weights, "--weights")
        if isinstance(state, dict) and "state_dict" in state:
            state = state["state_dict"]
        if not isinstance(state, dict):
            fail(f"--weights '{args.weights}' is not a state dict (it holds a {type(state).__name__})")
        try:
            missing, unexpected = model.load_state_dict(state, strict=False)
        except RuntimeError as e:
            fail(f"--weights '{args.weights}' is not a resnet18 state dict: {str(e).strip().splitlines()[0]}")
        needed = [k for k in missing if k.startswith(("conv1", "bn1", "layer1", "layer2"))]
        if needed:
            more = f", ... ({len(needed)} in all)" if len(needed) > 4 else ""
            fail(f"--weights '{args.weights}' is not a resnet18 state dict: it lacks {', '.join(needed[:4])}{more}")
        if unexpected:
            print(f"ignored: {', '.join(unexpected)}", file=sys.stderr)
    else:
        model = torchvision.models.resnet18(weights="IMAGENET1K_V1")
    arrays = {k: v.detach().cpu().numpy() for k, v in model.state_dict().items()}
    for k, v in arrays.items():
        arrays[k] = v.astype(np.int64) if k.endswith("num_batches_tracked") else v.astype(np.float32)
    try:
        np.savez(args.out, **arrays)
    except OSError as e:
        fail(f"cannot write --out '{args.out}': {e.strerror or e}")
    print(f"wrote {len(arrays)} tensors to {args.out}")


if __name__ == "__main__":
    main()
