"""Independent reference values for the network and renderer formulas (SPEC 3, 4).

Usage: model_reference.py <command> <dir>
Inputs and outputs are raw little-endian arrays listed in <dir>/manifest.txt (inputs, written
by the C++ test) and <dir>/out_manifest.txt (outputs), one line "name dtype d0 d1 ...".
Each formula is written here from SPEC.md (numpy, or the reference code's torch idiom where the
point is to reproduce an axis convention), never from the C++ code under test.
"""
import math
import os
import sys

import numpy as np

DTYPES = {"f32": np.float32, "f64": np.float64, "i64": np.int64}


def read_all(d):
    out = {}
    for line in open(os.path.join(d, "manifest.txt")):
        parts = line.split()
        if not parts:
            continue
        name, dt, shape = parts[0], parts[1], [int(x) for x in parts[2:]]
        out[name] = np.fromfile(os.path.join(d, name + ".bin"), dtype=DTYPES[dt]).reshape(shape)
    return out


def write_all(d, arrays):
    with open(os.path.join(d, "out_manifest.txt"), "w") as m:
        for name, a in arrays.items():
            a = np.ascontiguousarray(a)
            dt = {np.dtype(np.float32): "f32", np.dtype(np.float64): "f64", np.dtype(np.int64): "i64"}[a.dtype]
            a.tofile(os.path.join(d, "out_" + name + ".bin"))
            m.write(" ".join([name, dt] + [str(s) for s in a.shape]) + "\n")


def sincos(x, num_freqs, include_input):
    """SPEC 3.2: [x,] sin(f0 x), cos(f0 x), ... as float32 sin(phase + x * f), f = float(pi) 2^k."""
    x = x.astype(np.float32)
    freqs = (np.float32(np.pi) * (2.0 ** np.arange(num_freqs)).astype(np.float32)).astype(np.float32)
    freqs = np.repeat(freqs, 2)  # f0 f0 f1 f1 ...
    phases = np.zeros(2 * num_freqs, np.float32)
    phases[1::2] = np.float32(np.pi * 0.5)
    arg = x[:, None, :] * freqs[None, :, None]  # float32 product
    arg = (arg + phases[None, :, None]).astype(np.float32)  # float32 sum
    emb = np.sin(arg).reshape(len(x), -1)
    return np.concatenate([x, emb], 1) if include_input else emb


def gamma(d):
    """SPEC 3.4 view directions: [d, sin d, cos d, sin 2d, cos 2d, ..., cos 8d]."""
    parts = [d]
    for f in (1.0, 2.0, 4.0, 8.0):
        parts += [np.sin(d * np.float32(f)), np.cos(d * np.float32(f))]
    return np.concatenate(parts, 1).astype(np.float32)


def cmd_pe(a):
    import torch

    x = a["x"]
    out = {"pe32": sincos(x, 32, False), "pe10": sincos(x, 10, True), "gamma": gamma(a["d"])}
    # The reference module's own evaluation (torch.addcmul), to compare the fused variant.
    xt = torch.from_numpy(x)
    freqs = np.pi * 2.0 ** torch.arange(0, 32)
    f2 = torch.repeat_interleave(freqs, 2).view(1, -1, 1)
    ph = torch.zeros(64)
    ph[1::2] = np.pi * 0.5
    emb = xt.unsqueeze(1).repeat(1, 64, 1)
    out["pe32_addcmul"] = torch.sin(torch.addcmul(ph.view(1, -1, 1), emb, f2)).view(len(x), -1).numpy()
    return out


def cmd_dparf(a):
    """SPEC 3.3 with brute-force nearest fields."""
    xs, O, Rc, tok = a["xs"], a["origins"], a["rotations"], a["tokens"]
    nk, temp = int(a["nk"][0]), float(a["temperature"][0])
    d_all = np.sqrt(((xs[:, None, :].astype(np.float64) - O[None].astype(np.float64)) ** 2).sum(-1))
    idx = np.argsort(d_all, axis=1, kind="stable")[:, :nk]
    diff = xs[:, None, :] - O[idx]  # (N, k, 3)
    d = np.sqrt((diff.astype(np.float64) ** 2).sum(-1))
    w = np.exp(-d / temp - (-d / temp).max(1, keepdims=True))
    w = w / w.sum(1, keepdims=True)
    local = np.einsum("nkj,nkji->nki", diff.astype(np.float64), Rc[idx].astype(np.float64))  # diff^T Rc
    g = sincos(local.reshape(-1, 3).astype(np.float32), 10, True).reshape(len(xs), nk, -1)
    h = []
    for v in range(tok.shape[0]):
        feat = np.concatenate([tok[v][idx], g], -1)  # (N, k, C + 63)
        h.append((w[..., None] * feat).sum(1))
    return {"weights": w.astype(np.float32), "local": local.astype(np.float32), "index": idx.astype(np.int64),
            "h": np.stack(h, 1).astype(np.float32)}


def cmd_fdi(a):
    """The reference's cross-attention, with its Conv1d (N, C, V) layout (SPEC 3.4)."""
    import torch
    import torch.nn.functional as F

    t = {k: torch.from_numpy(v.copy()) for k, v in a.items()}
    s, p = t["s"], t["a"]  # (N, V, 256) human / appearance inputs (after relu)

    def conv(x, name):  # Conv1d k=1 on (N, C, V)
        return torch.einsum("oc,ncv->nov", t[name + "_w"], x) + t[name + "_b"][None, :, None]

    pix = p.permute(0, 2, 1)  # pixel_feat.permute(2, 1, 0) of a (V, C, N) tensor
    hol = s.permute(0, 2, 1)
    key_embed, value_embed = conv(pix, "key0"), conv(pix, "value0")
    query_key, query_value = conv(hol, "key1"), conv(hol, "value1")
    A = torch.bmm(key_embed.transpose(1, 2), query_key) / math.sqrt(key_embed.size(1))
    A = F.softmax(A, dim=1)
    out = torch.bmm(value_embed, A)
    o = (query_value + out).permute(0, 2, 1)  # (N, V, 256)
    e = torch.relu(torch.einsum("oc,nvc->nvo", t["fc_2_w"], torch.relu(torch.einsum("oc,nvc->nvo", t["fc_1_w"], o) + t["fc_1_b"])) + t["fc_2_b"])
    return {"attention": A.permute(0, 2, 1).numpy(), "e": e.numpy()}


def cmd_composite(a):
    """NeRF's raw2outputs as the reference uses it (SPEC 4), float32."""
    raw, z, d = a["raw"], a["z"], a["d"]
    dists = z[..., 1:] - z[..., :-1]
    dists = np.concatenate([dists, np.full_like(dists[..., :1], 1e10)], -1)
    dists = dists * np.linalg.norm(d, axis=-1)[:, None]
    rgb = 1 / (1 + np.exp(-raw[..., :3]))
    alpha = 1 - np.exp(-np.maximum(raw[..., 3], 0) * dists)
    T = np.cumprod(np.concatenate([np.ones_like(alpha[:, :1]), 1 - alpha + 1e-10], -1), -1)[:, :-1]
    w = (alpha * T).astype(np.float32)
    return {"rgb": (w[..., None] * rgb).sum(1).astype(np.float32), "depth": (w * z).sum(1).astype(np.float32),
            "acc": w.sum(1).astype(np.float32), "weights": w}


def cmd_encoder(a):
    """torchvision's resnet18 (conv1..layer2, BatchNorm with batch statistics as the reference
    runs it) and the reference's pixel feature / reduction (SPEC 3.1)."""
    import torch
    import torch.nn.functional as F
    import torchvision

    net = torchvision.models.resnet18()
    state = {k[len("model."):]: torch.from_numpy(v.copy()) for k, v in a.items() if k.startswith("model.")}
    missing, unexpected = net.load_state_dict(state, strict=False)
    assert not unexpected, unexpected
    assert all(k.startswith(("layer3", "layer4", "fc")) for k in missing), missing
    net.train()
    x = torch.from_numpy(a["images"].copy())
    with torch.no_grad():
        l0 = net.relu(net.bn1(net.conv1(x)))
        l1 = net.layer1(net.maxpool(l0))
        l2 = net.layer2(l1)
        H, W = x.shape[2:]
        lat = [F.interpolate(l, (H, W), mode="bilinear", align_corners=True) for l in (l0, l1, l2)]
        color = F.conv2d(x, torch.from_numpy(a["upsample_color.weight"].copy()), torch.from_numpy(a["upsample_color.bias"].copy()))
        pixel = torch.cat(lat + [color], 1)
        holder = F.conv2d(pixel, torch.from_numpy(a["reduction_layer.weight"].copy()), torch.from_numpy(a["reduction_layer.bias"].copy()))
    return {"l0": l0.numpy(), "l1": l1.numpy(), "l2": l2.numpy(), "pixel": pixel.numpy(), "holder": holder.numpy()}


def cmd_vit(a):
    """ViT-Tiny as SPEC 3.2 states it (timm pre-norm blocks), in torch."""
    import torch
    import torch.nn.functional as F

    t = {k: torch.from_numpy(v.copy()) for k, v in a.items()}
    depth, heads = int(a["depth"][0]), int(a["heads"][0])
    x = t["tokens"] + torch.from_numpy(sincos(a["positions"], 32, False))[None]
    B, N, C = x.shape
    for i in range(depth):
        p = lambda n: t[f"blocks.{i}.{n}"]
        y = F.layer_norm(x, (C,), p("norm1.weight"), p("norm1.bias"), eps=1e-6)
        qkv = F.linear(y, p("attn.qkv.weight"), p("attn.qkv.bias")).reshape(B, N, 3, heads, C // heads).permute(2, 0, 3, 1, 4)
        q, k, v = qkv[0], qkv[1], qkv[2]
        att = ((q @ k.transpose(-2, -1)) * (C // heads) ** -0.5).softmax(-1)
        y = F.linear((att @ v).transpose(1, 2).reshape(B, N, C), p("attn.proj.weight"), p("attn.proj.bias"))
        x = x + y
        y = F.layer_norm(x, (C,), p("norm2.weight"), p("norm2.bias"), eps=1e-6)
        y = F.linear(F.gelu(F.linear(y, p("mlp.fc1.weight"), p("mlp.fc1.bias"))), p("mlp.fc2.weight"), p("mlp.fc2.bias"))
        x = x + y
    x = F.layer_norm(x, (C,), t["norm.weight"], t["norm.bias"], eps=1e-6)
    return {"out": x.numpy()}


if __name__ == "__main__":
    command, directory = sys.argv[1], sys.argv[2]
    arrays = read_all(directory)
    write_all(directory, globals()["cmd_" + command](arrays))
