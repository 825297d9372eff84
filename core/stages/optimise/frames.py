"""The interaction frames as tensors, per (time, fixed camera), with a coarse-to-fine pyramid.

Level 0 is full resolution; level ``l`` halves the image ``l`` times (colour and mask averaged
over 2x2 blocks, depth averaged over its measured pixels and kept only where the whole block is
measured and inside the mask, so a depth edge never yields an in-between depth).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import torch
import torch.nn.functional as F

from ...model.capture import Capture
from ...train.views import View, make_view


@dataclass
class FrameSet:
    """Interaction views grouped by time: ``levels[l][i]`` is frame ``i`` at pyramid level ``l``."""

    times: list[int]                 # sorted interaction times; time index = position here
    time_index: list[int]            # per frame: its time's index in ``times``
    camera: list[int]                # per frame: fixed-camera index (order of first appearance)
    levels: list[list[View]]

    def at_time(self, ti: int) -> list[int]:
        """Frame indices of time index ``ti``."""
        return [i for i, t in enumerate(self.time_index) if t == ti]


def downsample(v: View) -> View:
    """``v`` at half resolution (see the module doc)."""
    def pool(x: torch.Tensor) -> torch.Tensor:
        return F.avg_pool2d(x[None, None] if x.ndim == 2 else x.permute(2, 0, 1)[None], 2)[0]
    h, w = v.height // 2, v.width // 2
    crop = (slice(0, 2 * h), slice(0, 2 * w))
    mask = pool(v.mask[crop])[0]
    rgb = pool(v.rgb[crop]).permute(1, 2, 0)
    valid = v.depth_valid[crop].float()
    cover = pool(valid)[0]
    depth = pool(v.depth[crop] * valid)[0] / cover.clamp_min(1e-6)
    full = cover > 0.999
    K = v.K.clone()
    K[:2] *= 0.5  # pixel centres at +0.5 (the rasterizer's convention): a plain scaling
    return replace(v, K=K, width=w, height=h, rgb=rgb, mask=mask,
                   depth=torch.where(full, depth, torch.zeros_like(depth)), depth_valid=full,
                   pixels=max(int((mask > 0.5).sum()), 1))


def interaction_frames(capture: Capture, device: torch.device, min_size: int = 24) -> FrameSet:
    """All interaction frames with a time (checked by ``stage.check``: there are some, all with
    depth); pyramid levels while the image stays >= ``min_size``."""
    frames = [f for f in capture.interaction if f.time is not None]
    times = sorted({int(f.time) for f in frames})
    cams: list[bytes] = []
    cam_idx = []
    for f in frames:
        key = f.camera.w2c.round(6).tobytes() + f.camera.K.round(6).tobytes()
        if key not in cams:
            cams.append(key)
        cam_idx.append(cams.index(key))
    level = [make_view(i, f, device) for i, f in enumerate(frames)]
    levels = [level]
    while min(level[0].width, level[0].height) // 2 >= min_size:
        level = [downsample(v) for v in level]
        levels.append(level)
    return FrameSet(times, [times.index(int(f.time)) for f in frames], cam_idx, levels)
