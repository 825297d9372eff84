"""CPU compositing backend: the numba kernels of core/raster_kernels.py as a torch.autograd.Function."""

from __future__ import annotations

import numba
import numpy as np
import torch

from . import raster_kernels as rk

TILE = 16


class _Composite(torch.autograd.Function):
    """feats (M,10) float32, depth-sorted -> colour sum (H,W,3), depth sum (H,W), alpha (H,W)."""

    @staticmethod
    def forward(ctx, feats: torch.Tensor, extent: np.ndarray, width: int, height: int):
        f = np.ascontiguousarray(feats.detach().cpu().numpy(), dtype=np.float32)
        offsets, ids = rk.bin_tiles(f, extent, width, height, TILE)
        out_c = np.empty((height, width, 3), np.float32)
        out_d = np.empty((height, width), np.float32)
        out_a = np.empty((height, width), np.float32)
        out_n = np.empty((height, width), np.int32)
        rk.blend_forward(f, offsets, ids, width, height, TILE, out_c, out_d, out_a, out_n)
        ctx.saved = (f, offsets, ids, out_a, out_n, width, height)
        ctx.device = feats.device
        return tuple(torch.from_numpy(a).to(feats.device) for a in (out_c, out_d, out_a))

    @staticmethod
    def backward(ctx, g_c, g_d, g_a):
        f, offsets, ids, out_a, out_n, width, height = ctx.saved
        grads = np.zeros((numba.get_num_threads(), f.shape[0], rk.NF), np.float32)

        def arr(g, shape):
            if g is None:
                return np.zeros(shape, np.float32)
            return np.ascontiguousarray(g.detach().cpu().numpy(), dtype=np.float32)
        rk.blend_backward(f, offsets, ids, width, height, TILE, out_a, out_n,
                          arr(g_c, (height, width, 3)), arr(g_d, (height, width)),
                          arr(g_a, (height, width)), grads)
        out = np.empty((f.shape[0], rk.NF), np.float32)
        rk.sum_threads(grads, out)
        return torch.from_numpy(out).to(ctx.device), None, None, None


def composite_cpu(means2d, conics, opacities, colors, depths, extent, order, width, height):
    """Blend the Gaussians ``order`` (front to back) with the numba kernels (autograd-aware).

    Returns the colour sum without background (H,W,3), alpha-weighted depth sum (H,W) and
    alpha (H,W), in the dtype of ``means2d`` (the kernels compute in float32)."""
    feats = torch.cat([means2d[order], conics[order], opacities[order, None], colors[order],
                       depths[order, None]], dim=1).to(torch.float32)
    ext = np.ascontiguousarray(extent[order].detach().cpu().numpy(), dtype=np.float32)
    return tuple(o.to(means2d.dtype) for o in _Composite.apply(feats, ext, width, height))
