"""Multi-view consistency of 3D points with the static RGB-D views (numpy/scipy only).

Nothing moves in the static views, so a point of the object must agree with every static view
that sees its pixel: no view may measure a surface clearly *behind* it (the view sees through
it), and it may not project clearly *outside* a view's object mask where nothing in front hides
it. Depth-initialised splats break this with flying depth pixels, dilated masks and far, noisy
views (streaks of points along camera rays, metres long on a 6 m view); the reconstruction's
first splat and the motion route's closed-state points both drop such points.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.ndimage import binary_dilation

from ..model.capture import Frame
from .noise import noise_sigma


def depth_range(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per pixel, the depth range its surface spans across the pixel: ``d -+ slack`` where the
    slack is half the depth change to the neighbours on a smooth surface (both neighbours valid
    and in line, per image direction); 0 where there is no object."""
    slack = np.zeros_like(d)
    pad = np.pad(d, 1, mode="edge")
    for a, b in ((pad[1:-1, :-2], pad[1:-1, 2:]), (pad[:-2, 1:-1], pad[2:, 1:-1])):
        smooth = (a > 0) & (b > 0) & (np.abs(a + b - 2 * d) < 0.02 * d + 0.25 * np.abs(b - a))
        slack = np.maximum(slack, np.where(smooth, 0.5 * np.abs(b - a), 0.0))
    valid = d > 0
    return np.where(valid, d - slack, 0.0), np.where(valid, d + slack, 0.0)


def masked_depth(f: Frame) -> np.ndarray:
    """The frame's depth inside its mask (0 elsewhere and where not measured)."""
    d = np.zeros(f.rgb.shape[:2], np.float32) if f.depth is None else np.nan_to_num(f.depth)
    if f.mask is not None:
        d = np.where(f.mask, d, 0.0).astype(np.float32)
    return d


def pixels_of(f: Frame, points: np.ndarray, shape: tuple[int, int]
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Which ``points`` fall inside frame ``f``'s image (of ``shape``) in front of its camera
    (bool (N,)), and for those their pixel row, column and depth."""
    uv, z = f.camera.project(points)
    h, w = shape
    with np.errstate(invalid="ignore"):
        j = np.floor(uv[:, 0]).astype(np.int64)
        i = np.floor(uv[:, 1]).astype(np.int64)
    inside = (z > 1e-3) & (i >= 0) & (i < h) & (j >= 0) & (j < w)
    return inside, i[inside], j[inside], z[inside]


def unsupported(points: np.ndarray, frames: list[Frame], margin: float, sigmas: float = 5.0,
                mask_pixels: int = 3, votes: int = 2) -> np.ndarray:
    """Points (N,3) that ``votes`` or more static views contradict (bool (N,)).

    A view contradicts a point when it measures the object's surface at the point's pixel
    farther than the point by more than its tolerance, ``max(margin, sigmas·√2·σ)`` with σ the
    view's depth noise (:func:`noise_sigma`), or when the pixel lies outside the view's object
    mask dilated by ``mask_pixels`` (masks are eroded or dilated by a pixel or two) and no
    measured surface there is in front of the point (a chair in front of the object cuts its
    mask without carving it). Views without depth or outside whose image the point falls say
    nothing.
    """
    against = np.zeros(len(points), np.int64)
    for f in frames:
        if f.depth is None:
            continue
        d_obj = masked_depth(f)
        lo, _ = depth_range(d_obj)
        tol = max(margin, sigmas * math.sqrt(2.0) * noise_sigma([d_obj]))
        inside, ii, jj, zi = pixels_of(f, points, lo.shape)
        d = lo[ii, jj]
        hit = (d > 0) & (d - zi > tol)
        if f.mask is not None:
            near = binary_dilation(f.mask.astype(bool), iterations=mask_pixels) \
                if mask_pixels > 0 else f.mask.astype(bool)
            raw = np.nan_to_num(f.depth)[ii, jj]
            hidden = (raw > 0) & (raw < zi - tol)
            hit |= ~near[ii, jj] & ~hidden
        against[np.flatnonzero(inside)] += hit
    return against >= votes


def seen_behind(points: np.ndarray, views: list[tuple[Frame, np.ndarray, float]]
                ) -> tuple[np.ndarray, np.ndarray]:
    """Per point (N,3), how many static views see past it (a surface measured farther than the
    point by more than the view's tolerance: the point is in space the view saw empty) and how
    many see a surface in front of it (the point is hidden behind what the view measured).
    ``views``: per view its frame, raw depth and tolerance (:func:`depth_views`). Views outside
    whose image the point falls or without a measurement at its pixel say nothing. Two int
    arrays (N,)."""
    past, behind, _ = seen_where(points, views)
    return past, behind


def seen_where(points: np.ndarray, views: list[tuple[Frame, np.ndarray, float]]
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`seen_behind`'s two counts, and per point how many views measure a surface at it
    (within the view's tolerance): three int arrays (N,)."""
    past = np.zeros(len(points), np.int64)
    behind = np.zeros(len(points), np.int64)
    at = np.zeros(len(points), np.int64)
    for f, raw, tol in views:
        inside, ii, jj, zi = pixels_of(f, points, raw.shape)
        d = raw[ii, jj]
        idx = np.flatnonzero(inside)
        past[idx] += (d > 0) & (d > zi + tol)
        behind[idx] += (d > 0) & (d < zi - tol)
        at[idx] += (d > 0) & (np.abs(d - zi) <= tol)
    return past, behind, at


def depth_views(frames: list[Frame], margin: float, sigmas: float = 3.0
                ) -> list[tuple[Frame, np.ndarray, float]]:
    """The frames with depth, each with its raw depth (not masked: a wall behind the object is
    seen too; 0 where not measured) and its tolerance ``max(margin, sigmas·√2·σ)``, σ its depth
    noise (:func:`noise_sigma`), for :func:`seen_behind`."""
    views = []
    for f in frames:
        if f.depth is None:
            continue
        raw = np.nan_to_num(f.depth).astype(np.float32)
        views.append((f, raw, max(margin, sigmas * math.sqrt(2.0) * noise_sigma([raw]))))
    return views
