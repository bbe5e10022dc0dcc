"""k-means label files as the reference implementation ships them (kmeans_dict/kmeans_dict_300.npy:
np.save of a dict whose `dict_voxel2pc_ind` has numpy.int32 keys), and a dict keyed by numpy
scalars of every integer, bool and float dtype, in both byte orders.

Usage: kmeans_reference.py <out_dir> <num_vertices> <clusters>
Writes:
  kmeans_dict.npy  {'pc2voxel_ind': int32 (Nv,), 'dict_voxel2pc_ind': {np.int32(c): int64 array}}
  labels.txt       numpy's reading of pc2voxel_ind, one label per line
  groups.txt       numpy's reading of dict_voxel2pc_ind: "key count first_vertex" per line
  scalar_keys.npy  {numpy scalar: index}
  scalar_keys.txt  numpy's reading of it: "kind value index" per line (kind i, b or f)
"""
import os
import sys

import numpy as np


class BigEndianScalar:
    """Pickles as numpy.core.multiarray.scalar(dtype('>..'), bytes): a big-endian numpy scalar."""

    def __init__(self, dtype, value):
        self.dtype, self.value = np.dtype(dtype).newbyteorder(">"), value

    def __reduce__(self):
        from numpy.core.multiarray import scalar

        return scalar, (self.dtype, np.array(self.value, dtype=self.dtype).tobytes())

    def __hash__(self):
        return hash((self.dtype.str, self.value))


def main(out, nv, clusters):
    nv, clusters = int(nv), int(clusters)
    rng = np.random.default_rng(5)
    labels = np.concatenate([np.arange(clusters), rng.integers(0, clusters, nv - clusters)])
    rng.shuffle(labels)
    groups = {np.int32(c): np.nonzero(labels == c)[0].astype(np.int64) for c in range(clusters)}
    np.save(os.path.join(out, "kmeans_dict.npy"),
            {"pc2voxel_ind": labels.astype(np.int32), "dict_voxel2pc_ind": groups})

    back = np.load(os.path.join(out, "kmeans_dict.npy"), allow_pickle=True).item()
    with open(os.path.join(out, "labels.txt"), "w") as f:
        f.writelines(f"{int(v)}\n" for v in back["pc2voxel_ind"])
    with open(os.path.join(out, "groups.txt"), "w") as f:
        for k, v in back["dict_voxel2pc_ind"].items():
            f.write(f"{int(k)} {len(v)} {int(v[0])}\n")

    keys = [np.int8(-3), np.uint8(200), np.int16(-300), np.uint16(60000), np.int32(-70000),
            np.uint32(4000000000), np.int64(-(2 ** 40)), np.bool_(True), np.float32(2.5),
            np.float64(-7.0), np.float16(0.5), BigEndianScalar("i4", 123456), BigEndianScalar("f8", 3.25),
            BigEndianScalar("u2", 513)]
    np.save(os.path.join(out, "scalar_keys.npy"), {k: i for i, k in enumerate(keys)})
    back = np.load(os.path.join(out, "scalar_keys.npy"), allow_pickle=True).item()
    with open(os.path.join(out, "scalar_keys.txt"), "w") as f:
        for k, i in back.items():
            kind = "b" if isinstance(k, (bool, np.bool_)) else "f" if isinstance(k, (float, np.floating)) else "i"
            value = int(k) if kind != "f" else repr(float(k))
            f.write(f"{kind} {value} {i}\n")


if __name__ == "__main__":
    main(*sys.argv[1:])
