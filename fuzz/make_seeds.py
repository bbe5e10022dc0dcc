"""Writes the small valid inputs the fuzz targets start from (scripts/fuzz.sh calls it).

Usage: make_seeds.py <out_dir>
Writes <out_dir>/zip/*.pth: reference-style checkpoints saved by the installed torch (to a path
and to a file object, whose records sit under 'archive/'; a state dict under 'net', a bare
state dict, views sharing a storage, several dtypes), each also as <name>.records (data.pkl and
the storages joined by "@@@@", the form fuzz/zip_fuzz.cpp zips itself), and <out_dir>/camera_path/*: camera path
files in YAML and JSON (an orbit of real rotations, 3x3 and 9-number forms). The pickle/.npy/.npz
seeds come from tests/python/make_io_fixtures.py, the config seeds are configs/*.yaml.
"""
import collections
import io
import json
import math
import os
import sys
import zipfile

import torch


def save_pth(out, name, obj, to_buffer=False):
    path = os.path.join(out, name)
    if to_buffer:
        buffer = io.BytesIO()
        torch.save(obj, buffer)
        with open(path, "wb") as f:
            f.write(buffer.getvalue())
    else:
        torch.save(obj, path)


def save_records(path):
    # The records form fuzz/zip_fuzz.cpp zips itself: data.pkl, then data/0, data/1, ...
    with zipfile.ZipFile(path) as z:
        names = {n.split("/", 1)[1]: n for n in z.namelist()}
        parts = [z.read(names["data.pkl"])]
        k = 0
        while "data/%d" % k in names:
            parts.append(z.read(names["data/%d" % k]))
            k += 1
    with open(path[:-len(".pth")] + ".records", "wb") as f:
        f.write(b"@@@@".join(parts))


def pth_seeds(out):
    os.makedirs(out, exist_ok=True)
    net = collections.OrderedDict()
    net["fc_0.weight"] = torch.arange(6, dtype=torch.float32).reshape(2, 3)
    net["fc_0.bias"] = torch.tensor([0.5, -1.0])
    save_pth(out, "tiny.pth", {"net": net, "epoch": 3})
    save_pth(out, "tiny_buffer.pth", {"net": net, "epoch": 3}, to_buffer=True)
    save_pth(out, "bare.pth", net)
    base = torch.arange(12, dtype=torch.float64).reshape(3, 4)
    views = collections.OrderedDict()
    views["t"] = base.t()
    views["row"] = base[1]
    views["col"] = base[:, 2]
    save_pth(out, "views.pth", {"net": views})
    dtypes = collections.OrderedDict()
    for dtype in (torch.float16, torch.bfloat16, torch.int8, torch.uint8, torch.int16,
                  torch.int32, torch.int64, torch.bool):
        dtypes[str(dtype)] = torch.arange(4).to(dtype)
    save_pth(out, "dtypes.pth", {"net": dtypes, "optim": {"lr": 5e-4}, "nested": {"a": {"b": 1}}})
    save_pth(out, "parameter.pth", {"net": {"w": torch.nn.Parameter(torch.ones(2, 2))}})
    for name in sorted(os.listdir(out)):
        if name.endswith(".pth"):
            save_records(os.path.join(out, name))


def rotation(theta):
    # Looking at the origin from a circle of radius 3 (world z up, OpenCV camera axes).
    c, s = math.cos(theta), math.sin(theta)
    z = [-c, -s, 0.0]
    x = [-s, c, 0.0]
    y = [z[1] * x[2] - z[2] * x[1], z[2] * x[0] - z[0] * x[2], z[0] * x[1] - z[1] * x[0]]
    return [x, y, z]


def camera_seeds(out):
    os.makedirs(out, exist_ok=True)
    K = [[500.0, 0.0, 256.0], [0.0, 500.0, 256.0], [0.0, 0.0, 1.0]]
    cameras = []
    for k in range(3):
        R = rotation(2 * math.pi * k / 3)
        cameras.append({"K": K, "R": R, "T": [0.0, 0.0, 3.0]})
    with open(os.path.join(out, "orbit.json"), "w") as f:
        json.dump({"width": 512, "height": 512, "cameras": cameras}, f)
    with open(os.path.join(out, "orbit.yaml"), "w") as f:
        f.write("# x_cam = R x_world + T\nwidth: 512\nheight: 512\ncameras:\n")
        for c in cameras:
            f.write("  - K: %s\n    R: %s\n    T: %s\n" % (c["K"], c["R"], c["T"]))
    with open(os.path.join(out, "flat.yaml"), "w") as f:
        f.write("cameras:\n  - {K: [500, 0, 256, 0, 500, 256, 0, 0, 1], "
                "R: [1, 0, 0, 0, 1, 0, 0, 0, 1], T: [0, 0, 2.5]}\n")


def main():
    out = sys.argv[1]
    pth_seeds(os.path.join(out, "zip"))
    camera_seeds(os.path.join(out, "camera_path"))


if __name__ == "__main__":
    main()
