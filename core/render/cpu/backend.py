"""CPU backend: numba projection + compositing (core/render/cpu/project_kernels.py,
core/render/cpu/blend_kernels.py) as one torch.autograd.Function with hand-written backward.

All kernel arrays are float32 and contiguous (one compiled specialisation per kernel); inputs
of other dtypes are converted and gradients are returned in the inputs' dtype and device.
"""

from __future__ import annotations

import numba
import numpy as np
import torch

from ...model.interrupt import cancellable
from . import blend_kernels as rk
from . import project_kernels as pk


def _f32(t: torch.Tensor) -> np.ndarray:
    return np.ascontiguousarray(t.detach().cpu().numpy(), dtype=np.float32)


class _RasterizeCPU(torch.autograd.Function):
    """(means, quats, log_scales, opacity_logits, colors) -> colour sum (H,W,3) without
    background, alpha-weighted depth sum (H,W), alpha (H,W)."""

    @staticmethod
    @cancellable
    def forward(ctx, means, quats, log_scales, opacity_logits, colors, cam, width, height, near,
                low_pass):
        arrays = [_f32(t) for t in (means, quats, log_scales, opacity_logits, colors)]
        n = arrays[0].shape[0]
        proj = np.empty((n, rk.NF), np.float32)
        extent = np.empty((n, 2), np.float32)
        visible = np.empty(n, np.bool_)
        pk.project_forward(*arrays, cam, width, height, np.float32(near), np.float32(low_pass),
                           proj, extent, visible)
        order, feats, ext = rk.sort_visible(proj, extent, visible)
        offsets, ids = rk.bin_tiles(feats, ext, width, height)
        out_c = np.empty((height, width, 3), np.float32)
        out_d = np.empty((height, width), np.float32)
        out_a = np.empty((height, width), np.float32)
        out_n = np.empty((height, width), np.int32)
        rk.blend_forward(feats, offsets, ids, width, height, out_c, out_d, out_a, out_n)
        ctx.saved = (arrays, cam, width, height, proj, visible, order, feats, offsets, ids,
                     out_a, out_n)
        ctx.like = [(t.dtype, t.device) for t in (means, quats, log_scales, opacity_logits, colors)]
        dtype, device = means.dtype, means.device
        return tuple(torch.from_numpy(a).to(device=device, dtype=dtype)
                     for a in (out_c, out_d, out_a))

    @staticmethod
    @cancellable
    def backward(ctx, g_c, g_d, g_a):
        (arrays, cam, width, height, proj, visible, order, feats, offsets, ids,
         out_a, out_n) = ctx.saved
        grads = np.zeros((numba.get_num_threads(), feats.shape[0], rk.NF), np.float32)
        rk.blend_backward(feats, offsets, ids, width, height, out_a, out_n,
                          _grad(g_c, (height, width, 3)), _grad(g_d, (height, width)),
                          _grad(g_a, (height, width)), grads)
        g_proj = np.zeros_like(proj)
        rk.sum_thread_grads(grads, order, g_proj)
        outs = [np.empty_like(a) for a in arrays]
        means, quats, log_scales = arrays[:3]
        pk.project_backward(means, quats, log_scales, cam, width, height, proj, visible, g_proj,
                            *outs)
        result = [torch.from_numpy(g).to(device=device, dtype=dtype)
                  for g, (dtype, device) in zip(outs, ctx.like)]
        return (*result, None, None, None, None, None)


def _grad(g: torch.Tensor | None, shape) -> np.ndarray:
    return np.zeros(shape, np.float32) if g is None else _f32(g)


def camera_array(K: torch.Tensor, w2c: torch.Tensor) -> np.ndarray:
    """The kernels' float32 camera vector [fx, fy, cx, cy, R row-major (9), t (3)]."""
    K, w2c = K.detach().cpu().double().numpy(), w2c.detach().cpu().double().numpy()
    return np.concatenate([[K[0, 0], K[1, 1], K[0, 2], K[1, 2]], w2c[:3, :3].ravel(),
                           w2c[:3, 3]]).astype(np.float32)


@cancellable
def rasterize_cpu(means, quats, log_scales, opacity_logits, colors, K, w2c, width, height, near,
                  low_pass):
    """Colour sum without background (H,W,3), alpha-weighted depth sum (H,W), alpha (H,W).

    A Ctrl-C inside the kernels or torch's autograd machinery comes out as
    ``Cancelled`` (core/model/interrupt.py), never a ``SystemError``.
    """
    return _RasterizeCPU.apply(means, quats, log_scales, opacity_logits, colors,
                               camera_array(K, w2c), int(width), int(height), float(near),
                               float(low_pass))
