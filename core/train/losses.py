"""Image losses of a render against a captured view: L1, SSIM, depth L1, alpha L1.

All are means over object pixels, so their weights do not depend on the image size or on how much
of the image the object covers.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from ..render.rasterize import RenderOutput
from .ssim import ssim
from .views import View


@dataclass
class LossWeights:
    """``(1 - ssim) L1 + ssim (1 - SSIM) + depth / unit * depth L1 + alpha * alpha L1``."""

    ssim: float = 0.2
    depth: float = 0.1     # per depth unit (the caller's, e.g. 1% of the object size)
    alpha: float = 0.5


def l1(rgb: torch.Tensor, target: torch.Tensor, pixels: int) -> torch.Tensor:
    """Absolute colour error summed over the image, per channel and object pixel (``target`` is
    zero outside the object, so a render that is black there adds nothing)."""
    return (rgb - target).abs().sum() / (3 * pixels)


def photometric(rgb: torch.Tensor, target: torch.Tensor, pixels: int,
                lambda_ssim: float) -> torch.Tensor:
    """``(1 - lambda_ssim) L1 + lambda_ssim (1 - SSIM)`` as in 3DGS."""
    return (1 - lambda_ssim) * l1(rgb, target, pixels) + lambda_ssim * (1 - ssim(rgb, target))


def depth_l1(depth: torch.Tensor, target: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
    """Mean absolute depth error (m) over the ``valid`` pixels (measured and inside the object)."""
    return (depth - target)[valid].abs().mean()


def alpha_l1(alpha: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Mean absolute error of the accumulated alpha against the object mask (keeps the background
    empty)."""
    return (alpha - mask).abs().mean()


def view_loss(r: RenderOutput, v: View, w: LossWeights, depth_unit: float) -> torch.Tensor:
    """The weighted sum of the losses of render ``r`` against view ``v``; depth errors are
    measured in ``depth_unit`` metres."""
    loss = photometric(r.rgb, v.rgb, v.pixels, w.ssim)
    if w.depth and v.depth_valid.any():
        loss = loss + w.depth / depth_unit * depth_l1(r.depth, v.depth, v.depth_valid)
    if w.alpha:
        loss = loss + w.alpha * alpha_l1(r.alpha, v.mask)
    return loss


def robust_image_loss(r: RenderOutput, v: View, *, depth_unit: float, sigma_rgb: float = 0.1,
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

    Where ``v.occluder_depth`` shows something that is not the object (an arm, a hand), a render
    whose surface there lies behind it (or is empty) is not compared: the object is hidden there.
    """
    colour = (r.rgb - v.rgb).abs().mean(-1) / sigma_rgb
    depth = torch.where(v.depth_valid, (r.depth - v.depth).abs() / (sigma_depth * depth_unit),
                        torch.zeros_like(r.depth))
    alpha = (r.alpha - v.mask).abs() / sigma_alpha
    res = colour + depth + alpha
    if v.occluder_depth is not None:
        occ = v.occluder_depth
        hidden = (occ > 0) & ((r.depth <= 0) | (r.depth > occ - sigma_depth * depth_unit))
        res = torch.where(hidden.detach(), torch.zeros_like(res), res)
    loss = (res / (1 + res)).sum() / v.pixels
    if lambda_ssim:
        loss = loss + lambda_ssim * (1 - ssim(r.rgb, v.rgb, (res.detach() < 1).float()))
    return loss
