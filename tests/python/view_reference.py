"""The reference's preprocessing of one target view (METHOD 2.1), with numpy and OpenCV's Python
binding, written from docs/METHOD.md: mask union, border band on the distorted mask, undistortion of
image and mask with float32 K and D, resize (INTER_AREA / INTER_NEAREST), black background.

Usage:
  view_reference.py distort <human_dir> <k1> <k2>   set camera 0's D to (k1, k2, 0, 0, 0) in annots.npy
  view_reference.py view <human_dir> <frame> <camera> <ratio> <out_dir>
      writes <out_dir>/mask.npy (uint8 HxW) and <out_dir>/image.npy (float32 HxWx3 RGB)
"""
import os
import sys

import cv2
import numpy as np


def load_annots(human):
    return np.load(os.path.join(human, "annots.npy"), allow_pickle=True).item()


def cmd_distort(human, k1, k2):
    annots = load_annots(human)
    annots["cams"]["D"][0] = np.array([[float(k1)], [float(k2)], [0.0], [0.0], [0.0]])
    np.save(os.path.join(human, "annots.npy"), annots)


def read_mask(human, rel):
    mask = None
    for folder in ("mask", "mask_cihp"):
        path = os.path.join(human, folder, os.path.splitext(rel)[0] + ".png")
        if os.path.exists(path):
            m = (cv2.imread(path, cv2.IMREAD_GRAYSCALE) != 0).astype(np.uint8)
            mask = m if mask is None else (mask | m)
    return mask


def cmd_view(human, frame, camera, ratio, out):
    annots = load_annots(human)
    rel = annots["ims"][int(frame)]["ims"][int(camera)]
    img = cv2.cvtColor(cv2.imread(os.path.join(human, rel), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
    img = img.astype(np.float32) / 255.0
    msk = read_mask(human, rel)
    kernel = np.ones((5, 5), np.uint8)
    band = (cv2.dilate(msk, kernel) - cv2.erode(msk, kernel)) == 1
    msk[band] = 100  # on the distorted mask [parity]
    K = np.array(annots["cams"]["K"][int(camera)]).astype(np.float32)
    D = np.array(annots["cams"]["D"][int(camera)]).astype(np.float32)
    img = cv2.undistort(img, K, D)
    msk = cv2.undistort(msk, K, D)
    ratio = float(ratio)
    H, W = int(img.shape[0] * ratio), int(img.shape[1] * ratio)
    if (H, W) != img.shape[:2]:
        img = cv2.resize(img, (W, H), interpolation=cv2.INTER_AREA)
        msk = cv2.resize(msk, (W, H), interpolation=cv2.INTER_NEAREST)
    img[msk == 0] = 0
    np.save(os.path.join(out, "mask.npy"), msk)
    np.save(os.path.join(out, "image.npy"), np.ascontiguousarray(img))


if __name__ == "__main__":
    {"distort": cmd_distort, "view": cmd_view}[sys.argv[1]](*sys.argv[2:])
