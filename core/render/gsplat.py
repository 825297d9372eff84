"""GPU backend: gsplat's CUDA rasterizer behind the same interface (used only if CUDA + gsplat).

gsplat implements the same 3DGS model with its own small differences (alpha clamp 0.999, every
pixel of a touched tile evaluated instead of the 3 sigma ellipse, and its expected depth blends
each Gaussian's centre depth, not the planar depth of core/render/constants.py, so slanted surfaces
render biased toward the camera by up to ~a pixel footprint); it cannot be tested on CPU.
"""

from __future__ import annotations

import torch

from .sh import sh_degree


def rasterize_gsplat(means, quats, log_scales, opacity_logits, sh, K, w2c, width, height,
                     background, near, low_pass):
    """-> rgb (H,W,3) over ``background``, expected depth (H,W), alpha (H,W) (float32 inside,
    returned in the dtype of ``means``)."""
    from gsplat import rasterization

    f = torch.float32
    colors, alphas, _ = rasterization(
        means.to(f), quats.to(f), torch.exp(log_scales).to(f),
        torch.sigmoid(opacity_logits).to(f), sh.to(f), w2c.to(f)[None], K.to(f)[None],
        int(width), int(height), near_plane=near, eps2d=low_pass, sh_degree=sh_degree(sh.shape[1]),
        render_mode="RGB+ED")
    alpha = alphas[0, ..., 0].to(means.dtype)
    rgb = colors[0, ..., :3].to(means.dtype) + (1.0 - alpha)[..., None] * background
    return rgb, colors[0, ..., 3].to(means.dtype), alpha
