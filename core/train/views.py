"""Captured frames as tensors: what a training or evaluation step compares a render with."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from ..model.capture import Frame


@dataclass
class View:
    """One captured frame as tensors on the training device."""

    index: int              # the caller's index of the frame (e.g. position in capture.static)
    K: torch.Tensor
    w2c: torch.Tensor
    width: int
    height: int
    rgb: torch.Tensor       # (H,W,3) in [0,1], zero outside the mask
    mask: torch.Tensor      # (H,W) float 0/1
    depth: torch.Tensor     # (H,W) metres, 0 = no measurement
    depth_valid: torch.Tensor  # (H,W) bool: measured and inside the mask
    pixels: int             # object pixels (at least 1)
    # known occluders (core/stages/optimise/occluders.py): Gaussians rendered with the model (a
    # robot twin), and the depth of other things in front that are not the object (0 = none)
    occluder: Any = None
    occluder_depth: torch.Tensor | None = None
    # the camera's depth noise at this resolution (m, one sigma; 0 = not measured), measured from
    # its own depth maps (core/geometry/noise.py) where a loss must follow the capture's noise
    depth_noise: float = 0.0
    # masks are never exact: the mask grown or shrunk by -D..D pixels (2D+1,H,W), and the frame's
    # colour without the mask (H,W,3); set where a loss picks each frame's offset (optimise)
    mask_offsets: torch.Tensor | None = None
    rgb_full: torch.Tensor | None = None


def make_view(index: int, f: Frame, device: torch.device) -> View:
    """Frame ``f`` (the caller's frame number ``index``) as tensors on ``device``."""
    def t(a: np.ndarray) -> torch.Tensor:
        return torch.as_tensor(np.ascontiguousarray(a), dtype=torch.float32, device=device)
    h, w = f.rgb.shape[:2]
    mask = np.ones((h, w), bool) if f.mask is None else f.mask.astype(bool)
    depth = np.zeros((h, w), np.float32) if f.depth is None else np.nan_to_num(f.depth)
    rgb = f.rgb.astype(np.float32) / 255.0 * mask[..., None]
    return View(index, t(f.camera.K), t(f.camera.w2c), w, h, t(rgb), t(mask), t(depth),
                torch.as_tensor(mask & (depth > 0), device=device), max(int(mask.sum()), 1))
