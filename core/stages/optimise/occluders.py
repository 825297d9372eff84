"""Known occluders of the interaction frames: the robot's twin, and other things not the object.

Per frame (core/geometry/occlusion.py): the pixels the robot twin explains join the frame's target
(mask, depth, colour) and the twin's Gaussians are rendered with the model there
(``View.occluder``), so the arm's pixels are explained instead of bending the joints; the twin
hides the parts behind it as the arm does. Other pixels outside the mask with a measured depth (a
hand, an unknown robot, a calibration error of the twin) bound the object only up to that depth
(``View.occluder_depth``; the loss ignores a render hidden behind them).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Callable

import numpy as np
import torch

from ...geometry.occlusion import twin_pixels
from ...model.capture import Capture, Frame
from ...render.rasterize import render
from ...train.views import View
from ..robot_twin import twin_for_capture

#: Depth agreement of the twin and a frame below which a pixel is the arm's (m; plus 2 %).
TWIN_TOLERANCE = 0.01


def known_occluders(capture: Capture, device, use_twin: bool = True
                    ) -> Callable[[Frame, View], View] | None:
    """``add(frame, view) -> view`` with the frame's known occluders; None when there are none
    (no twin, and no interaction frame measures anything outside its mask)."""
    twin = twin_for_capture(capture, device) if use_twin else None
    frames = [f for f in capture.interaction if f.time is not None]
    if twin is None and not any(f.mask is not None and f.depth is not None
                                and np.any((f.depth > 0) & ~f.mask) for f in frames):
        return None

    def add(frame: Frame, view: View) -> View:
        raw = np.zeros(frame.rgb.shape[:2], np.float32) if frame.depth is None \
            else np.nan_to_num(frame.depth)
        obj = np.ones(raw.shape, bool) if frame.mask is None else frame.mask
        g = twin(frame) if twin is not None else None
        arm = np.zeros(raw.shape, bool)
        if g is not None:
            with torch.no_grad():
                r = render(g, frame.camera)
            robot = np.where(r.alpha.cpu().numpy() > 0.5, r.depth.cpu().numpy(), 0.0)
            arm = twin_pixels(raw, robot, TWIN_TOLERANCE) & ~obj
        other = ~obj & ~arm & (raw > 0)
        t = lambda a: torch.as_tensor(np.ascontiguousarray(a), dtype=torch.float32,  # noqa: E731
                                      device=view.depth.device)
        armt = torch.as_tensor(arm, device=view.depth.device)
        rgb = torch.where(armt[..., None], t(frame.rgb.astype(np.float32) / 255.0), view.rgb)
        return replace(view, rgb=rgb, mask=torch.where(armt, torch.ones_like(view.mask), view.mask),
                       depth=torch.where(armt, t(raw), view.depth),
                       depth_valid=view.depth_valid | (armt & (t(raw) > 0)),
                       occluder=g, occluder_depth=t(np.where(other, raw, 0.0)) if other.any()
                       else None)
    return add
