"""Random-weight LPIPS fixture: weights .npz (via scripts/export_lpips.py) plus images and the
distances of the Python formula. Usage: lpips_reference.py DIR"""
import os
import sys

import numpy as np
import torch

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "scripts"))
import export_lpips  # noqa: E402

d = sys.argv[1]
features, lins = export_lpips.build(random_seed=5)
export_lpips.export(features, lins, f"{d}/lpips_random.npz")
torch.manual_seed(6)
a = torch.rand(3, 3, 40, 56) * 2 - 1
b = (a + 0.3 * torch.randn_like(a)).clamp(-1, 1)
with torch.no_grad():
    dist = export_lpips.reference_lpips(features, lins, a, b)
np.save(f"{d}/a.npy", a.numpy())
np.save(f"{d}/b.npy", b.numpy())
np.save(f"{d}/dist.npy", dist.numpy())
