"""scikit-image's SSIM and numpy's PSNR on images written by the C++ test.

Usage: ssim_reference.py DIR
DIR/pairs.txt has one line "h w" per image pair; pair i is stored as raw float64 little-endian
files DIR/a_<i>.bin and DIR/b_<i>.bin of shape (h, w, 3). Writes DIR/ssim.txt: "ssim psnr" per
pair, with the protocol's settings (METHOD 6).
"""
import sys

import numpy as np
from skimage.metrics import structural_similarity

d = sys.argv[1]
out = []
with open(f"{d}/pairs.txt") as f:
    for i, line in enumerate(f):
        h, w = map(int, line.split())
        a = np.fromfile(f"{d}/a_{i}.bin", dtype="<f8").reshape(h, w, 3)
        b = np.fromfile(f"{d}/b_{i}.bin", dtype="<f8").reshape(h, w, 3)
        s = structural_similarity(a, b, channel_axis=2, data_range=2.0)
        mse = np.mean((a - b) ** 2)
        psnr = -10 * np.log(mse) / np.log(10)
        out.append(f"{s:.17g} {psnr:.17g}")
with open(f"{d}/ssim.txt", "w") as f:
    f.write("\n".join(out) + "\n")
