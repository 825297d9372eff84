"""Image losses shared by the stages that fit a splat to RGB-D frames.

``image_loss``: ``(1 - λ_ssim) L1 + λ_ssim (1 - SSIM)`` of the render (black background) against
the masked image, L1 summed over the image and divided by the object pixels; plus a depth term
over pixels measured inside the mask, in units of ``depth_unit`` (plain L1, or Huber with
threshold 1 unit, whose gradient is bounded so pixels no model explains cannot dominate); plus
``λ_alpha`` times the mean |alpha − mask|.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from .ssim import ssim


def image_loss(r, v, *, lambda_ssim: float = 0.2, lambda_depth: float = 0.1,
               depth_unit: float = 0.01, lambda_alpha: float = 0.5,
               robust: bool = False) -> torch.Tensor:
    """Loss of render ``r`` (rgb, depth, alpha) against view ``v`` (rgb, mask, depth,
    depth_valid, pixels), as in the module doc."""
    l1 = (r.rgb - v.rgb).abs().sum() / (3 * v.pixels)
    loss = (1 - lambda_ssim) * l1 + lambda_ssim * (1 - ssim(r.rgb, v.rgb))
    if lambda_depth and bool(v.depth_valid.any()):
        err = (r.depth - v.depth)[v.depth_valid] / depth_unit
        d = F.huber_loss(err, torch.zeros_like(err), delta=1.0) if robust else err.abs().mean()
        loss = loss + lambda_depth * d
    if lambda_alpha:
        loss = loss + lambda_alpha * (r.alpha - v.mask).abs().mean()
    return loss


def robust_image_loss(r, v, *, depth_unit: float, sigma_rgb: float = 0.1,
                      sigma_depth: float = 2.0, sigma_alpha: float = 0.5,
                      lambda_ssim: float = 0.2) -> torch.Tensor:
    """A loss that pixels no model explains cannot drag (an unseen interior revealed by an open
    door, an arm, a shadow, a flying depth pixel).

    Per pixel, the errors of colour (mean |Δrgb|), depth (|Δz| in ``depth_unit``, where measured
    inside the mask) and alpha (|alpha − mask|) are scaled by their sigmas and summed into r;
    the pixel costs ρ(r) = r / (1 + r): L1-like near zero (precise fits), saturating at 1 for
    pixels that stay wrong whatever the parameters do, so their gradient fades. Summed over the
    image and divided by the object pixels; plus ``λ_ssim (1 − SSIM)`` over the pixels with
    r < 1.
    """
    colour = (r.rgb - v.rgb).abs().mean(-1) / sigma_rgb
    depth = torch.where(v.depth_valid, (r.depth - v.depth).abs() / (sigma_depth * depth_unit),
                        torch.zeros_like(r.depth))
    alpha = (r.alpha - v.mask).abs() / sigma_alpha
    res = colour + depth + alpha
    loss = (res / (1 + res)).sum() / v.pixels
    if lambda_ssim:
        loss = loss + lambda_ssim * (1 - ssim(r.rgb, v.rgb, (res.detach() < 1).float()))
    return loss
