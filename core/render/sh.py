"""Real spherical harmonics (degree 0..3) for view-dependent Gaussian colour, as in 3DGS.

Colour of a Gaussian seen along the unit direction ``d`` (from the camera centre to the Gaussian
mean, world frame) is ``max(sum_k sh[k] * Y_k(d) + 0.5, 0)`` per channel; ``sh[:, 0]`` is the DC
term, so a constant colour ``c`` has ``sh[:, 0] = (c - 0.5) / C0``.
"""

from __future__ import annotations

import math

import torch

C0 = 0.28209479177387814
C1 = 0.4886025119029199
C2 = (1.0925484305920792, -1.0925484305920792, 0.31539156525252005,
      -1.0925484305920792, 0.5462742152960396)
C3 = (-0.5900435899266435, 2.890611442640554, -0.4570457994644658, 0.3731763325901154,
      -0.4570457994644658, 1.445305721320277, -0.5900435899266435)


def sh_degree(num_coeffs: int) -> int:
    """SH degree from the number of coefficients K = (degree+1)^2 (degree 0..3)."""
    degree = int(round(math.sqrt(num_coeffs))) - 1
    if (degree + 1) ** 2 != num_coeffs or not 0 <= degree <= 3:
        raise ValueError(f"SH coefficient count must be 1, 4, 9 or 16, not {num_coeffs}")
    return degree


def sh0_to_rgb(sh0):
    """Colour of DC coefficients ``sh0`` (tensor or array, (..., 3)), before clamping: the
    view-independent part of a Gaussian's colour."""
    return C0 * sh0 + 0.5


def rgb_to_sh0(rgb):
    """DC coefficient giving colour ``rgb`` (tensor or array, (..., 3); inverse of
    :func:`sh0_to_rgb`)."""
    return (rgb - 0.5) / C0


def sh_basis(degree: int, dirs: torch.Tensor) -> torch.Tensor:
    """Basis values Y_k(dirs) for unit directions (N,3) -> (N, (degree+1)^2)."""
    x, y, z = dirs.unbind(-1)
    out = [torch.full_like(x, C0)]
    if degree >= 1:
        out += [-C1 * y, C1 * z, -C1 * x]
    if degree >= 2:
        xx, yy, zz, xy, yz, xz = x * x, y * y, z * z, x * y, y * z, x * z
        out += [C2[0] * xy, C2[1] * yz, C2[2] * (2.0 * zz - xx - yy), C2[3] * xz,
                C2[4] * (xx - yy)]
    if degree >= 3:
        out += [C3[0] * y * (3.0 * xx - yy), C3[1] * xy * z, C3[2] * y * (4.0 * zz - xx - yy),
                C3[3] * z * (2.0 * zz - 3.0 * xx - 3.0 * yy), C3[4] * x * (4.0 * zz - xx - yy),
                C3[5] * z * (xx - yy), C3[6] * x * (xx - 3.0 * yy)]
    return torch.stack(out, dim=-1)


def eval_sh_colors(sh: torch.Tensor, means: torch.Tensor, cam_center: torch.Tensor) -> torch.Tensor:
    """Per-Gaussian RGB (N,3) seen from ``cam_center``: SH(view dir) + 0.5, clamped at 0."""
    degree = sh_degree(sh.shape[1])
    if degree == 0:
        raw = C0 * sh[:, 0]
    else:
        dirs = means - cam_center
        dirs = dirs / dirs.norm(dim=-1, keepdim=True).clamp_min(1e-12)
        raw = (sh_basis(degree, dirs).unsqueeze(-1) * sh).sum(dim=1)
    return (raw + 0.5).clamp_min(0.0)
