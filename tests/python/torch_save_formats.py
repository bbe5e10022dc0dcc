"""Writes checkpoints with the installed torch's own torch.save, whatever its version (Debian 12's
1.13, Debian 13's 2.6, a pip 2.x), for tests/model/test_torch_save_formats.cpp.

Usage: torch_save_formats.py <dir>
Writes <dir>/every_dtype.pth (torch.save to a path), <dir>/every_dtype_buffer.pth (torch.save
to a file object: its records sit under 'archive/'), <dir>/every_dtype_big.pth (the first one
rewritten as a big-endian machine writes it: a 'byteorder' record saying 'big' and byte-swapped
storages), <dir>/bad_byteorder.pth (the same saying 'middle'), and <dir>/layout.txt: the torch
version, then the records of every_dtype.pth, one a line, without their archive folder.

The values follow formulas that the C++ test computes itself (dtype_values there):
  i = 0..23, shape (2, 3, 4); floats i * 0.5 - 3; int8 i * 7 - 80; uint8 i * 11;
  int16 i * 37 - 300; int32 i * 123457 - 1500000; int64 i * 2^40 - 3; bool i % 3 == 0.
"""
import collections
import io
import os
import pickle
import sys
import zipfile

import torch

DTYPES = {
    "float16": torch.float16, "bfloat16": torch.bfloat16, "float32": torch.float32,
    "float64": torch.float64, "int8": torch.int8, "uint8": torch.uint8, "int16": torch.int16,
    "int32": torch.int32, "int64": torch.int64, "bool": torch.bool,
}
ITEMSIZE = {
    "HalfStorage": 2, "BFloat16Storage": 2, "FloatStorage": 4, "DoubleStorage": 8,
    "CharStorage": 1, "ByteStorage": 1, "ShortStorage": 2, "IntStorage": 4, "LongStorage": 8,
    "BoolStorage": 1,
}


def dtype_values(name):
    i = torch.arange(24, dtype=torch.int64)
    if name in ("float16", "bfloat16", "float32", "float64"):
        v = (i.double() * 0.5 - 3).to(DTYPES[name])
    elif name == "int8":
        v = (i * 7 - 80).to(torch.int8)
    elif name == "uint8":
        v = (i * 11).to(torch.uint8)
    elif name == "int16":
        v = (i * 37 - 300).to(torch.int16)
    elif name == "int32":
        v = (i * 123457 - 1500000).to(torch.int32)
    elif name == "int64":
        v = i * 2**40 - 3
    else:
        v = i % 3 == 0
    return v.reshape(2, 3, 4)


def checkpoint():
    net = collections.OrderedDict()
    for name in DTYPES:
        net["dtype." + name] = dtype_values(name)
    # Views: a transposed tensor, and two slices of one storage at offsets (one storage record).
    net["view.transposed"] = torch.arange(24, dtype=torch.float32).reshape(4, 6).t()
    base = torch.arange(30, dtype=torch.float64) * 0.25
    net["view.slice_a"] = base[5:17].reshape(3, 4)
    net["view.slice_b"] = base[20:26:2]
    net["scalar"] = torch.tensor(2.5)
    net["empty"] = torch.zeros(0, 3)
    # A module's state dict: Parameters, a BatchNorm's int64 num_batches_tracked, _metadata.
    torch.manual_seed(0)
    module = torch.nn.Sequential(torch.nn.Linear(3, 2), torch.nn.BatchNorm1d(2))
    with torch.no_grad():
        module[0].weight.copy_(torch.arange(6, dtype=torch.float32).reshape(2, 3) - 2)
        module[0].bias.copy_(torch.tensor([0.5, -0.5]))
    for k, v in module.state_dict().items():
        net["module." + k] = v
    net["param"] = torch.nn.Parameter(torch.tensor([1.0, -2.0, 4.0]))
    return {"net": net, "epoch": 7, "meta": {"torch": torch.__version__, "step": 3}}


def storage_itemsizes(pkl):
    """Storage key -> item size, from the persistent ids of data.pkl (nothing constructed)."""
    sizes = {}

    class Anything:  # stands for every other torch global (functions and classes alike)
        def __init__(self, *args, **kwargs):
            pass

        def __setstate__(self, state):
            pass

    class Scan(pickle.Unpickler):
        def find_class(self, module, name):
            if module == "torch" and name.endswith("Storage"):
                return name
            if module.startswith("torch"):
                return Anything
            return super().find_class(module, name)

        def persistent_load(self, pid):
            sizes[pid[2]] = ITEMSIZE[pid[1]]
            return None

    Scan(io.BytesIO(pkl)).load()
    return sizes


def big_endian_copy(src, dst, order=b"big"):
    with zipfile.ZipFile(src) as z:
        names = z.namelist()
        prefix = names[0].split("/")[0] + "/"
        sizes = storage_itemsizes(z.read(prefix + "data.pkl"))
        with zipfile.ZipFile(dst, "w", zipfile.ZIP_STORED) as out:
            for n in names:
                data = z.read(n)
                rel = n[len(prefix):]
                if rel.startswith("data/") and rel[5:] in sizes:
                    k = sizes[rel[5:]]
                    data = b"".join(data[j:j + k][::-1] for j in range(0, len(data), k))
                if rel != "byteorder":
                    out.writestr(n, data)
            out.writestr(prefix + "byteorder", order)


def main(out):
    ckpt = checkpoint()
    path = os.path.join(out, "every_dtype.pth")
    torch.save(ckpt, path)
    buffer = io.BytesIO()
    torch.save(ckpt, buffer)
    with open(os.path.join(out, "every_dtype_buffer.pth"), "wb") as f:
        f.write(buffer.getvalue())
    big_endian_copy(path, os.path.join(out, "every_dtype_big.pth"))
    big_endian_copy(path, os.path.join(out, "bad_byteorder.pth"), b"middle")

    with zipfile.ZipFile(path) as z:
        records = [n.split("/", 1)[1] for n in z.namelist()]
    # A torch that writes the byteorder record reads it too: it must read the big-endian copy
    # back equal (this checks the fixture itself).
    if "byteorder" in records:
        # Our own file; weights_only (2.6's default) would refuse torch.__version__'s class.
        again = torch.load(os.path.join(out, "every_dtype_big.pth"), weights_only=False)
        for k, v in ckpt["net"].items():
            assert torch.equal(again["net"][k], v), k
    # 2.x layout details that the C++ reader must live with.
    major, minor = (int(x) for x in torch.__version__.split(".")[:2])
    if (major, minor) >= (2, 1):
        assert ".data/serialization_id" in records, records
        assert "byteorder" in records, records
    with open(os.path.join(out, "layout.txt"), "w") as f:
        f.write(torch.__version__ + "\n")
        f.write("\n".join(records) + "\n")


if __name__ == "__main__":
    main(sys.argv[1])
