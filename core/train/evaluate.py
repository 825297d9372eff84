"""Figures of a splat against captured views: PSNR of the object pixels and depth MAE.

- PSNR: the render over a black background vs the captured image, MSE over the 3 channels of the
  pixels inside the mask (values in [0,1]), ``PSNR = -10 log10(MSE)``;
- depth MAE: mean |rendered depth - measured depth| in mm over pixels inside the mask with a valid
  measured depth (rendered depth is 0 where nothing was rendered; those count).
"""

from __future__ import annotations

import math

import torch

from ..render.rasterize import RenderOutput
from .params import render_params
from .views import View


def psnr(mse: float) -> float:
    """PSNR (dB) of a mean squared error of values in [0,1]."""
    return -10 * math.log10(max(mse, 1e-12))


@torch.no_grad()
def view_figures(r: RenderOutput, v: View) -> dict[str, float]:
    """PSNR (dB) and depth MAE (mm) of one render ``r`` against its view ``v``."""
    mse = float(((r.rgb - v.rgb) ** 2)[v.mask.bool()].mean())
    mae = float((r.depth - v.depth)[v.depth_valid].abs().mean()) * 1000
    return {"psnr": psnr(mse), "depth_mm": mae}


@torch.no_grad()
def evaluate(params: dict[str, torch.Tensor], views: list[View], backend: str = "auto"
             ) -> dict[str, float]:
    """PSNR of the object pixels (dB) and depth MAE (mm) pooled over ``views``."""
    se, n_px, ae, n_d = 0.0, 0, 0.0, 0
    for v in views:
        out = render_params(params, v, backend)
        m = v.mask.bool()
        se += float(((out.rgb - v.rgb)[m] ** 2).sum())
        n_px += 3 * int(m.sum())
        ae += float((out.depth - v.depth)[v.depth_valid].abs().sum())
        n_d += int(v.depth_valid.sum())
    return {"psnr": psnr(se / max(n_px, 1)), "depth_mae_mm": 1000 * ae / max(n_d, 1)}
