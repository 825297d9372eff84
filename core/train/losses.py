"""Image losses of a render against a captured view: L1, SSIM, depth L1, alpha L1.

All are means over object pixels, so their weights do not depend on the image size or on how much
of the image the object covers.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

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
                      lambda_ssim: float = 0.2, noise_sigmas: float = 0.0,
                      exposure: bool = False) -> torch.Tensor:
    """A loss that pixels no model explains cannot drag (an unseen interior revealed by an open
    door, an arm, a shadow, a flying depth pixel).

    Per pixel, the errors of colour (mean |Δrgb|), depth (|Δz| in ``depth_unit``, where measured
    inside the mask) and alpha (|alpha − mask|) are scaled by their sigmas and summed into r;
    the pixel costs ρ(r) = r / (1 + r): L1-like near zero (precise fits), saturating at 1 for
    pixels that stay wrong whatever the parameters do, so their gradient fades. Summed over the
    image and divided by the object pixels; plus ``λ_ssim (1 − SSIM)`` over the pixels with
    r < 1.

    ``noise_sigmas``: the depth scale is at least this many of the view's measured depth noise
    (``v.depth_noise``): a far camera's centimetres of noise would otherwise put every pixel in
    the saturated part of ρ, where no pixel pulls. ``exposure``: the render's colour is scaled
    by the frame's exposure gain, the median ratio of frame to render colour over the object
    pixels the render covers (a constant of the step: auto-exposure changes the whole frame's
    brightness, and an uncorrected gain of 10 % is a colour error on every pixel).
    Where the view carries ``mask_offsets`` (its mask grown and shrunk by a few pixels), the
    offset that best matches the render's alpha is the frame's mask for this step (a constant,
    like the gain): a segmentation a pixel too wide or too narrow all round otherwise turns
    into colour and alpha errors along the whole silhouette that outweigh a part's motion.

    Where ``v.occluder_depth`` shows something that is not the object (an arm, a hand), a render
    whose surface there lies behind it (or is empty) is not compared: the object is hidden there.
    """
    v = matched_mask(r, v)
    rgb = r.rgb * exposure_gain(r, v) if exposure else r.rgb
    colour = (rgb - v.rgb).abs().mean(-1) / sigma_rgb
    scale = max(sigma_depth * depth_unit, noise_sigmas * v.depth_noise)
    depth = torch.where(v.depth_valid, (r.depth - v.depth).abs() / scale,
                        torch.zeros_like(r.depth))
    alpha = (r.alpha - v.mask).abs() / sigma_alpha
    res = colour + depth + alpha
    if v.occluder_depth is not None:
        occ = v.occluder_depth
        hidden = (occ > 0) & ((r.depth <= 0) | (r.depth > occ - scale))
        res = torch.where(hidden.detach(), torch.zeros_like(res), res)
    loss = (res / (1 + res)).sum() / v.pixels
    if lambda_ssim:
        loss = loss + lambda_ssim * (1 - ssim(rgb, v.rgb, (res.detach() < 1).float()))
    return loss


@torch.no_grad()
def matched_mask(r: RenderOutput, v: View) -> View:
    """``v`` with the mask offset (of ``v.mask_offsets``) nearest the render's alpha (L1), its
    colour and depth validity masked by it; ``v`` itself when it has no offsets."""
    if v.mask_offsets is None:
        return v
    cost = (v.mask_offsets - r.alpha[None]).abs().flatten(1).sum(1)
    mask = v.mask_offsets[int(torch.argmin(cost))]
    rgb = v.rgb if v.rgb_full is None else v.rgb_full * mask[..., None]
    return replace(v, mask=mask, rgb=rgb, depth_valid=(v.depth > 0) & (mask > 0.5),
                   mask_offsets=None)


@torch.no_grad()
def exposure_gain(r: RenderOutput, v: View, lo: float = 0.5, hi: float = 2.0) -> torch.Tensor:
    """The frame's exposure relative to the render: the median of frame / render brightness over
    the object pixels the render covers and that are not dark (ratios of dark pixels are noise);
    1 when fewer than 16 such pixels; clamped to [lo, hi]."""
    a = r.rgb.mean(-1)
    b = v.rgb.mean(-1)
    ok = (v.mask > 0.5) & (r.alpha > 0.5) & (a > 0.05) & (b > 0.02)
    if int(ok.sum()) < 16:
        return torch.ones((), dtype=r.rgb.dtype, device=r.rgb.device)
    return (b[ok] / a[ok]).median().clamp(lo, hi)
