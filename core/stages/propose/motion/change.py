"""Change detection: which static-splat points a later interaction step sees *through*.

Rigid scenes cannot reveal what was behind a surface, so a point that the closed state shows and a
later step's measured depth passes behind (or shows no object at) belongs to a moving part. Depth
noise per camera sets the thresholds (core/stages/propose/motion/cameras.py).
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import minimum_filter
from scipy.spatial import cKDTree

from .cameras import InteractionView, grid_points, lookup, pixels_of
from .config import CLOSED_TIME


def mark_changed(views: list[InteractionView], points: np.ndarray, spacing: float) -> None:
    """For views whose closed state is a render: a pixel changed when its measured point is
    farther than ``max(threshold, 1.5 spacing)`` from every splat point (a render's error is too
    large to compare depths closely with) and not far behind the render."""
    tree = None
    for v in views:
        if v.ref_source != "splat":
            continue
        if tree is None:
            tree = cKDTree(points)
        tol = max(v.threshold, 1.5 * spacing)
        for t, d in v.depth.items():
            P, _, _ = grid_points(v, d)
            valid = d > 0
            far = np.zeros(d.shape, bool)
            far[valid] = tree.query(P[valid], distance_upper_bound=tol)[0] > tol
            v.ranges[f"changed{t}"] = far & ((v.ref <= 0) | (d < v.ref + v.ref_threshold))


def vanish_times(points: np.ndarray, views: list[InteractionView], times: list[int], spacing: float
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per point: first step at which a view sees through it (-1: never), how many times, and
    the earliest step it may have vanished at: before its first step, the steps in which every
    view that saw it closed had something in front of it (an arm, or an opened part) and an arm
    hid it in some view (then, or in the closed state) leave the onset open. Without an arm
    (nothing outside the masks in front of the object) the onset is the first step.
    ``spacing``: the points' typical spacing (m)."""
    first = np.full(len(points), -1, np.int64)
    count = np.zeros(len(points), np.int64)
    hidden = np.ones((len(points), len(times)), bool)
    behind_arm = np.zeros((len(points), len(times)), bool)
    for v in views:
        inside, z, lo, hi = lookup(v, "ref", points)
        flat = pixels_of(v, points)[1]
        if v.ref_source == "splat":   # splat points scatter about a spacing around surfaces
            seen = _front_points(v, points, spacing) & (z < hi + v.ref_threshold)
            margin = max(v.threshold, 1.5 * spacing)
        else:
            seen = inside & (lo > 0) & (z > lo - v.threshold) & (z < hi + v.threshold)
            margin = v.threshold
        for k, t in enumerate(times):
            if t not in v.depth:
                continue
            _, _, d, _ = lookup(v, t, points)
            occ = np.where(inside, v.occluder(t).reshape(-1)[flat], np.inf)
            hidden[:, k] &= ~seen | (occ < z - margin) | ((d > 0) & (d < z - margin))
            behind_arm[:, k] |= occ < z - margin
            if CLOSED_TIME in v.free:   # an arm hid it in the closed state: this view's onset
                closed = np.where(inside, v.occluder(CLOSED_TIME).reshape(-1)[flat], np.inf)
                behind_arm[:, k] |= closed < z - margin
            # background where the part was counts only against a measured closed state (the
            # render's silhouette is blurred: points at its rim would all seem gone); an arm in
            # front of the point says nothing (cameras.object_depth)
            free = np.where(inside, v.free[t].reshape(-1)[flat], 0.0)
            empty = (d <= 0) & (z < free - margin) & (v.ref_source != "splat")
            gone = seen & ((d - z > margin) | empty)
            count += gone
            new = gone & ((first < 0) | (first > t))
            first[new] = t
    hidden &= behind_arm
    step = {t: k for k, t in enumerate(times)}
    onset = np.array([step.get(int(t), 0) for t in first])
    for k in range(len(times) - 1, 0, -1):   # walk back over hidden steps
        back = (onset == k) & hidden[:, k - 1] & (first >= 0)
        onset[back] = k - 1
    return first, count, np.array(times)[onset]


def _front_points(v: InteractionView, points: np.ndarray, spacing: float) -> np.ndarray:
    """Which points are in front in ``v``: within ``max(threshold, 1.5 spacing)`` of the nearest
    point over their pixel (a point z-buffer; empty pixels take their 3x3 neighbourhood's). A
    rendered closed state blends depth layers, too loosely to tell the front points."""
    inside, flat, z = pixels_of(v, points)
    zbuf = np.full(v.ref.size, np.inf)
    np.minimum.at(zbuf, flat[inside], z[inside])
    zbuf = zbuf.reshape(v.ref.shape)
    zbuf = np.where(np.isfinite(zbuf), zbuf, minimum_filter(zbuf, size=3, mode="nearest"))
    return inside & (z < zbuf.reshape(-1)[flat] + max(v.threshold, 1.5 * spacing))


def moving_at(points: np.ndarray, views: list[InteractionView], times: list[int]) -> np.ndarray:
    """(N, steps) flags: some view's depth at the point's pixel changed from the step before."""
    active = np.zeros((len(points), len(times)), bool)
    for v in views:
        inside, flat, _ = pixels_of(v, points)
        for k in range(1, len(times)):
            a, b = times[k - 1], times[k]
            if a not in v.depth or b not in v.depth:
                continue
            da, db = v.depth[a].reshape(-1)[flat], v.depth[b].reshape(-1)[flat]
            active[:, k] |= inside & (((da > 0) != (db > 0)) | (np.abs(db - da) > v.threshold))
    return active
