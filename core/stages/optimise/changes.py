"""What the frames show changing: pixels whose measurement differs from the same fixed camera's
closed state (its time-0 frame) beyond the capture's own noise.

Comparing a frame with its camera's time-0 frame cancels everything static (the splat's errors,
the room, the camera's registration), so a far, noisy capture still shows a door opening where a
comparison of the frame with a render could not (centimetres of depth noise, a splat that blurs
texture). Colour is compared after the exposure gain between the two frames, depth after a 3x3
median. Each threshold is ``sigmas`` times the robust spread (MAD) of the same difference between
consecutive times of the camera: from one time to the next most pixels do not move, so that
spread is the noise.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from ...train.views import View
from .frames import FrameSet


def median3(depth: torch.Tensor) -> torch.Tensor:
    """3x3 median of the measured depths (0 = none) around each pixel; 0 where fewer than 5 of
    the 9 are measured."""
    h, w = depth.shape
    cols = F.unfold(depth[None, None], 3, padding=1)[0]                  # (9, H*W)
    valid = cols > 0
    med = torch.nanmedian(torch.where(valid, cols, torch.nan), 0).values
    return torch.where(valid.sum(0) >= 5, torch.nan_to_num(med), torch.zeros_like(med)).view(h, w)


def colour_of(v: View) -> torch.Tensor:
    return v.rgb if v.rgb_full is None else v.rgb_full


def region_of(v: View) -> torch.Tensor:
    """The object's pixels, as wide as the mask may be."""
    return (v.mask if v.mask_offsets is None else v.mask_offsets[-1]) > 0.5


def _gain(a: View, b: View, region: torch.Tensor) -> torch.Tensor:
    """Exposure of ``a`` relative to ``b``: median brightness ratio over ``region``."""
    x, y = colour_of(a).mean(-1), colour_of(b).mean(-1)
    ok = region & (x > 0.02) & (y > 0.05)
    return (x[ok] / y[ok]).median() if int(ok.sum()) >= 16 else torch.ones(())


def _differences(a: View, b: View, da: torch.Tensor, db: torch.Tensor
                 ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Colour and depth differences of two frames of one camera, and the object region where
    they count (either frame's object, nothing known in front: an arm, a hand). Occluders
    inside the mask (the body's inside an opened part reveals, core/stages/optimise/
    occluders.py) count: the part's motion changed them."""
    region = region_of(a) | region_of(b)
    for v in (a, b):
        if v.occluder_depth is not None:
            region &= (v.occluder_depth <= 0) | (v.mask > 0.5)
    colour = (colour_of(a) / _gain(a, b, region) - colour_of(b)).abs().mean(-1)
    both = (da > 0) & (db > 0)
    depth = torch.where(both, (da - db).abs(), torch.zeros_like(da))
    return colour, depth, region


def _mad(values: list[torch.Tensor]) -> float:
    x = torch.cat([v.reshape(-1) for v in values])
    return 1.4826 * float(x.median()) if len(x) else 0.0


@torch.no_grad()
def frame_changes(frames: FrameSet, level: int = 0, sigmas: float = 4.0
                  ) -> dict[int, torch.Tensor]:
    """Per frame (of a camera with a time-0 frame, at a time other than 0): bool (H,W), the
    pixels of the object region whose colour or depth changed from the camera's time-0 frame
    by more than ``sigmas`` noise sigmas (module doc)."""
    views = frames.levels[level]
    out: dict[int, torch.Tensor] = {}
    for cam in sorted(set(frames.camera)):
        ids = sorted((i for i, c in enumerate(frames.camera) if c == cam),
                     key=lambda i: frames.times[frames.time_index[i]])
        closed = [i for i in ids if frames.times[frames.time_index[i]] == 0]
        if not closed or len(ids) < 3:
            continue
        depth = {i: median3(views[i].depth) for i in ids}
        noise_c, noise_d = [], []
        for a, b in zip(ids[:-1], ids[1:]):
            c, d, region = _differences(views[b], views[a], depth[b], depth[a])
            noise_c.append(c[region])
            noise_d.append(d[region & (d > 0)])
        tol_c = max(sigmas * _mad(noise_c), 1e-3)
        tol_d = max(sigmas * _mad(noise_d), 1e-3)
        ref = closed[0]
        for i in ids:
            if i in closed:
                continue
            c, d, region = _differences(views[i], views[ref], depth[i], depth[ref])
            out[i] = region & ((c > tol_c) | (d > tol_d))
    return out
