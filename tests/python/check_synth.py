"""Checks a dataset written by transhuman-synth with numpy/scipy alone (no project code):
the ZJU-MoCap structure of METHOD 1.1, the body model files, the camera ring, and, for a dataset
generated with noise.enabled=false, that the published vertices projected with the published
cameras (and OpenCV's distortion model, implemented here) fall inside the masks.

usage: check_synth.py DATASET [--noise-free] [--ring RADIUS JITTER] [--resave DIR]
  --resave DIR: np.save copies of every annots.npy and of the first params file into DIR, as
                <human>_annots.npy / <human>_params.npy, for the C++ side to compare.
Exits 1 with a message on the first failed check.
"""
import argparse
import os
import pickle
import sys

import numpy as np
import scipy.ndimage
import scipy.sparse
from PIL import Image

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import numpy1_format  # noqa: E402  (np.save as numpy 1.x wrote it, under numpy 2 too)


def fail(msg):
    print("check_synth: FAILED: " + msg)
    sys.exit(1)


def expect(cond, msg):
    if not cond:
        fail(msg)


def check_model(root):
    npz = dict(np.load(os.path.join(root, "smpl_model.npz")))
    for k in ("v_template", "shapedirs", "posedirs", "J_regressor", "weights", "kintree_table", "f"):
        expect(k in npz, "smpl_model.npz lacks " + k)
    V = npz["v_template"].shape[0]
    expect(npz["v_template"].shape == (V, 3), "v_template shape")
    expect(npz["shapedirs"].shape == (V, 3, 10), "shapedirs shape %s" % (npz["shapedirs"].shape,))
    expect(npz["posedirs"].shape == (V, 3, 207), "posedirs shape")
    expect(not npz["posedirs"].any(), "posedirs should be zero")
    expect(npz["J_regressor"].shape == (24, V), "J_regressor shape")
    expect(np.allclose(npz["J_regressor"].sum(1), 1), "J_regressor rows must sum to 1")
    expect(np.allclose(npz["weights"].sum(1), 1), "weights rows must sum to 1")
    expect(list(npz["kintree_table"][0][1:]) ==
           [0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 20, 21],
           "kintree_table parents")
    height = npz["v_template"][:, 1].max() - npz["v_template"][:, 1].min()
    expect(1.6 < height < 1.9, "template height %.3f m" % height)
    with open(os.path.join(root, "smpl_model.pkl"), "rb") as f:
        pkl = pickle.load(f, encoding="latin1")
    expect(scipy.sparse.isspmatrix_csc(pkl["J_regressor"]), "pkl J_regressor is not a csc_matrix")
    expect(np.array_equal(pkl["J_regressor"].toarray(), npz["J_regressor"]), "pkl J_regressor differs")
    for k in ("v_template", "shapedirs", "posedirs", "weights", "kintree_table", "f"):
        expect(np.array_equal(pkl[k], npz[k]), "pkl %s differs from npz" % k)
    return V


def distort(xy, D):
    """OpenCV's lens model on normalised coordinates (k1, k2, p1, p2, k3)."""
    k1, k2, p1, p2, k3 = D.reshape(-1)[:5]
    x, y = xy[:, 0], xy[:, 1]
    r2 = x * x + y * y
    radial = 1 + k1 * r2 + k2 * r2 ** 2 + k3 * r2 ** 3
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return np.stack([xd, yd], 1)


def mask_of(human_dir, image_path):
    """Union of mask/ and mask_cihp/ (METHOD 2.1); None when neither exists."""
    stem = os.path.splitext(image_path)[0] + ".png"
    union = None
    for kind in ("mask", "mask_cihp"):
        p = os.path.join(human_dir, kind, stem)
        if os.path.exists(p):
            m = np.array(Image.open(p)) != 0
            union = m if union is None else (union | m)
    return union


def check_human(root, human, V, args):
    d = os.path.join(root, human)
    annots = np.load(os.path.join(d, "annots.npy"), allow_pickle=True).item()
    expect(isinstance(annots, dict) and set(annots) == {"cams", "ims"}, human + ": annots keys")
    cams = annots["cams"]
    expect(set(cams) == {"K", "R", "T", "D"}, human + ": cams keys")
    n = len(cams["K"])
    expect(n == (21 if human in ("CoreView_313", "CoreView_315") else 23) or args.any_cameras,
           human + ": %d cameras" % n)
    for key, shape in (("K", (3, 3)), ("R", (3, 3)), ("T", (3, 1)), ("D", (5, 1))):
        expect(len(cams[key]) == n, human + ": len(cams[%s])" % key)
        for a in cams[key]:
            expect(isinstance(a, np.ndarray) and a.shape == shape and a.dtype == np.float64,
                   human + ": cams[%s] entry %s %s" % (key, getattr(a, "shape", None), getattr(a, "dtype", None)))
    for R in cams["R"]:
        expect(np.allclose(R @ R.T, np.eye(3), atol=1e-9) and np.linalg.det(R) > 0, human + ": R not a rotation")
    ims = annots["ims"]
    expect(isinstance(ims, list) and len(ims) > 0, human + ": ims")
    for entry in ims:
        expect(isinstance(entry, dict) and len(entry["ims"]) == n, human + ": ims entry")
        for p in entry["ims"]:
            expect(isinstance(p, str) and os.path.exists(os.path.join(d, p)), human + ": missing " + str(p))
    first = ims[0]["ims"][0]
    if human in ("CoreView_313", "CoreView_315"):
        expect(first.startswith("Camera (1)/%s_Camera_(1)_0001_" % human), human + ": original name " + first)
    else:
        expect(first == "Camera_B1/000000.jpg", human + ": name " + first)

    # Camera centres on the ring around the z axis, in calibration order.
    centres = np.stack([-R.T @ (T[:, 0] / 1000.0) for R, T in zip(cams["R"], cams["T"])])
    if args.ring:
        radius, jitter = args.ring
        rad = np.hypot(centres[:, 0], centres[:, 1])
        expect(np.all(np.abs(rad - radius) <= jitter + 0.05), human + ": centres off the ring %s" % rad)
        expect(np.all((centres[:, 2] > 0.5) & (centres[:, 2] < 2.5)), human + ": camera heights")
        ang = np.unwrap(np.arctan2(centres[:, 1], centres[:, 0]))
        expect(np.all(np.diff(ang) > 0), human + ": cameras not in ring order")

    params_dir = "params" if human == "CoreView_396" else "new_params"
    verts_dir = "vertices" if human == "CoreView_396" else "new_vertices"
    offset = 1 if human in ("CoreView_313", "CoreView_315") else 0
    inside_fractions, near_fractions = [], []
    for f, entry in enumerate(ims):
        i = f + offset
        params = np.load(os.path.join(d, params_dir, "%d.npy" % i), allow_pickle=True).item()
        for key, shape in (("poses", (1, 72)), ("Rh", (1, 3)), ("Th", (1, 3)), ("shapes", (1, 10))):
            expect(params[key].shape == shape, human + ": params[%s] shape %s" % (key, params[key].shape))
        verts = np.load(os.path.join(d, verts_dir, "%d.npy" % i))
        expect(verts.shape == (V, 3), human + ": vertices shape %s" % (verts.shape,))
        expect(verts[:, 2].min() > -0.05, human + ": body below the floor")
        for c, p in enumerate(entry["ims"]):
            img = Image.open(os.path.join(d, p))
            m = mask_of(d, p)
            expect(m is not None, human + ": no mask for " + p)
            expect(m.shape == (img.size[1], img.size[0]), human + ": mask size " + p)
            expect(m.mean() > 0.005, human + ": empty mask " + p)
            if not args.noise_free:
                continue
            K, R, T, D = (cams[k][c] for k in ("K", "R", "T", "D"))
            x = verts @ R.T + T[:, 0] / 1000.0
            xy = distort(x[:, :2] / x[:, 2:], D)
            u = K[0, 0] * xy[:, 0] + K[0, 1] * xy[:, 1] + K[0, 2]
            v = K[1, 1] * xy[:, 1] + K[1, 2]
            ui, vi = np.round(u).astype(int), np.round(v).astype(int)
            ok = (ui >= 0) & (ui < m.shape[1]) & (vi >= 0) & (vi < m.shape[0])
            expect(ok.mean() > 0.99, human + ": vertices outside the image in " + p)
            inside_fractions.append(m[vi[ok], ui[ok]].mean())
            # Vertices on the rim of a limb project onto the silhouette's edge pixels, half of
            # them just outside; a geometric error would move them further.
            near = scipy.ndimage.binary_dilation(m, np.ones((3, 3), bool))
            near_fractions.append(near[vi[ok], ui[ok]].mean())
    if inside_fractions:
        worst = min(inside_fractions)
        print("check_synth: %s: vertices inside the masks: mean %.4f, worst image %.4f; "
              "within 1 px: worst image %.5f" % (human, np.mean(inside_fractions), worst, min(near_fractions)))
        expect(worst >= 0.95, human + ": only %.3f of the vertices fall inside a mask" % worst)
        expect(min(near_fractions) >= 0.999, human + ": vertices more than 1 px outside the masks")

    if args.resave:
        numpy1_format.save(os.path.join(args.resave, human + "_annots.npy"), annots)
        params = np.load(os.path.join(d, params_dir, "%d.npy" % offset), allow_pickle=True).item()
        numpy1_format.save(os.path.join(args.resave, human + "_params.npy"), params)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("root")
    ap.add_argument("--noise-free", action="store_true")
    ap.add_argument("--any-cameras", action="store_true")
    ap.add_argument("--ring", nargs=2, type=float)
    ap.add_argument("--resave")
    args = ap.parse_args()
    V = check_model(args.root)
    humans = sorted(h for h in os.listdir(args.root) if os.path.exists(os.path.join(args.root, h, "annots.npy")))
    expect(humans, "no humans in " + args.root)
    for h in humans:
        check_human(args.root, h, V, args)
    print("check_synth: OK (%d humans)" % len(humans))


if __name__ == "__main__":
    main()
