"""The smallest-area box of planar points over rotations: a footprint's or a face's sides."""

from __future__ import annotations

import numpy as np


def turned_boxes(xy: np.ndarray, degrees: np.ndarray, percentiles: tuple[float, float]
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The ``percentiles`` boxes of the points ``xy`` (N,2) turned by each of ``degrees``:
    their areas (A,) and low and high corners (A,2) in each turned frame."""
    t = np.radians(degrees)
    c, s = np.cos(t)[:, None], np.sin(t)[:, None]
    first, second = c * xy[:, 0] + s * xy[:, 1], -s * xy[:, 0] + c * xy[:, 1]    # (A, N)
    lo1, hi1 = np.percentile(first, percentiles, axis=1)
    lo2, hi2 = np.percentile(second, percentiles, axis=1)
    return (hi1 - lo1) * (hi2 - lo2), np.c_[lo1, lo2], np.c_[hi1, hi2]


def smallest_turn(xy: np.ndarray, percentiles: tuple[float, float], fine: float | None
                  ) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """The turn (degrees) of the smallest-area ``percentiles`` box of ``xy`` over 1 deg steps,
    then (``fine``) over steps of that many degrees within 1 deg of the best; its low and high
    corners, and the areas of the 1 deg steps' boxes (90,)."""
    degrees = np.arange(0.0, 90.0, 1.0)
    coarse, lo, hi = turned_boxes(xy, degrees, percentiles)
    area, best = coarse, int(np.argmin(coarse))
    if fine:
        degrees = degrees[best] + np.arange(-1.0, 1.0 + fine / 2, fine)
        area, lo, hi = turned_boxes(xy, degrees, percentiles)
        best = int(np.argmin(area))
    return float(degrees[best]), lo[best], hi[best], coarse


def smallest_rectangle(xy: np.ndarray, percentiles: tuple[float, float] = (1.0, 99.0),
                       limit: int | None = None, fine: float | None = None
                       ) -> tuple[float, np.ndarray, np.ndarray]:
    """Of the ``percentiles`` boxes of the points ``xy`` (N,2) turned in 1 deg steps (robust
    to a few stray points; an even subsample of at most ``limit`` of them), the one of smallest
    area: its angle (radians, of its first side (cos, sin); the second is (-sin, cos)) and its
    low and high corners (2,) in that frame. ``fine``: then searched in steps of that many
    degrees within 1 deg of the best."""
    if limit is not None:
        xy = xy[:: max(1, len(xy) // limit)]
    turn, lo, hi, _ = smallest_turn(xy, percentiles, fine)
    return float(np.radians(turn)), lo, hi


def upright_axes(points: np.ndarray, up: np.ndarray, limit: int = 20000, fine: float = 0.05,
                 round_contrast: float = 1.05) -> np.ndarray:
    """The directions of an upright body's box: ``up`` and, when its footprint has sides, the
    two sides of its smallest footprint rectangle (:func:`smallest_rectangle` of the points
    projected on the plane square to ``up``). A round footprint (the largest turned box less
    than ``round_contrast`` times the smallest in area: a bin, a drum) has no sides to give,
    and only ``up`` is returned. Rows, unit (1 or 3, 3)."""
    up = np.asarray(up, float) / np.linalg.norm(up)
    u = np.cross(up, [1.0, 0.0, 0.0] if abs(up[0]) < 0.9 else [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(up, u)
    p = np.asarray(points, float)
    p = p[:: max(1, len(p) // limit)]
    xy = np.c_[p @ u, p @ v]
    if len(p) < 10:
        return up[None]
    turn, _, _, area = smallest_turn(xy, (1.0, 99.0), fine)
    if area.max() < round_contrast * area.min():
        return up[None]
    t = np.radians(turn)
    side = np.cos(t) * u + np.sin(t) * v
    return np.array([up, side, np.cross(up, side)])
