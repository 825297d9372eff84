"""The interaction frames as tensors, per (time, fixed camera), with a coarse-to-fine pyramid.

Level 0 is full resolution; level ``l`` halves the image ``l`` times (colour and mask averaged
over 2x2 blocks, depth averaged over its measured pixels and kept only where the whole block is
measured, so a depth edge never yields an in-between depth; it counts as the object's where the
whole block is inside the mask). Masked frames also carry their mask grown and shrunk by up to
``mask_pixels`` (the loss picks the offset that fits each render: core/train/losses.py) and
their unmasked colour.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
import torch
import torch.nn.functional as F

from ...geometry.noise import noise_sigma
from ...model.capture import Capture, Frame
from ...train.views import View, make_view


@dataclass
class FrameSet:
    """Interaction views grouped by time: ``levels[l][i]`` is frame ``i`` at pyramid level ``l``."""

    times: list[int]                 # sorted interaction times; time index = position here
    time_index: list[int]            # per frame: its time's index in ``times``
    camera: list[int]                # per frame: fixed-camera index (order of first appearance)
    levels: list[list[View]]
    tool: dict[int, np.ndarray] = field(default_factory=dict)   # time -> robot tool pose (4x4)

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
    valid = (v.depth[crop] > 0).float()
    cover = pool(valid)[0]
    depth = pool(v.depth[crop] * valid)[0] / cover.clamp_min(1e-6)
    full = cover > 0.999
    K = v.K.clone()
    K[:2] *= 0.5  # pixel centres at +0.5 (the rasterizer's convention): a plain scaling
    occ = v.occluder_depth
    if occ is not None:   # the nearest occluder of each block
        near = -F.max_pool2d(torch.where(occ[crop] > 0, -occ[crop], -torch.inf)[None, None], 2)[0, 0]
        occ = torch.where(torch.isfinite(near), near, torch.zeros_like(near))
    offsets = None if v.mask_offsets is None else \
        F.avg_pool2d(v.mask_offsets[None, :, crop[0], crop[1]], 2)[0]
    rgb_full = None if v.rgb_full is None else pool(v.rgb_full[crop]).permute(1, 2, 0)
    return replace(v, K=K, width=w, height=h, rgb=rgb, mask=mask,
                   depth=torch.where(full, depth, torch.zeros_like(depth)),
                   depth_valid=full & (mask > 0.999),
                   pixels=max(int((mask > 0.5).sum()), 1), occluder_depth=occ,
                   mask_offsets=offsets, rgb_full=rgb_full)


def interaction_frames(capture: Capture, device: torch.device, min_size: int = 24,
                       occluders=None, mask_pixels: int = 2) -> FrameSet:
    """All interaction frames with a time (checked by ``stage.check``: there are some, all with
    depth); pyramid levels while the image stays >= ``min_size``. ``occluders(frame, view) ->
    view`` adds known occluders to each view (core/stages/optimise/occluders.py);
    ``mask_pixels``: how far a mask may be off all round (module doc)."""
    frames = [f for f in capture.interaction if f.time is not None]
    times = sorted({int(f.time) for f in frames})
    cams: list[bytes] = []
    cam_idx = []
    for f in frames:
        key = f.camera.w2c.round(6).tobytes() + f.camera.K.round(6).tobytes()
        if key not in cams:
            cams.append(key)
        cam_idx.append(cams.index(key))
    level = [with_mask_offsets(make_view(i, f, device), f, mask_pixels)
             for i, f in enumerate(frames)]
    if occluders is not None:
        level = [occluders(f, v) for f, v in zip(frames, level)]
    levels = [level]
    while min(level[0].width, level[0].height) // 2 >= min_size:
        level = [downsample(v) for v in level]
        levels.append(level)
    levels = with_noise(levels, cam_idx)
    return FrameSet(times, [times.index(int(f.time)) for f in frames], cam_idx, levels)


def with_mask_offsets(v: View, f: Frame, pixels: int) -> View:
    """``v`` with its mask shrunk and grown by ``-pixels..pixels`` (square structuring element)
    and the frame's unmasked colour; ``v`` as it is for a frame without a mask or ``pixels`` 0."""
    if f.mask is None or pixels <= 0:
        return v
    m = v.mask[None, None]
    grown = [F.max_pool2d(m, 2 * d + 1, 1, d)[0, 0] for d in range(1, pixels + 1)]
    shrunk = [-F.max_pool2d(-m, 2 * d + 1, 1, d)[0, 0] for d in range(pixels, 0, -1)]
    rgb = torch.as_tensor(f.rgb.astype("float32") / 255.0, device=v.rgb.device)
    return replace(v, mask_offsets=torch.stack(shrunk + [v.mask] + grown), rgb_full=rgb)


def with_noise(levels: list[list[View]], camera: list[int]) -> list[list[View]]:
    """The views with each camera's depth noise at each level (:func:`noise_sigma` over its
    frames; where a level has too few measured pixels to tell, half the finer level's: a 2x2
    average of independent noise)."""
    out: list[list[View]] = []
    for li, level in enumerate(levels):
        sigma = {}
        for c in set(camera):
            maps = [(v.depth * v.depth_valid).cpu().numpy() for v, ci in zip(level, camera)
                    if ci == c]
            s = noise_sigma(maps)
            if s <= 0 and li > 0:
                s = 0.5 * out[li - 1][camera.index(c)].depth_noise
            sigma[c] = s
        out.append([replace(v, depth_noise=sigma[c]) for v, c in zip(level, camera)])
    return out
