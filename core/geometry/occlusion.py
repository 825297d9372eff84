"""What a frame shows of the object, and where something else (an arm, a hand) hides it.

Shared by the motion route's change detection and the optimisation's loss: a pixel outside the
object mask bounds the object only up to its measured depth; behind it nothing is known.
"""

from __future__ import annotations

import numpy as np

from ..model.capture import Frame


def object_depth(f: Frame, robot: np.ndarray | None, tolerance: float
                 ) -> tuple[np.ndarray, np.ndarray]:
    """The object's depth in frame ``f`` (0 = not the object or not measured) and its free space:
    per pixel, the depth up to which no object surface can be (0 = no evidence).

    A pixel outside the mask shows something that is not the object: nothing of the object lies
    in front of its measured depth, and behind it nothing is known (an arm or a hand hides it);
    without a measurement (synthetic background) it is free all the way (inf). Pixels the robot
    twin explains (``robot``: its rendered depth, 0 where it does not cover; the frame's depth
    within ``max(tolerance, 2 %)`` of it, or no measurement) are such pixels too, even where there
    is no mask or the mask holds the arm. Inside the mask there is no evidence of free space (a
    missing measurement is just missing)."""
    raw = np.zeros(f.rgb.shape[:2], np.float32) if f.depth is None else np.nan_to_num(f.depth)
    if f.mask is None and robot is None:
        return raw, np.zeros_like(raw)
    obj = np.ones(raw.shape, bool) if f.mask is None else f.mask.copy()
    if robot is not None:
        arm = twin_pixels(raw, robot, tolerance)
        obj &= ~arm
        raw = np.where(arm & (raw <= 0), robot, raw)
    free = np.where(obj, 0.0, np.where(raw > 0, raw, np.inf))
    return np.where(obj, raw, 0.0).astype(np.float32), free


def twin_pixels(raw: np.ndarray, robot: np.ndarray, tolerance: float) -> np.ndarray:
    """Pixels a robot twin explains: it covers them (``robot`` = its rendered depth, 0 elsewhere)
    and the measured depth ``raw`` is within ``max(tolerance, 2 %)`` of it, or missing."""
    tol = np.maximum(tolerance, 0.02 * robot)
    return (robot > 0) & ((raw <= 0) | (np.abs(raw - robot) < tol))
