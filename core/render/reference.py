"""Slow, exact pure-torch compositing: the ground truth for the numba kernels' values and gradients.

Every pixel evaluates every visible Gaussian (in depth order) whose 3 sigma box contains it,
with the same rules as the kernels: skip where ``power > 4.5`` or ``alpha < 1/255``,
``alpha = min(0.99, opacity * exp(-power))``, and stop before the first Gaussian that would bring
the transmittance below 1e-4. Pixels are processed in square blocks only to bound memory;
autograd through it gives the reference gradients. Gaussian i's depth at pixel p is planar,
``depth_i + slope_i . (p - mean2d_i)`` (core/render/constants.py).
"""

from __future__ import annotations

import torch

from .constants import ALPHA_MAX, ALPHA_MIN, POWER_CUTOFF, T_MIN


def composite_reference(means2d: torch.Tensor, conics: torch.Tensor, opacities: torch.Tensor,
                        colors: torch.Tensor, depths: torch.Tensor, slopes: torch.Tensor,
                        extent: torch.Tensor,
                        order: torch.Tensor, width: int, height: int, background: torch.Tensor,
                        block: int = 16) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Blend the Gaussians ``order`` (visible ones, front to back) -> rgb (H,W,3),
    alpha-weighted depth sum (H,W) and alpha (H,W)."""
    m, con, op = means2d[order], conics[order], opacities[order]
    col, dep, ext = colors[order], depths[order], extent[order]
    slo = slopes[order]
    rows_rgb, rows_d, rows_a = [], [], []
    for r0 in range(0, height, block):
        r1 = min(r0 + block, height)
        blk_rgb, blk_d, blk_a = [], [], []
        for c0 in range(0, width, block):
            c1 = min(c0 + block, width)
            rgb, d, a = _block(m, con, op, col, dep, slo, ext, r0, r1, c0, c1, background)
            blk_rgb.append(rgb), blk_d.append(d), blk_a.append(a)
        rows_rgb.append(torch.cat(blk_rgb, 1)), rows_d.append(torch.cat(blk_d, 1))
        rows_a.append(torch.cat(blk_a, 1))
    return torch.cat(rows_rgb, 0), torch.cat(rows_d, 0), torch.cat(rows_a, 0)


def _block(m, con, op, col, dep, slo, ext, r0, r1, c0, c1, background):
    h, w = r1 - r0, c1 - c0
    with torch.no_grad():
        sel = ((m[:, 0] + ext[:, 0] >= c0 + 0.5) & (m[:, 0] - ext[:, 0] <= c1 - 0.5)
               & (m[:, 1] + ext[:, 1] >= r0 + 0.5) & (m[:, 1] - ext[:, 1] <= r1 - 0.5))
        idx = torch.nonzero(sel).squeeze(1)  # keeps the depth order
    if idx.numel() == 0:
        zeros = torch.zeros(h, w, dtype=m.dtype, device=m.device)
        return background.expand(h, w, 3).clone(), zeros, zeros
    m, con, op, col, dep, slo = m[idx], con[idx], op[idx], col[idx], dep[idx], slo[idx]
    ii, jj = torch.meshgrid(torch.arange(r0, r1, dtype=m.dtype, device=m.device) + 0.5,
                            torch.arange(c0, c1, dtype=m.dtype, device=m.device) + 0.5,
                            indexing="ij")
    dx = jj.reshape(-1, 1) - m[:, 0]
    dy = ii.reshape(-1, 1) - m[:, 1]
    power = 0.5 * (con[:, 0] * dx * dx + con[:, 2] * dy * dy) + con[:, 1] * dx * dy
    alpha = (op * torch.exp(-power)).clamp(max=ALPHA_MAX)
    with torch.no_grad():
        keep = (power <= POWER_CUTOFF) & (alpha >= ALPHA_MIN)
    alpha = torch.where(keep, alpha, torch.zeros_like(alpha))
    with torch.no_grad():
        keep = torch.cumprod(1.0 - alpha, dim=1) >= T_MIN
    alpha = torch.where(keep, alpha, torch.zeros_like(alpha))
    trans = torch.cumprod(1.0 - alpha, dim=1)
    t_before = torch.cat([torch.ones_like(trans[:, :1]), trans[:, :-1]], dim=1)
    weights = alpha * t_before
    t_final = trans[:, -1]
    rgb = weights @ col + t_final[:, None] * background
    planar = dep + slo[:, 0] * dx + slo[:, 1] * dy
    return (rgb.reshape(h, w, 3), (weights * planar).sum(1).reshape(h, w),
            (1.0 - t_final).reshape(h, w))
