"""The reference implementation's orbit (gen_path of Neural Body / NHP render_utils),
transcribed with numpy, for tests/video: LLFF axis reordering, mean centre, 80th-percentile
radii x 1.3, viewmatrix, and back to world->camera. The one change METHOD 7 asks for: the camera
looks at `target` (the person) instead of the reference's offset point.

Usage: orbit_reference.py <dir>   reads R.npy (C,3,3), T.npy (C,3,1) metres, target.npy (3,),
                                  n.npy (1,); writes w2c.npy (n,4,4), radii.npy (3,)
"""
import sys

import numpy as np


def normalize(x):
    return x / np.linalg.norm(x)


def viewmatrix(z, up, pos):
    vec2 = normalize(z)
    vec1 = normalize(np.cross(vec2, up))
    vec0 = normalize(np.cross(vec1, vec2))
    return np.stack([vec0, vec1, vec2, pos], 1)


def gen_path(RT, target, n):
    lower_row = np.array([[0., 0., 0., 1.]])
    RT = np.concatenate([RT, np.tile(lower_row[None], (len(RT), 1, 1))], 1)
    RT = np.linalg.inv(RT)
    RT = np.concatenate([RT[:, :, 1:2], RT[:, :, 0:1], -RT[:, :, 2:3], RT[:, :, 3:4]], 2)
    up = normalize(RT[:, :3, 0].sum(0))
    z = normalize(RT[0, :3, 2])
    vec1 = normalize(np.cross(z, up))
    vec2 = normalize(np.cross(up, vec1))
    center = RT[:, :3, 3].mean(0)
    c2w = np.stack([up, vec1, vec2, center], 1)
    tt = np.matmul(c2w[:3, :3].T, (RT[:, :3, 3] - c2w[:3, 3])[..., None])[..., 0].T
    rads = np.percentile(np.abs(tt), 80, -1) * 1.3
    radii = rads.copy()
    rads = np.array(list(rads) + [1.])
    out = []
    for theta in np.linspace(0., 2 * np.pi, n + 1)[:-1]:
        cam_pos = np.array([0, np.sin(theta), np.cos(theta), 1] * rads)
        cam_pos_world = np.dot(c2w[:3, :4], cam_pos)
        mat = viewmatrix(cam_pos_world - target, up, cam_pos_world)
        mat = np.concatenate([mat[:, 1:2], mat[:, 0:1], -mat[:, 2:3], mat[:, 3:4]], 1)
        mat = np.concatenate([mat, lower_row], 0)
        out.append(np.linalg.inv(mat))
    return np.stack(out), radii


d = sys.argv[1]
R, T = np.load(f"{d}/R.npy"), np.load(f"{d}/T.npy")
w2c, radii = gen_path(np.concatenate([R, T], 2), np.load(f"{d}/target.npy"),
                      int(np.load(f"{d}/n.npy")[0]))
np.save(f"{d}/w2c.npy", w2c)
np.save(f"{d}/radii.npy", radii)
