"""Differentiable Gaussian splat rasterizer: ``rasterize`` (raw tensors) and ``render`` (a camera).

Pipeline: SH colours in torch (autograd), EWA projection, a single depth sort of the visible
Gaussians, then front-to-back alpha compositing, by one of the backends:

- ``"cpu"``: numba kernels for projection and compositing with hand-written backward, wrapped in
  a torch.autograd.Function (core/render/cpu/backend.py);
- ``"reference"``: dense pure-torch compositing (core/render/reference.py), slow, for tests;
- ``"gsplat"``: gsplat's CUDA rasterizer (only when CUDA and gsplat are importable);
- ``"auto"``: gsplat for CUDA tensors when available, else ``"cpu"``.

Outputs: rgb (H,W,3) over ``background``; depth (H,W) = alpha-weighted z-depth / alpha (0 where
alpha < 1e-6), each Gaussian contributing its planar depth at the pixel (the linearised depth of
its max-density point along the pixel's ray, core/render/constants.py; gsplat: its centre depth);
alpha (H,W) = 1 - final transmittance.
"""

from __future__ import annotations

from typing import NamedTuple

import torch

from .device import resolve_backend
from .gaussians import Gaussians
from .constants import LOW_PASS, NEAR_PLANE
from .cpu.project import as_tensor, project
from .reference import composite_reference
from .sh import eval_sh_colors

ALPHA_EPS = 1e-6


class RenderOutput(NamedTuple):
    """Rendered image (H,W,3), expected depth (H,W) and accumulated alpha (H,W)."""

    rgb: torch.Tensor
    depth: torch.Tensor
    alpha: torch.Tensor


def camera_centre(w2c: torch.Tensor) -> torch.Tensor:
    """The camera's centre in world coordinates from its world-to-camera matrix (4x4)."""
    return -w2c[:3, :3].T @ w2c[:3, 3]


def rasterize(means: torch.Tensor, quats: torch.Tensor, log_scales: torch.Tensor,
              opacity_logits: torch.Tensor, sh: torch.Tensor, K, w2c, width: int, height: int,
              background=None, backend: str = "auto", near: float = NEAR_PLANE,
              low_pass: float = LOW_PASS, grad_rows: torch.Tensor | None = None
              ) -> RenderOutput:
    """Render N Gaussians with intrinsics ``K`` (3x3) and ``w2c`` (4x4, OpenCV axes).

    ``low_pass``: the 2D dilation in px^2 (this project's default, core/render/constants.py; 0.3 is
    the original 3DGS value, for splats trained with it).

    Differentiable w.r.t. every Gaussian input (and ``background`` if it is a tensor).
    ``grad_rows``: indices of the only Gaussians whose gradients the caller uses (a fit that
    moves one part); the others' may then be zero (the CPU backend skips their backward).
    """
    width, height = int(width), int(height)
    if width < 1 or height < 1:
        raise ValueError(f"image size must be positive, not {width}x{height}")
    Gaussians(means, quats, log_scales, opacity_logits, sh)  # raises ValueError on bad shapes
    backend = resolve_backend(backend, means.device)
    K, w2c = as_tensor(K, means), as_tensor(w2c, means)
    bg = (torch.zeros(3, dtype=means.dtype, device=means.device) if background is None
          else as_tensor(background, means).reshape(3))
    if backend == "gsplat":
        from .gsplat import rasterize_gsplat
        rgb, depth, alpha = rasterize_gsplat(means, quats, log_scales, opacity_logits, sh, K, w2c,
                                             width, height, bg, near, low_pass)
        depth = torch.where(alpha > ALPHA_EPS, depth, torch.zeros_like(depth))
        return RenderOutput(rgb, depth, alpha)

    colors = eval_sh_colors(sh, means, camera_centre(w2c))
    if backend == "reference":
        proj = project(means, quats, log_scales, K, w2c, width, height, near, low_pass)
        with torch.no_grad():
            vis = torch.nonzero(proj.visible).squeeze(1)
            order = vis[torch.argsort(proj.depths[vis], stable=True)]
        rgb, dsum, alpha = composite_reference(proj.means2d, proj.conics,
                                               torch.sigmoid(opacity_logits), colors, proj.depths,
                                               proj.slopes, proj.extent, order, width, height, bg)
    else:
        from .cpu.backend import rasterize_cpu
        csum, dsum, alpha = rasterize_cpu(means, quats, log_scales, opacity_logits, colors, K,
                                          w2c, width, height, near, low_pass, grad_rows)
        rgb = csum + (1.0 - alpha)[..., None] * bg
    valid = alpha > ALPHA_EPS
    depth = torch.where(valid, dsum / torch.where(valid, alpha, torch.ones_like(alpha)),
                        torch.zeros_like(dsum))
    return RenderOutput(rgb, depth, alpha)


def render(gaussians, camera, background=None, backend: str = "auto") -> RenderOutput:
    """Render ``gaussians`` (render.gaussians.Gaussians) with a ``model.cameras.Camera``."""
    g = gaussians
    return rasterize(g.means, g.quats, g.log_scales, g.opacity_logits, g.sh, camera.K,
                     camera.w2c, camera.width, camera.height, background, backend)
