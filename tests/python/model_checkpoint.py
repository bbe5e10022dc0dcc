"""Writes .pth files shaped like the reference implementation's checkpoints (METHOD 8), with random
values, using Debian's python3-torch; and the expected tensors as raw arrays for the C++ test.

Usage: model_checkpoint.py <dir>
Writes <dir>/full.pth ({'net', 'optim', 'scheduler', 'recorder', 'epoch'}), <dir>/bare.pth (the
state dict itself, an OrderedDict), <dir>/wrong_shape.pth, <dir>/missing.pth, <dir>/extra_key.pth,
<dir>/int_tensor.pth, <dir>/bool_tensor.pth, <dir>/resnet18.pth (the ResNet part under
torchvision's names), and the 'net' tensors as <dir>/<name>.bin + manifest.txt (float32/int64).
"""
import collections
import os
import sys

import torch
import torchvision


def conv1d(sd, name, cin, cout):
    sd[name + ".weight"] = torch.randn(cout, cin, 1) * 0.05
    sd[name + ".bias"] = torch.randn(cout) * 0.05


def reference_state_dict():
    torch.manual_seed(0)
    sd = collections.OrderedDict()
    resnet = torchvision.models.resnet18()
    for k, v in resnet.state_dict().items():  # layer3, layer4, fc: present but unused
        sd["encoder.model." + k] = torch.randn_like(v.float()).to(v.dtype) if v.is_floating_point() else v + 3
    sd["encoder.reduction_layer.weight"] = torch.randn(192, 384, 1, 1) * 0.05
    sd["encoder.reduction_layer.bias"] = torch.randn(192) * 0.05
    sd["encoder.upsample_color.weight"] = torch.randn(128, 3, 1, 1) * 0.05
    sd["encoder.upsample_color.bias"] = torch.randn(128) * 0.05
    sd["encoder.PE_color._freqs"] = torch.randn(1, 20, 1)
    sd["encoder.PE_color._phases"] = torch.randn(1, 20, 1)
    sd["ViT.cls_token"] = torch.randn(1, 1, 192)
    sd["ViT.mask_token"] = torch.randn(1, 1, 192)
    sd["ViT.PE._freqs"] = torch.repeat_interleave(3.1415927 * 2.0 ** torch.arange(32), 2).view(1, -1, 1)
    sd["ViT.PE._phases"] = torch.zeros(1, 64, 1)
    for i in range(12):
        b = f"ViT.blocks.{i}."
        for n in ("norm1", "norm2"):
            sd[b + n + ".weight"] = 1 + 0.1 * torch.randn(192)
            sd[b + n + ".bias"] = 0.1 * torch.randn(192)
        sd[b + "attn.qkv.weight"] = torch.randn(576, 192) * 0.02
        sd[b + "attn.qkv.bias"] = torch.randn(576) * 0.02
        sd[b + "attn.proj.weight"] = torch.randn(192, 192) * 0.02
        sd[b + "attn.proj.bias"] = torch.randn(192) * 0.02
        sd[b + "mlp.fc1.weight"] = torch.randn(768, 192) * 0.02
        sd[b + "mlp.fc1.bias"] = torch.randn(768) * 0.02
        sd[b + "mlp.fc2.weight"] = torch.randn(192, 768) * 0.02
        sd[b + "mlp.fc2.bias"] = torch.randn(192) * 0.02
    sd["ViT.norm.weight"] = 1 + 0.1 * torch.randn(192)
    sd["ViT.norm.bias"] = 0.1 * torch.randn(192)
    conv1d(sd, "spatial_key_value_0.key_embed", 256, 128)
    conv1d(sd, "spatial_key_value_0.value_embed", 256, 256)
    conv1d(sd, "spatial_key_value_1.key_embed", 256, 128)
    conv1d(sd, "spatial_key_value_1.value_embed", 256, 256)
    sd["xyzc_net.conv0.subm0.weight"] = torch.randn(3, 3, 3, 192, 64)  # unused sparse conv net
    sd["PE_relative._freqs"] = torch.randn(1, 20, 1)
    sd["PE_relative._phases"] = torch.randn(1, 20, 1)
    conv1d(sd, "fc_0", 255, 256)
    for n in ("fc_1", "fc_2", "fc_3", "feature_fc"):
        conv1d(sd, n, 256, 256)
    conv1d(sd, "alpha_fc", 256, 1)
    conv1d(sd, "view_fc", 283, 128)
    conv1d(sd, "rgb_fc", 128, 3)
    conv1d(sd, "fc_4", 128, 128)
    conv1d(sd, "alpha_res_0", 384, 256)
    conv1d(sd, "rgb_res_0", 384, 256)
    conv1d(sd, "rgb_res_1", 384, 128)
    return sd


def main(out):
    sd = reference_state_dict()
    sd._metadata = collections.OrderedDict({"": {"version": 1}})  # as nn.Module.state_dict() sets
    opt = torch.optim.Adam([torch.nn.Parameter(torch.zeros(3))], lr=7e-4)
    sched = torch.optim.lr_scheduler.MultiStepLR(opt, milestones=[10, 20], gamma=0.5)
    full = {"net": sd, "optim": opt.state_dict(), "scheduler": sched.state_dict(), "recorder": {"step": 1234},
            "epoch": 2100}
    torch.save(full, os.path.join(out, "full.pth"))
    torch.save(sd, os.path.join(out, "bare.pth"))
    # torchvision's layout for scripts/export_pretrained.py: the same ResNet values, unprefixed.
    torch.save({k[len("encoder.model."):]: v for k, v in sd.items() if k.startswith("encoder.model.")},
               os.path.join(out, "resnet18.pth"))
    wrong = collections.OrderedDict(sd)
    wrong["fc_3.weight"] = torch.randn(256, 255, 1)
    torch.save({"net": wrong}, os.path.join(out, "wrong_shape.pth"))
    missing = collections.OrderedDict(sd)
    del missing["alpha_fc.bias"]
    torch.save({"net": missing}, os.path.join(out, "missing.pth"))
    extra = collections.OrderedDict(sd)
    extra["fc_5.weight"] = torch.randn(128, 128, 1)  # not in the reference network
    torch.save({"net": extra}, os.path.join(out, "extra_key.pth"))
    integer = collections.OrderedDict(sd)
    integer["alpha_fc.bias"] = torch.ones(1, dtype=torch.int64)
    torch.save({"net": integer}, os.path.join(out, "int_tensor.pth"))
    flags = collections.OrderedDict(sd)
    flags["rgb_fc.bias"] = torch.ones(3, dtype=torch.bool)
    torch.save({"net": flags}, os.path.join(out, "bool_tensor.pth"))
    with open(os.path.join(out, "manifest.txt"), "w") as m:
        for k, v in sd.items():
            if k.startswith(("xyzc_net", "encoder.model.layer3", "encoder.model.layer4", "encoder.model.fc")):
                continue
            a = v.contiguous().numpy()
            dt = {"float32": "f32", "int64": "i64"}[str(a.dtype)]
            a.tofile(os.path.join(out, k + ".bin"))
            m.write(" ".join([k, dt] + [str(s) for s in a.shape]) + "\n")


if __name__ == "__main__":
    main(sys.argv[1])
