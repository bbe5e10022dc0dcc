// Anchor for the precompiled <torch/torch.h> shared by every target.
