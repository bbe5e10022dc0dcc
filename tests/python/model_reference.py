"""Independent reference values for the network and renderer formulas (METHOD 3, 4).

Usage: model_reference.py <command> <dir> [<dir> ...]
Inputs and outputs are raw little-endian arrays listed in <dir>/manifest.txt (inputs, written
by the C++ test) and <dir>/out_manifest.txt (outputs), one line "name dtype d0 d1 ...".
Each formula is written here from docs/METHOD.md (numpy, or the reference code's torch idiom where the
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
    """METHOD 3.2: [x,] sin(f0 x), cos(f0 x), ... as float32 sin(phase + x * f), f = float(pi) 2^k."""
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
    """METHOD 3.4 view directions: [d, sin d, cos d, sin 2d, cos 2d, ..., cos 8d]."""
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
    """METHOD 3.3 with brute-force nearest fields."""
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
    """The reference's cross-attention, with its Conv1d (N, C, V) layout (METHOD 3.4)."""
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
    """NeRF's raw2outputs as the reference uses it (METHOD 4), float32."""
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
    runs it) and the reference's pixel feature / reduction (METHOD 3.1)."""
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
    """ViT-Tiny as METHOD 3.2 states it (timm pre-norm blocks), in torch."""
    import torch
    import torch.nn.functional as F

    t = {k: torch.from_numpy(v.copy()) for k, v in a.items()}
    depth, heads = int(a["depth"][0]), int(a["heads"][0])
    x = t["tokens"] + reference_pe(t["positions"], 32, False)[None]  # the reference's addcmul (fused)
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


def reference_pe(x, num_freqs, include_input):
    """The reference's PositionalEncoding: sin(addcmul(phases, x, freqs)) in float32 (METHOD 3.2)."""
    import torch

    freqs = torch.repeat_interleave(math.pi * 2.0 ** torch.arange(0, num_freqs), 2).view(1, -1, 1).float()
    phases = torch.zeros(2 * num_freqs)
    phases[1::2] = math.pi * 0.5
    emb = x.unsqueeze(1).repeat(1, 2 * num_freqs, 1)
    emb = torch.sin(torch.addcmul(phases.view(1, -1, 1), emb, freqs)).view(x.shape[0], -1)
    return torch.cat([x, emb], -1) if include_input else emb


def cmd_pe_fused(a):
    """The token PE table of the reference (torch.addcmul, fused rounding) for the positions given."""
    import torch

    return {"pe32": reference_pe(torch.from_numpy(a["x"].copy()), 32, False).numpy()}


def cmd_render(a):
    """End to end (METHOD 2.2, 3, 4): a reference-format checkpoint saved by torch.save renders the
    given rays of one frame. Every stage is written here from docs/METHOD.md, in PyTorch; nothing comes
    from the C++ code but the frame's inputs and the rays."""
    import torch
    import torch.nn.functional as F
    import torchvision

    ckpt = torch.load(open(os.path.join(DIR, "checkpoint.txt")).read().strip(), map_location="cpu")
    sd = ckpt["net"] if "net" in ckpt else ckpt
    t = {k: torch.from_numpy(v.copy()) for k, v in a.items()}
    images, K, R, T = t["ref_images"], t["K"].double(), t["R"].double(), t["T"].double()
    V, _, H, W = images.shape

    def conv1d(name, x):  # Conv1d k=1 on (..., C) as the reference's (C, N) layout would give
        return F.linear(x, sd[name + ".weight"][:, :, 0], sd[name + ".bias"])

    # METHOD 3.1: ResNet-18 to layer2 with batch statistics, upsampled, colour channels, reduction.
    net = torchvision.models.resnet18()
    enc = {k[len("encoder.model."):]: v for k, v in sd.items() if k.startswith("encoder.model.")}
    net.load_state_dict(enc, strict=False)
    net.train()
    with torch.no_grad():
        l0 = net.relu(net.bn1(net.conv1(images)))
        l1 = net.layer1(net.maxpool(l0))
        l2 = net.layer2(l1)
        ups = [F.interpolate(l, (H, W), mode="bilinear", align_corners=True) for l in (l0, l1, l2)]
        color = F.conv2d(images, sd["encoder.upsample_color.weight"], sd["encoder.upsample_color.bias"])
        pixel = torch.cat(ups + [color], 1)
        holder = F.conv2d(pixel, sd["encoder.reduction_layer.weight"], sd["encoder.reduction_layer.bias"])

        def project(pts):  # (N, 3) world -> (V, N, 2) pixels, METHOD 2.2
            xc = torch.einsum("vij,nj->vni", R, pts.double()) + T[:, None, :, 0]
            uvw = torch.einsum("vij,vnj->vni", K, xc)
            return (uvw[..., :2] / uvw[..., 2:]).float()

        def sample(feat, uv):  # grid_sample at uv * 2 / (size - 1) - 1 -> (V, N, C)
            grid = torch.stack([uv[..., 0] * 2 / (W - 1) - 1, uv[..., 1] * 2 / (H - 1) - 1], -1)
            out = F.grid_sample(feat, grid[:, None], mode="bilinear", padding_mode="border", align_corners=True)
            return out[:, :, 0].permute(0, 2, 1)

        # Painting, tokens (mean over every vertex of a cluster), positions, TransHE.
        vertices, labels = t["vertices"], t["labels"]
        painted = sample(holder, project(vertices)) * t["visibility"].float()[..., None]
        nt = int(labels.max()) + 1
        members = [labels == c for c in range(nt)]
        tokens = torch.stack([painted[:, m].mean(1) for m in members], 1)
        canonical = t["canonical"]  # float64
        positions = torch.stack([canonical[m].mean(0) for m in members]) / 1.5
        x = tokens + reference_pe(positions.float(), 32, False)[None]
        depth = len({k.split(".")[2] for k in sd if k.startswith("ViT.blocks.")})
        heads, C = 3, x.shape[-1]
        B, N = x.shape[:2]
        for i in range(depth):
            p = lambda n: sd[f"ViT.blocks.{i}.{n}"]
            y = F.layer_norm(x, (C,), p("norm1.weight"), p("norm1.bias"), eps=1e-6)
            qkv = F.linear(y, p("attn.qkv.weight"), p("attn.qkv.bias")).reshape(B, N, 3, heads, C // heads).permute(2, 0, 3, 1, 4)
            att = ((qkv[0] @ qkv[1].transpose(-2, -1)) * (C // heads) ** -0.5).softmax(-1)
            x = x + F.linear((att @ qkv[2]).transpose(1, 2).reshape(B, N, C), p("attn.proj.weight"), p("attn.proj.bias"))
            y = F.layer_norm(x, (C,), p("norm2.weight"), p("norm2.bias"), eps=1e-6)
            x = x + F.linear(F.gelu(F.linear(y, p("mlp.fc1.weight"), p("mlp.fc1.bias"))), p("mlp.fc2.weight"), p("mlp.fc2.bias"))
        tokens = F.layer_norm(x, (C,), sd["ViT.norm.weight"], sd["ViT.norm.bias"], eps=1e-6)

        # DPaRF frames (METHOD 3.3): cluster means of the SMPL-frame vertices and of A.
        Rh, Th = t["Rh"], t["Th"]
        xs_vertices = (vertices - Th) @ Rh  # Rh^T (x - Th) per row
        origins = torch.stack([xs_vertices[m].mean(0) for m in members])
        rotations = torch.stack([t["A"][m].mean(0) for m in members])

        # Rays (METHOD 4): 64 (or `samples`) points, no jitter; culling at the body distance.
        S = int(a["samples"][0])
        o, d, near, far = t["origins"], t["directions"], t["near"], t["far"]
        tt = torch.linspace(0, 1, S)
        z = near[:, None] * (1 - tt) + far[:, None] * tt
        pts = (o[:, None] + d[:, None] * z[..., None]).reshape(-1, 3)
        dirs = F.normalize(d, dim=-1)[:, None].expand(-1, S, -1).reshape(-1, 3)
        near_body = torch.cdist(pts.double(), vertices.double()).min(1)[0] <= float(a["cull"][0])

        xs = (pts - Th) @ Rh
        dist = torch.cdist(xs, origins)
        knn_d, knn = dist.topk(7, 1, largest=False, sorted=True)
        w = F.softmax(-knn_d / 0.5, 1)
        local = ((xs[:, None] - origins[knn])[:, :, None, :] @ rotations[knn])[:, :, 0]
        g = reference_pe(local.reshape(-1, 3), 10, True).view(len(xs), 7, -1)
        h = torch.stack([(w[..., None] * torch.cat([tokens[v][knn], g], -1)).sum(1) for v in range(V)], 1)

        # FDI and heads (METHOD 3.4), (N, V, C) layout.
        pv = sample(pixel, project(pts)).permute(1, 0, 2)
        s = torch.relu(conv1d("fc_0", h))
        app = torch.relu(conv1d("alpha_res_0", pv))
        k0, u0 = conv1d("spatial_key_value_0.key_embed", app), conv1d("spatial_key_value_0.value_embed", app)
        q1, r1 = conv1d("spatial_key_value_1.key_embed", s), conv1d("spatial_key_value_1.value_embed", s)
        att = F.softmax(torch.einsum("njc,nvc->nvj", k0, q1) / math.sqrt(k0.shape[-1]), -1)
        o_v = r1 + torch.einsum("nvj,njc->nvc", att, u0)
        e = torch.relu(conv1d("fc_2", torch.relu(conv1d("fc_1", o_v))))
        sigma = conv1d("alpha_fc", torch.relu(conv1d("fc_3", e.mean(1))))[:, 0]
        c = conv1d("feature_fc", e) + conv1d("rgb_res_0", pv)
        gam = torch.from_numpy(gamma(dirs.numpy()))[:, None].expand(-1, V, -1)
        c = torch.relu(conv1d("view_fc", torch.cat([c, gam], -1))) + conv1d("rgb_res_1", pv)
        rgb = conv1d("rgb_fc", torch.relu(conv1d("fc_4", c.mean(1))))
        raw = torch.cat([rgb, sigma[:, None]], -1) * near_body[:, None]
    raw = raw.view(len(o), S, 4).numpy()
    out = cmd_composite({"raw": raw, "z": z.numpy(), "d": d.numpy()})
    return {"rgb": out["rgb"], "acc": out["acc"], "depth": out["depth"], "sigma": raw[..., 3].copy(),
            "kept": near_body.view(len(o), S).long().numpy()}



def cmd_network(a):
    """METHOD 3 as a whole, in PyTorch, for one frame and its points in the ablation that the cfg_*
    flags describe (the paper's model, w/o a, w/o h, w/o RGB, SPC, w/o TransHE, the coordinate and
    grouping variants, the PE roundings, BatchNorm's statistics): raw [rgb, sigma] per point at
    inference, and in training mode the parameters' gradients of sum(sigma w_3) + sum(rgb w_rgb
    coloured<K>) for each mask coloured<K> given (outputs <K>G_<name>). Only the weights (P_<name>,
    B_<name>: the C++ parameter and buffer names), the frame and the points come from the C++
    side."""
    import torch
    import torch.nn.functional as F

    t = {k: torch.from_numpy(v.copy()) for k, v in a.items()}
    cfg = {k[4:]: float(v.reshape(-1)[0]) for k, v in a.items() if k.startswith("cfg_")}
    params = {k[2:]: v for k, v in t.items() if k.startswith("P_")}
    buffers = {k[2:]: v for k, v in t.items() if k.startswith("B_")}
    images, vis, labels = t["ref_images"], t["visibility"].float(), t["labels"]
    V, _, H, W = images.shape
    K, R, T = t["K"], t["R"], t["T"].reshape(-1, 3)
    Rh, Th, A = t["Rh"], t["Th"].reshape(3), t["A"]
    vertices, pts, dirs = t["vertices"], t["pts"], t["dirs"]

    def pe(x, num_freqs, fused, include_input):
        if fused:
            return reference_pe(x, num_freqs, include_input)
        freqs = torch.repeat_interleave(math.pi * 2.0 ** torch.arange(0, num_freqs), 2).view(1, -1, 1).float()
        phases = torch.zeros(2 * num_freqs)
        phases[1::2] = math.pi * 0.5
        emb = torch.sin(x.unsqueeze(1) * freqs + phases.view(1, -1, 1)).reshape(x.shape[0], -1)
        return torch.cat([x, emb], -1) if include_input else emb

    def project(x):  # (N, 3) world -> (N, V, 2) pixels
        cam = torch.einsum("vij,nj->nvi", R, x) + T[None]
        img = torch.einsum("vij,nvj->nvi", K, cam)
        return img[..., :2] / img[..., 2:]

    def sample(feat, uv):  # (V, C, H, W) at (N, V, 2) -> (N, V, C)
        grid = torch.stack([uv[..., 0] * 2 / (W - 1) - 1, uv[..., 1] * 2 / (H - 1) - 1], -1)
        out = F.grid_sample(feat, grid.permute(1, 0, 2)[:, None], mode="bilinear", padding_mode="border",
                            align_corners=True)
        return out[:, :, 0].permute(2, 0, 1)

    def forward(P, training):
        def lin(name, x):
            return F.linear(x, P[name + ".weight"], P.get(name + ".bias"))

        def conv(name, x, stride=1, padding=0):
            return F.conv2d(x, P[name + ".weight"], P.get(name + ".bias"), stride, padding)

        def bn(name, x):  # batch statistics in training, and at inference unless running ones
            batch = training or cfg["batch_stats"] > 0
            return F.batch_norm(x, None if batch else buffers[name + ".running_mean"],
                                None if batch else buffers[name + ".running_var"], P[name + ".weight"],
                                P[name + ".bias"], training=batch, momentum=0.1, eps=1e-5)

        def block(name, x, stride):
            y = F.relu(bn(name + ".bn1", conv(name + ".conv1", x, stride, 1)))
            y = bn(name + ".bn2", conv(name + ".conv2", y, 1, 1))
            if name + ".downsample.0.weight" in P:
                x = bn(name + ".downsample.1", conv(name + ".downsample.0", x, stride))
            return F.relu(y + x)

        # 3.1: ResNet-18 to layer2, the levels upsampled, the raw-RGB channels.
        m = "encoder.model."
        l0 = F.relu(bn(m + "bn1", conv(m + "conv1", images, 2, 3)))
        l1 = block(m + "layer1.1", block(m + "layer1.0", F.max_pool2d(l0, 3, 2, 1), 1), 1)
        l2 = block(m + "layer2.1", block(m + "layer2.0", l1, 2), 1)
        p_v = [F.interpolate(l, (H, W), mode="bilinear", align_corners=True) for l in (l0, l1, l2)]
        if "encoder.upsample_color.weight" in P:
            p_v.append(conv("encoder.upsample_color", images))
        p_v = torch.cat(p_v, 1)

        xs = (pts - Th) @ Rh  # SMPL frame
        xs_vertices = (vertices - Th) @ Rh
        s = None
        if cfg["human"] > 0:
            # 3.1 painting: F_v (V, Nv, 192), zero where a vertex is invisible.
            F_v = sample(conv("encoder.reduction_layer", p_v), project(vertices)).permute(1, 0, 2) * vis[..., None]
            if cfg["spc"] > 0:
                s = spc(P, lin, F_v, xs_vertices, xs)
            else:
                s = token_fields(P, lin, F_v, xs_vertices, xs)

        # 3.4 FDI.
        def attention(q, k):  # (N, V, V): softmax over the key views
            return F.softmax(q @ k.transpose(1, 2) / math.sqrt(q.shape[2]), 2)

        if cfg["appearance"] > 0:
            p = sample(p_v, project(pts))
            app = F.relu(lin("fdi.alpha_res_0", p))
            k, u = lin("fdi.key0", app), lin("fdi.value0", app)
            if s is not None:
                o = lin("fdi.value1", s) + attention(lin("fdi.key1", s), k) @ u
            else:
                o = u + attention(k, k) @ u
        else:
            o = lin("fdi.value1", s)
        e = F.relu(lin("fdi.fc_2", F.relu(lin("fdi.fc_1", o))))
        # 3.4 the heads.
        sigma = lin("heads.alpha_fc", F.relu(lin("heads.fc_3", e.mean(1))))[:, 0]
        d = dirs / dirs.norm(dim=1, keepdim=True)
        gam = torch.cat([d] + [f(d * s_) for s_ in (1.0, 2.0, 4.0, 8.0) for f in (torch.sin, torch.cos)], 1)
        c = lin("heads.feature_fc", e)
        if cfg["appearance"] > 0:
            c = c + lin("heads.rgb_res_0", p)
        c = F.relu(lin("heads.view_fc", torch.cat([c, gam[:, None].expand(-1, V, -1)], 2)))
        if cfg["appearance"] > 0:
            c = c + lin("heads.rgb_res_1", p)
        rgb = lin("heads.rgb_fc", F.relu(lin("heads.fc_4", c.mean(1))))
        return rgb, sigma

    def token_fields(P, lin, F_v, xs_vertices, xs):
        # 3.2 TransHE: cluster means (clusters without vertices have no token), positions, ViT.
        nt = int(cfg["num_tokens"])
        member = F.one_hot(labels, nt)
        keep = member.sum(0).nonzero().flatten()

        def mean(values, weights=None):
            m_ = member.to(values.dtype)
            w = torch.ones(values.shape[-2], dtype=values.dtype) if weights is None else weights.to(values.dtype)
            sums = m_.t() @ (values * w[..., None])
            counts = (w @ m_)[..., None]
            return (sums / counts.clamp_min(1)).index_select(-2, keep)

        tokens = mean(F_v, vis if cfg["mean_over_visible"] > 0 else None)
        if cfg["transhe"] > 0:
            body = xs_vertices if cfg["position_observation"] > 0 else t["canonical"]
            sc = cfg["pe_scale"]
            positions = ((((mean(body.double()) + sc) / (2 * sc)) - 0.5) * 2).float()
            x = tokens + pe(positions, int(cfg["transhe_pe_freqs"]), cfg["transhe_fused"] > 0, False)[None]
            depth = len({k.split(".")[3] for k in P if k.startswith("human.ViT.blocks.")})
            heads, C = int(cfg["heads"]), x.shape[-1]
            B, N = x.shape[:2]
            for i in range(depth):
                b = f"human.ViT.blocks.{i}."
                y = F.layer_norm(x, (C,), P[b + "norm1.weight"], P[b + "norm1.bias"], eps=1e-6)
                qkv = lin(b + "attn.qkv", y).reshape(B, N, 3, heads, C // heads).permute(2, 0, 3, 1, 4)
                att = ((qkv[0] @ qkv[1].transpose(-2, -1)) / math.sqrt(C // heads)).softmax(-1)
                x = x + lin(b + "attn.proj", (att @ qkv[2]).transpose(1, 2).reshape(B, N, C))
                y = F.layer_norm(x, (C,), P[b + "norm2.weight"], P[b + "norm2.bias"], eps=1e-6)
                x = x + lin(b + "mlp.fc2", F.gelu(lin(b + "mlp.fc1", y)))
            tokens = F.layer_norm(x, (C,), P["human.ViT.norm.weight"], P["human.ViT.norm.bias"], eps=1e-6)
        # 3.3 DPaRF: the Nk nearest token frames (Oc, Rc), softmax(-distance / T), local coordinates.
        Oc, Rc = mean(xs_vertices), mean(A.reshape(-1, 9)).view(-1, 3, 3)
        N, nk = xs.shape[0], int(cfg["nk"])
        knn = ((xs[:, None] - Oc[None]) ** 2).sum(2).topk(nk, 1, largest=False, sorted=True)[1]
        diff = xs[:, None] - Oc[knn]  # (N, Nk, 3)
        w = F.softmax(-diff.norm(dim=-1) / cfg["temperature"], 1)
        freqs, fused = int(cfg["dparf_pe_freqs"]), cfg["dparf_fused"] > 0
        g = None
        if cfg["coordinate"] == 0:  # relative: l_k = Rc(k)^T (xs - Oc(k))
            Rk = Rc[knn]
            local = diff[..., 0:1] * Rk[..., 0, :] + diff[..., 1:2] * Rk[..., 1, :] + diff[..., 2:3] * Rk[..., 2, :]
            g = pe(local.reshape(-1, 3), freqs, fused, True).view(N, nk, -1)
        elif cfg["coordinate"] == 1:  # absolute: the point's own
            g = pe(xs, freqs, fused, True)[:, None].expand(N, nk, -1)
        field = tokens[:, knn].permute(1, 0, 2, 3)  # (N, V, Nk, C)
        if g is not None:
            field = torch.cat([field, g[:, None].expand(N, V, nk, -1)], 3)
        return F.relu(lin("human.fc_0", (w[:, None, :, None] * field).sum(2)))

    def spc(P, lin, F_v, xs_vertices, xs):
        # The SPC baseline: embedded painted features averaged into voxels over the posed body,
        # two 3D convolutions, read trilinearly (zero outside the grid).
        voxel = cfg["voxel_size"]
        lo = xs_vertices.min(0)[0] - 2 * voxel
        hi = xs_vertices.max(0)[0] + 2 * voxel
        dims = ((hi - lo) / voxel).ceil().long() + 1
        nx, ny, nz = dims.tolist()
        cell = ((xs_vertices - lo) / voxel).round().long()
        vox = (cell[:, 2] * ny + cell[:, 1]) * nx + cell[:, 0]
        emb = lin("human.embed", F_v)
        C = emb.shape[2]
        sums = torch.zeros(V, nz * ny * nx, C).index_add(1, vox, emb)
        counts = torch.zeros(nz * ny * nx).index_add(0, vox, torch.ones(len(vox)))
        grid = (sums / counts.clamp_min(1)[None, :, None]).permute(0, 2, 1).reshape(V, C, nz, ny, nx)
        for i in (0, 2):
            grid = F.relu(F.conv3d(grid, P[f"human.conv.{i}.weight"], P[f"human.conv.{i}.bias"], padding=1))
        at = ((xs - lo) / ((dims - 1).float() * voxel)) * 2 - 1
        f = F.grid_sample(grid, at.view(1, 1, 1, -1, 3).expand(V, 1, 1, len(xs), 3), mode="bilinear",
                          padding_mode="zeros", align_corners=True)
        return F.relu(lin("human.fc_0", f.view(V, C, -1).permute(2, 0, 1)))

    with torch.no_grad():
        rgb, sigma = forward(params, False)
    out = {"raw": torch.cat([rgb, sigma[:, None]], 1).numpy()}
    leaves = {k: v.clone().requires_grad_(True) for k, v in params.items()}
    rgb, sigma = forward(leaves, True)
    w, names = t["w"], sorted(leaves)
    masks = sorted(k for k in t if k.startswith("coloured"))  # one gradient set per mask
    for i, mask in enumerate(masks):
        loss = (sigma * w[:, 3]).sum() + (rgb * w[:, :3] * t[mask]).sum()
        grads = torch.autograd.grad(loss, [leaves[n] for n in names], allow_unused=True,
                                    retain_graph=i + 1 < len(masks))
        for name, g in zip(names, grads):
            if g is not None:
                out[mask[len("coloured"):] + "G_" + name] = g.numpy()
    return out


if __name__ == "__main__":
    command = sys.argv[1]
    for DIR in sys.argv[2:]:  # one or more inputs' folders, each answered in its own
        write_all(DIR, globals()["cmd_" + command](read_all(DIR)))
