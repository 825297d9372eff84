"""CPU backend: numba projection + compositing (core/render/cpu/project_kernels.py,
core/render/cpu/blend_kernels.py) as one torch.autograd.Function with hand-written backward.

All kernel arrays are float32 and contiguous (one compiled specialisation per kernel); inputs
of other dtypes are converted and gradients are returned in the inputs' dtype and device.
Each camera's last projection is kept (:class:`Projections`): a render projects again only
the Gaussians whose inputs changed since, and a backward pass can be limited to the Gaussians
whose gradients the caller uses (``grad_rows``).
"""

from __future__ import annotations

from collections import OrderedDict

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
                low_pass, backward, rows):
        arrays = [_f32(t) for t in (means, quats, log_scales, opacity_logits, colors)]
        proj, extent, visible = PROJECTIONS.project(arrays, cam, width, height, near, low_pass,
                                                    backward)
        order, feats, ext = rk.sort_visible(proj, extent, visible)
        offsets, ids = rk.bin_tiles(feats, ext, width, height)
        out_c = np.empty((height, width, 3), np.float32)
        out_d = np.empty((height, width), np.float32)
        out_a = np.empty((height, width), np.float32)
        out_n = np.empty((height, width), np.int32)
        rk.blend_forward(feats, offsets, ids, width, height, out_c, out_d, out_a, out_n)
        ctx.saved = (arrays, cam, width, height, proj, visible, order, feats, offsets, ids,
                     out_a, out_n, rows)
        ctx.like = [(t.dtype, t.device) for t in (means, quats, log_scales, opacity_logits, colors)]
        dtype, device = means.dtype, means.device
        return tuple(torch.from_numpy(a).to(device=device, dtype=dtype)
                     for a in (out_c, out_d, out_a))

    @staticmethod
    @cancellable
    def backward(ctx, g_c, g_d, g_a):
        (arrays, cam, width, height, proj, visible, order, feats, offsets, ids,
         out_a, out_n, rows) = ctx.saved
        wanted = np.zeros(0, np.bool_)
        if rows is not None:      # only these Gaussians' gradients are used
            wanted = np.zeros_like(visible)
            wanted[rows] = True
            visible = visible & wanted
            wanted = wanted[order]
        grads = np.zeros((grad_buffers(), feats.shape[0], rk.NF), np.float32)
        rk.blend_backward(feats, offsets, ids, width, height, out_a, out_n,
                          _grad(g_c, (height, width, 3)), _grad(g_d, (height, width)),
                          _grad(g_a, (height, width)), wanted, grads)
        g_proj = np.zeros_like(proj)
        rk.sum_thread_grads(grads, order, g_proj)
        outs = [np.empty_like(a) for a in arrays]
        means, quats, log_scales = arrays[:3]
        pk.project_backward(means, quats, log_scales, cam, width, height, proj, visible, g_proj,
                            *outs)
        result = [torch.from_numpy(g).to(device=device, dtype=dtype)
                  for g, (dtype, device) in zip(outs, ctx.like)]
        return (*result, None, None, None, None, None, None, None)


class Projections:
    """The last projection per camera, image size and Gaussian count, so that the next render
    projects only the Gaussians whose inputs changed.

    The optimisation renders one camera again and again with one part moved (state searches,
    hypothesis scores, one joint's fits): projecting every Gaussian was a fifth of such a
    render. The result is bit-identical to a full projection (each row is a function of its
    own inputs only). Kept least recently used first, within ``budget`` bytes (at least the
    newest). One per process (:data:`PROJECTIONS`), used from one thread: the engine renders
    from one."""

    def __init__(self, budget: int = 96 << 20) -> None:
        self.budget = budget
        self.entries: OrderedDict[tuple, tuple[np.ndarray, ...]] = OrderedDict()

    def project(self, arrays: list[np.ndarray], cam: np.ndarray, width: int, height: int,
                near: float, low_pass: float, private: bool
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``project_forward`` of ``arrays`` (means, quats, log_scales, opacity logits, colours):
        (feats (N,12), extent (N,2), visible (N,)), kept here for the next call: read-only,
        and valid until then; with ``private``, feats and visible are copies (a backward pass
        keeps them)."""
        n = arrays[0].shape[0]
        key = (cam.tobytes(), width, height, near, low_pass, n)
        entry = self.entries.pop(key, None)   # re-entered only once projected
        if entry is None:
            bits = [a.reshape(n, int(np.prod(a.shape[1:]))).view(np.uint32) for a in arrays]
            entry = (np.concatenate(bits, 1), np.empty((n, rk.NF), np.float32),
                     np.empty((n, 2), np.float32), np.empty(n, np.bool_))
            seen = entry[0][:0]               # no rows: project them all
        else:
            seen = entry[0]
        pk.project_forward(*arrays, cam, width, height, np.float32(near), np.float32(low_pass),
                           seen, *entry[1:])
        self.entries[key] = entry
        while len(self.entries) > 1 and sum(a.nbytes for e in self.entries.values()
                                             for a in e) > self.budget:
            self.entries.popitem(last=False)
        feats, extent, visible = entry[1:]
        return (feats.copy(), extent, visible.copy()) if private else (feats, extent, visible)


PROJECTIONS = Projections()


#: The fewest gradient buffers of a backward pass (:func:`grad_buffers`).
MIN_GRAD_BUFFERS = 2


def grad_buffers() -> int:
    """Buffers the backward pass sums its tiles' gradients into: one per thread, at least
    ``MIN_GRAD_BUFFERS``. The buffers fix the float sums' order, so a render's gradients are the
    same to the bit with one thread or two: the optimisation runs parts of its work in two
    one-thread processes (core/stages/optimise/parallel.py) and ends where one two-thread
    process does."""
    return max(MIN_GRAD_BUFFERS, numba.get_num_threads())


def _grad(g: torch.Tensor | None, shape) -> np.ndarray:
    return np.zeros(shape, np.float32) if g is None else _f32(g)


def camera_array(K: torch.Tensor, w2c: torch.Tensor) -> np.ndarray:
    """The kernels' float32 camera vector [fx, fy, cx, cy, R row-major (9), t (3)]."""
    K, w2c = K.detach().cpu().double().numpy(), w2c.detach().cpu().double().numpy()
    return np.concatenate([[K[0, 0], K[1, 1], K[0, 2], K[1, 2]], w2c[:3, :3].ravel(),
                           w2c[:3, 3]]).astype(np.float32)


@cancellable
def rasterize_cpu(means, quats, log_scales, opacity_logits, colors, K, w2c, width, height, near,
                  low_pass, grad_rows=None):
    """Colour sum without background (H,W,3), alpha-weighted depth sum (H,W), alpha (H,W).
    ``grad_rows``: the only Gaussians whose gradients are used (the others' are zero).

    A Ctrl-C inside the kernels or torch's autograd machinery comes out as
    ``Cancelled`` (core/model/interrupt.py), never a ``SystemError``.
    """
    inputs = (means, quats, log_scales, opacity_logits, colors)
    backward = torch.is_grad_enabled() and any(t.requires_grad for t in inputs)
    rows = None if grad_rows is None else np.asarray(torch.as_tensor(grad_rows).cpu())
    return _RasterizeCPU.apply(*inputs, camera_array(K, w2c), int(width), int(height),
                               float(near), float(low_pass), backward, rows)
