"""Independent near/far of METHOD 2.2 in numpy (the reference's algorithm, written from the spec).

Usage: near_far_reference.py rays.txt box.txt out.txt
rays.txt: N rows "ox oy oz dx dy dz"; box.txt: 2 rows "x y z" (min, max).
out.txt: N rows "valid near far".
"""
import sys

import numpy as np

rays = np.loadtxt(sys.argv[1], ndmin=2)
box = np.loadtxt(sys.argv[2])
o, d = rays[:, :3].copy(), rays[:, 3:].copy()
bounds = box + np.array([-0.01, 0.01])[:, None]
d[np.abs(d) < 1e-5] = 1e-5
t = ((bounds[None] - o[:, None]) / d[:, None]).reshape(-1, 6)
p = t[..., None] * d[:, None] + o[:, None]
eps = 1e-6
inside = np.all((p >= bounds[0] - eps) & (p <= bounds[1] + eps), axis=-1)
valid = inside.sum(-1) == 2
near = np.zeros(len(o))
far = np.zeros(len(o))
pts = p[valid][inside[valid]].reshape(-1, 2, 3)
norm = np.linalg.norm(d[valid], axis=1)
d0 = np.linalg.norm(pts[:, 0] - o[valid], axis=1) / norm
d1 = np.linalg.norm(pts[:, 1] - o[valid], axis=1) / norm
near[valid] = np.minimum(d0, d1)
far[valid] = np.maximum(d0, d1)
np.savetxt(sys.argv[3], np.stack([valid.astype(float), near, far], 1), fmt="%.17g")
