"""Planar per-pixel depth of a splat: every Gaussian as a small plane patch (worker side, torch).

The rasterizer's depth blends each Gaussian's centre depth. On a surface seen at a slant the
Gaussians overlapping a pixel have centres at different depths and the nearer ones composite
first, so the blend is biased toward the camera (measured: 10-20 mm on the synthetic benchmark
at 160x120, where a pixel spans ~15 mm). Here Gaussian i contributes the depth of its own plane
(through its mean, normal = the axis of its smallest scale) at pixel p, linearised at the mean:
``z_i + a_i . (p - m_i)``, with ``a_i`` the plane's depth change per pixel (limited to 3 pixel
footprints). That is affine in p, so the blend needs only three per-Gaussian constants
``(a_u, a_v, z_i - a_i . m_i)``, rendered as the colour channels of one more rasterize call.
"""

from __future__ import annotations

import torch

from .raster_project import as_tensor, quat_to_rotmat
from .rasterize import ALPHA_EPS, rasterize
from .sh import C0

MAX_SLOPE = 3.0  # pixel footprints of depth change per pixel


def planar_depth(means: torch.Tensor, quats: torch.Tensor, log_scales: torch.Tensor,
                 opacity_logits: torch.Tensor, K, w2c, width: int, height: int,
                 backend: str = "auto") -> torch.Tensor:
    """Planar expected depth (H,W), alpha-normalised (0 where nothing is rendered)."""
    K, w2c = as_tensor(K, means), as_tensor(w2c, means)
    R = quat_to_rotmat(quats)
    axis = log_scales.argmin(-1)
    normal = R.gather(2, axis[:, None, None].expand(-1, 3, 1)).squeeze(-1)
    Rw, tw = w2c[:3, :3], w2c[:3, 3]
    m = means @ Rw.T + tw
    n = normal @ Rw.T
    fx, fy = K[0, 0], K[1, 1]
    z = m[:, 2].clamp_min(1e-3)
    nm = (n * m).sum(-1)
    nm = torch.where(nm.abs() < 1e-6, torch.full_like(nm, 1e-6), nm)
    limit = MAX_SLOPE * z / fx
    a_u = (-n[:, 0] * z * z / (fx * nm)).clamp(-limit, limit)
    a_v = (-n[:, 1] * z * z / (fy * nm)).clamp(-limit, limit)
    u, v = fx * m[:, 0] / z, fy * m[:, 1] / z  # pixel position relative to the principal point
    values = torch.stack([a_u, a_v, m[:, 2] - a_u * u - a_v * v], -1)
    offset = float(values.detach().abs().max()) + 1.0  # colours must stay >= 0
    sh = ((values + offset - 0.5) / C0).unsqueeze(1)
    out = rasterize(means, quats, log_scales, opacity_logits, sh, K, w2c, width, height, None,
                    backend)
    s = out.rgb - offset * out.alpha[..., None]
    pu = torch.arange(width, dtype=means.dtype, device=means.device) + 0.5 - K[0, 2]
    pv = torch.arange(height, dtype=means.dtype, device=means.device) + 0.5 - K[1, 2]
    num = pu[None, :] * s[..., 0] + pv[:, None] * s[..., 1] + s[..., 2]
    valid = out.alpha > ALPHA_EPS
    return torch.where(valid, num / torch.where(valid, out.alpha, torch.ones_like(out.alpha)),
                       torch.zeros_like(num))
