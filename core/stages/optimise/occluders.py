"""Known occluders of the interaction frames: the robot's twin, and other things not the object.

Per frame (core/geometry/occlusion.py): the pixels the robot twin explains join the frame's target
(mask, depth, colour) and the twin's Gaussians are rendered with the model there
(``View.occluder``), so the arm's pixels are explained instead of bending the joints; the twin
hides the parts behind it as the arm does. Other pixels outside the mask with a measured depth (a
hand, an unknown robot, a calibration error of the twin) bound the object only up to that depth
(``View.occluder_depth``; the loss ignores a render hidden behind them).

So do the pixels that show the body's inside (:func:`inside_body`): an opened door or drawer
reveals an interior the closed views never saw, which the splat does not hold. No placement of
the closed parts explains it except a wrong one: a part moved into the body, where it covers
those pixels at about their depth, which pays where the true opening leaves them empty. The
loss compares a render there only where it is nearer than the inside the frame measured; the
search for missed parts still counts them as changes (:mod:`.changes`), and a fit that then hides
its part in the body is turned outwards (:func:`.hypotheses.turn_outwards`).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Callable

import numpy as np
import torch

from ...geometry.consistency import seen_where
from ...geometry.noise import noise_sigma
from ...geometry.occlusion import twin_pixels
from ...model.capture import Capture, Frame
from ...render.rasterize import render
from ...train.views import View
from ..robot_twin import twin_for_capture
from .plausible import OpenSpace

#: Depth agreement of the twin and a frame below which a pixel is the arm's (m; plus 2 %).
TWIN_TOLERANCE = 0.01


def inside_body(frame: Frame, depth: np.ndarray, obj: np.ndarray, space: OpenSpace,
                sigmas: float = 3.0) -> np.ndarray:
    """Pixels of ``frame`` (its measured ``depth``, within ``obj``) whose measured point lies
    inside the body even brought ``sigmas`` of the frame's depth noise nearer (a far camera's
    noise puts a closed front centimetres behind itself): behind a surface some static view
    measured, on none they measured, in space none saw empty
    (:func:`~artgs.core.geometry.consistency.seen_where`, with the static views' own
    tolerances; a surface is behind what the views on its other side measured). A part that
    opens moves into space the static views saw empty, so its pixels are never among these.
    Bool (H, W)."""
    near = np.where(depth > 0, np.maximum(depth - sigmas * noise_sigma([depth]), 1e-3), 0.0)
    pts, idx = frame.camera.backproject(near, obj)
    inside = np.zeros(depth.size, bool)
    if len(pts):
        past, behind, at = seen_where(pts, space.views)
        inside[idx[(behind > 0) & (past == 0) & (at == 0)]] = True
    return inside.reshape(depth.shape)


def known_occluders(capture: Capture, device, use_twin: bool = True,
                    space: OpenSpace | None = None) -> Callable[[Frame, View], View] | None:
    """``add(frame, view) -> view`` with the frame's known occluders, and with the pixels that
    show the body's inside (:func:`inside_body`) where ``space`` (the static views' depth) is
    given; None when there are none (no twin, no ``space``, and no interaction frame measures
    anything outside its mask)."""
    twin = twin_for_capture(capture, device) if use_twin else None
    frames = [f for f in capture.interaction if f.time is not None]
    if twin is None and space is None and not any(
            f.mask is not None and f.depth is not None and np.any((f.depth > 0) & ~f.mask)
            for f in frames):
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
        if space is not None:
            other |= inside_body(frame, raw, obj & ~arm, space)
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
