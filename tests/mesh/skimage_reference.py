"""Reference meshes from scikit-image's marching cubes (Lewiner) for tests/mesh.

Usage: skimage_reference.py <out_dir> <noise>   (noise: std of added Gaussian noise)
Writes field.npy (D, H, W) float32, and for it at level 0.5 with spacing/origin below:
sk_verts.npy (V, 3) float64 world xyz, sk_area.npy (1,) float64.
"""
import sys

import numpy as np
from skimage import measure

out = sys.argv[1]
rng = np.random.default_rng(11)
D, H, W = 30, 34, 38
origin = np.array([0.1, -0.2, 0.3])     # world x, y, z of sample [0][0][0]
voxel = np.array([0.03, 0.025, 0.02])   # spacing along x, y, z

z, y, x = np.meshgrid(np.arange(D), np.arange(H), np.arange(W), indexing="ij")
field = np.zeros((D, H, W))
for _ in range(12):  # smooth blobs, some touching: saddles and ambiguous faces
    c = rng.uniform([6, 6, 6], [D - 6, H - 6, W - 6])
    s = rng.uniform(2.0, 5.0)
    field += np.exp(-((z - c[0]) ** 2 + (y - c[1]) ** 2 + (x - c[2]) ** 2) / (2 * s * s))
field += float(sys.argv[2]) * rng.standard_normal(field.shape)
field[:2], field[-2:], field[:, :2], field[:, -2:], field[:, :, :2], field[:, :, -2:] = (0,) * 6
field = field.astype(np.float32)

verts, faces, _, _ = measure.marching_cubes(
    field, level=0.5, spacing=tuple(voxel[::-1]), method="lewiner")
verts_xyz = verts[:, ::-1].astype(np.float64) + origin
np.save(f"{out}/field.npy", field)
np.save(f"{out}/sk_verts.npy", verts_xyz)
np.save(f"{out}/sk_area.npy", np.array([measure.mesh_surface_area(verts, faces)]))
