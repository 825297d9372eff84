"""Differentiable SSIM (11x11 Gaussian window, sigma 1.5, zero padding, as in 3DGS).

The five local moments (mu_x, mu_y, E[x^2], E[y^2], E[xy]) are filtered together: one grouped
separable convolution (a row pass then a column pass) over all channels at once, the fastest torch
form on CPU (shared/notes/cpu-rasterizer.md).
"""

from __future__ import annotations

import functools

import torch
import torch.nn.functional as F

C1 = 0.01 ** 2
C2 = 0.03 ** 2


@functools.lru_cache(maxsize=8)
def _kernel(size: int, sigma: float, channels: int, dtype: torch.dtype) -> tuple[torch.Tensor, ...]:
    x = torch.arange(size, dtype=torch.float64) - (size - 1) / 2
    g = torch.exp(-x ** 2 / (2 * sigma ** 2))
    g = (g / g.sum()).to(dtype)
    return (g.view(1, 1, 1, size).repeat(channels, 1, 1, 1),
            g.view(1, 1, size, 1).repeat(channels, 1, 1, 1))


def ssim_map(x: torch.Tensor, y: torch.Tensor, size: int = 11, sigma: float = 1.5) -> torch.Tensor:
    """Per-pixel SSIM of images ``x``, ``y`` (H,W,C) in [0,1], averaged over channels -> (H,W)."""
    c = x.shape[-1]
    a = x.permute(2, 0, 1)
    b = y.permute(2, 0, 1)
    stack = torch.cat([a, b, a * a, b * b, a * b], 0).unsqueeze(0)  # (1, 5C, H, W)
    row, col = _kernel(size, float(sigma), 5 * c, x.dtype)
    pad = size // 2
    m = F.conv2d(F.conv2d(stack, row, padding=(0, pad), groups=5 * c), col, padding=(pad, 0),
                 groups=5 * c)[0]
    mu_x, mu_y, xx, yy, xy = m.split(c, 0)
    mu_xx, mu_yy, mu_xy = mu_x * mu_x, mu_y * mu_y, mu_x * mu_y
    s = ((2 * mu_xy + C1) * (2 * (xy - mu_xy) + C2)) / \
        ((mu_xx + mu_yy + C1) * (xx - mu_xx + yy - mu_yy + C2))
    return s.mean(0)


def ssim(x: torch.Tensor, y: torch.Tensor, mask: torch.Tensor | None = None,
         size: int = 11) -> torch.Tensor:
    """Mean SSIM of (H,W,C) images, over ``mask`` (H,W bool) pixels if given.

    Only the box where either image is not zero, grown by half the window, is filtered: a
    window of zeros in both images has SSIM exactly 1, and an object's frame (zero outside its
    mask) and its render (zero where no Gaussian reaches) are mostly that."""
    m = torch.ones(x.shape[:2], dtype=x.dtype, device=x.device) if mask is None else \
        mask.to(x.dtype)
    box = _active_box(x, y, size // 2)
    if box is None:
        return m.sum() / m.sum().clamp_min(1)
    r, c = box
    s = ssim_map(x[r, c], y[r, c], size)
    outside = m.sum() - m[r, c].sum()
    return ((s * m[r, c]).sum() + outside) / m.sum().clamp_min(1)


def _active_box(x: torch.Tensor, y: torch.Tensor, pad: int) -> tuple[slice, slice] | None:
    """Rows and columns of the box holding every pixel where ``x`` or ``y`` is not zero, grown
    by ``pad``; None when both are zero everywhere."""
    with torch.no_grad():
        nz = (x != 0).any(-1) | (y != 0).any(-1)
        rows, cols = torch.nonzero(nz.any(1)).view(-1), torch.nonzero(nz.any(0)).view(-1)
    if not len(rows):
        return None
    h, w = nz.shape
    return (slice(max(int(rows[0]) - pad, 0), min(int(rows[-1]) + pad + 1, h)),
            slice(max(int(cols[0]) - pad, 0), min(int(cols[-1]) + pad + 1, w)))
