"""EWA projection of 3D Gaussians to screen-space conics (vectorised torch, autograd backward).

The model (3DGS / gsplat): camera-frame mean ``t = W p + w``; Gaussians with ``t_z <= near`` are
culled; 3D covariance ``R S S^T R^T`` (R from the normalised quaternion, S = exp(log_scales));
2D covariance ``J W Sigma W^T J^T + LOW_PASS I`` (the low-pass dilation, core/render/constants.py),
with the Jacobian evaluated at ``t`` whose x/z, y/z are clamped to 1.3x the field of view (as
gsplat does); the conic is the inverse 2D covariance. A Gaussian touches pixel centre ``p`` only
inside its 3 sigma ellipse (``power = 0.5 d^T conic d <= 4.5``, d = p - mean2d); ``extent`` holds
the half sizes of the ellipse's axis-aligned bounding box, ``3 sqrt(cov2d_xx)``, ``3
sqrt(cov2d_yy)``.
``slopes`` are the planar depth's change per pixel (core/render/constants.py): with ``M = W R`` and
``b = M^T t`` (the mean in the Gaussian's own frame), ``Sigma^-1 t = M (b / s^2)`` and
``t^T Sigma^-1 t = sum(b^2 / s^2)``, so no 3x3 inverse is needed.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import torch

from ..constants import FOV_PAD, LOW_PASS, MAX_SLOPE, NEAR_PLANE, SIGMA_CUTOFF

class Projected(NamedTuple):
    """Per-Gaussian screen-space quantities (N rows each)."""

    means2d: torch.Tensor   # (N,2) pixel coordinates
    conics: torch.Tensor    # (N,3) inverse 2D covariance (a, b, c): [[a, b], [b, c]]
    depths: torch.Tensor    # (N,) camera z
    slopes: torch.Tensor    # (N,2) planar depth change per pixel in x and y
    extent: torch.Tensor    # (N,2) half sizes of the 3 sigma box (no gradient)
    visible: torch.Tensor   # (N,) bool: in front of the near plane and overlapping the image


def quat_to_rotmat(quats: torch.Tensor) -> torch.Tensor:
    """Quaternions (N,4) w x y z (any norm > 0) -> rotation matrices (N,3,3)."""
    q = quats / quats.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    w, x, y, z = q.unbind(-1)
    return torch.stack([
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    ], dim=-1).reshape(-1, 3, 3)


def as_tensor(a, like: torch.Tensor) -> torch.Tensor:
    """``a`` (numpy or torch) as a tensor with ``like``'s dtype and device."""
    if isinstance(a, torch.Tensor):
        return a.to(dtype=like.dtype, device=like.device)
    return torch.as_tensor(np.asarray(a), dtype=like.dtype, device=like.device)


def project(means: torch.Tensor, quats: torch.Tensor, log_scales: torch.Tensor,
            K: torch.Tensor, w2c: torch.Tensor, width: int, height: int,
            near: float = NEAR_PLANE, low_pass: float = LOW_PASS) -> Projected:
    """Project Gaussians with intrinsics ``K`` (3x3) and world-to-camera ``w2c`` (4x4, OpenCV)."""
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    Rw, tw = w2c[:3, :3], w2c[:3, 3]
    t = means @ Rw.T + tw
    z = t[:, 2]
    in_front = z > near
    z = torch.where(in_front, z, torch.ones_like(z))  # keeps culled rows finite (zero gradient)
    x, y = t[:, 0], t[:, 1]

    tan_x, tan_y = 0.5 * width / fx, 0.5 * height / fy
    lim_x_pos, lim_x_neg = (width - cx) / fx + FOV_PAD * tan_x, cx / fx + FOV_PAD * tan_x
    lim_y_pos, lim_y_neg = (height - cy) / fy + FOV_PAD * tan_y, cy / fy + FOV_PAD * tan_y
    tx = z * torch.minimum(torch.maximum(x / z, -lim_x_neg), lim_x_pos)
    ty = z * torch.minimum(torch.maximum(y / z, -lim_y_neg), lim_y_pos)

    zero = torch.zeros_like(z)
    J = torch.stack([fx / z, zero, -fx * tx / (z * z),
                     zero, fy / z, -fy * ty / (z * z)], dim=-1).reshape(-1, 2, 3)
    R = quat_to_rotmat(quats)
    M = R * torch.exp(log_scales)[:, None, :]   # R S
    T = J @ Rw @ M                                                  # (N,2,3)
    cov = T @ T.transpose(1, 2)
    ca = cov[:, 0, 0] + low_pass
    cb = cov[:, 0, 1]
    cc = cov[:, 1, 1] + low_pass
    det = ca * cc - cb * cb
    ok = in_front & (det > 0)
    det = torch.where(ok, det, torch.ones_like(det))
    conics = torch.stack([cc / det, -cb / det, ca / det], dim=-1)
    means2d = torch.stack([fx * x / z + cx, fy * y / z + cy], dim=-1)
    slopes = depth_slopes(Rw @ R, torch.stack([x, y, z], -1), log_scales, fx, fy)

    with torch.no_grad():
        extent = SIGMA_CUTOFF * torch.stack([ca, cc], dim=-1).clamp_min(0).sqrt()
        lo, hi = means2d - extent, means2d + extent
        on_screen = (hi[:, 0] > 0) & (lo[:, 0] < width) & (hi[:, 1] > 0) & (lo[:, 1] < height)
        visible = ok & on_screen & torch.isfinite(means2d).all(-1) & torch.isfinite(extent).all(-1)
    return Projected(means2d, conics, torch.where(in_front, t[:, 2], zero),
                     torch.where(in_front[:, None], slopes, torch.zeros_like(slopes)), extent,
                     visible)


def depth_slopes(M: torch.Tensor, t: torch.Tensor, log_scales: torch.Tensor, fx, fy
                 ) -> torch.Tensor:
    """Planar depth change per pixel (N,2) of Gaussians with camera-from-local rotations ``M``
    (N,3,3), camera-frame means ``t`` (N,3) (z > 0) and ``log_scales`` (see the module doc)."""
    b = (M.transpose(1, 2) @ t[:, :, None])[:, :, 0]
    e = b * torch.exp(-2.0 * log_scales)
    c = (M @ e[:, :, None])[:, :, 0]
    q = (b * e).sum(-1)
    z = t[:, 2]
    out = []
    for col, f in ((c[:, 0], fx), (c[:, 1], fy)):
        a = -z * z * col / (q * f)
        lim = MAX_SLOPE * z / f
        out.append(torch.where(a > lim, lim, torch.where(a < -lim, -lim, a)))
    return torch.stack(out, -1)
