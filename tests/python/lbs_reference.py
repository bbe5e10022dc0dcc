"""Independent numpy LBS (METHOD 2.3) for tests/body: reads a body model (.npz as np.savez wrote
it, or SMPL's pickled .pkl with a scipy.sparse J_regressor) and a batch of poses/shapes, writes
the per-vertex transforms A, joint transforms G, joints and posed vertices.

usage: lbs_reference.py MODEL(.npz|.pkl) INPUTS.npz OUTPUT.npz
  INPUTS.npz: poses (B, 72), shapes (B, S')
  OUTPUT.npz: A (B, V, 4, 4), G (B, 24, 4, 4), joints (B, 24, 3), posed_joints (B, 24, 3),
              vertices (B, V, 3)   -- all float64
Rotations come from scipy.spatial.transform.Rotation, not from a Rodrigues formula of ours.
"""
import pickle
import sys

import numpy as np
import scipy.sparse
from scipy.spatial.transform import Rotation


def load_model(path):
    if path.endswith(".pkl"):
        with open(path, "rb") as f:
            m = pickle.load(f, encoding="latin1")
        jreg = m["J_regressor"]
        assert scipy.sparse.issparse(jreg), "J_regressor should be a scipy.sparse matrix"
        m = dict(m)
        m["J_regressor"] = jreg.toarray()
    else:
        m = dict(np.load(path))
    return {k: np.asarray(v) for k, v in m.items() if k in
            ("v_template", "shapedirs", "posedirs", "J_regressor", "weights", "kintree_table", "f")}


def lbs(m, poses, shapes):
    v_template = m["v_template"].astype(np.float64)
    shapedirs = m["shapedirs"].astype(np.float64)
    posedirs = m["posedirs"].astype(np.float64)
    jreg = m["J_regressor"].astype(np.float64)
    weights = m["weights"].astype(np.float64)
    parents = m["kintree_table"][0].astype(np.int64)
    n_joints = jreg.shape[0]

    betas = np.zeros(shapedirs.shape[2])
    betas[: shapes.shape[0]] = shapes
    v_shaped = v_template + np.einsum("vcs,s->vc", shapedirs, betas)
    J = jreg @ v_shaped
    R = Rotation.from_rotvec(poses.reshape(-1, 3)).as_matrix()
    pose_feature = (R[1:] - np.eye(3)).reshape(-1)
    v_posed = v_shaped + np.einsum("vcp,p->vc", posedirs, pose_feature)

    G = np.zeros((n_joints, 4, 4))
    for j in range(n_joints):
        local = np.eye(4)
        local[:3, :3] = R[j]
        local[:3, 3] = J[j] if j == 0 else J[j] - J[parents[j]]
        G[j] = local if j == 0 else G[parents[j]] @ local
    posed_joints = G[:, :3, 3].copy()
    G_rel = G.copy()
    for j in range(n_joints):
        G_rel[j, :3, 3] -= G[j, :3, :3] @ J[j]
    A = np.einsum("vj,jab->vab", weights, G_rel)
    verts = np.einsum("vab,vb->va", A[:, :3, :3], v_posed) + A[:, :3, 3]
    return A, G_rel, J, posed_joints, verts


def main():
    model_path, inputs_path, output_path = sys.argv[1:4]
    m = load_model(model_path)
    inputs = np.load(inputs_path)
    outs = [lbs(m, p, s) for p, s in zip(inputs["poses"], inputs["shapes"])]
    names = ("A", "G", "joints", "posed_joints", "vertices")
    np.savez(output_path, **{n: np.stack([o[i] for o in outs]) for i, n in enumerate(names)})


if __name__ == "__main__":
    main()
