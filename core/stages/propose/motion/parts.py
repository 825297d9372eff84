"""Segmentation: vanished points grouped into moving parts, and a part's oriented box."""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree


def group_parts(points: np.ndarray, first: np.ndarray, active: np.ndarray, times: list[int],
                radius: float, min_points: int, onset_ratio: float = 2.5,
                earliest: np.ndarray | None = None) -> list[np.ndarray]:
    """Index arrays of moving parts, largest first.

    Vanished points within ``radius`` of each other are linked when they first vanish at the same
    step, or one step apart while the earlier one's pixels still change (``active``, from
    :func:`change.moving_at`): a door's hinge side vanishes steps after its edge. A group whose
    count of newly vanished points jumps by ``onset_ratio`` from one step to the next holds a second
    part starting there (a neighbouring drawer opened after the door); the links across that step
    are cut. ``earliest`` (from :func:`change.vanish_times`): a point hidden by an arm may have
    vanished as early as this step, so it links with points vanishing from there to its first step.
    """
    idx = np.flatnonzero(first >= 0)
    if len(idx) == 0:
        return []
    step = {t: k for k, t in enumerate(times)}
    f = np.array([step[t] for t in first[idx]], np.int64)   # step indices (times may skip)
    lo = f if earliest is None else np.array([step[t] for t in earliest[idx]], np.int64)
    pairs = cKDTree(points[idx]).query_pairs(radius, output_type="ndarray")
    if len(pairs):
        a, b = pairs[:, 0], pairs[:, 1]
        swap = f[a] > f[b]
        a, b = np.where(swap, b, a), np.where(swap, a, b)
        gap = np.maximum(lo[b] - f[a], 0)
        keep = (gap == 0) | ((gap == 1) & active[idx[a], np.minimum(lo[b], len(times) - 1)])
        pairs = np.stack([a, b], axis=1)[keep]
    labels = _components(len(idx), pairs)
    if len(pairs):
        cut = np.zeros(len(pairs), bool)
        for lab in np.unique(labels):
            members = labels == lab
            counts = {t: int(np.sum(f[members] == t)) for t in np.unique(f[members])}
            for t, c in counts.items():
                if t - 1 in counts and c > onset_ratio * counts[t - 1] and c >= min_points / 2:
                    cut |= (labels[pairs[:, 0]] == lab) & (f[pairs[:, 1]] == t) \
                        & (f[pairs[:, 0]] == t - 1)
        if cut.any():
            labels = _components(len(idx), pairs[~cut])
    parts = [idx[labels == lab] for lab in np.unique(labels)]
    parts = [p for p in parts if len(p) >= min_points]
    return sorted(parts, key=len, reverse=True)


def _components(n: int, pairs: np.ndarray) -> np.ndarray:
    """Connected-component label of each of ``n`` nodes linked by index ``pairs`` (M, 2)."""
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n)) \
        if len(pairs) else coo_matrix((n, n))
    return connected_components(graph, directed=False)[1]


def box_of(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Oriented box (centre, axes rows thinnest first, half sizes) by PCA, robust percentiles."""
    c = np.median(points, axis=0)
    _, _, Vt = np.linalg.svd(points - c, full_matrices=False)
    axes = Vt[::-1].copy()
    local = (points - c) @ axes.T
    lo, hi = np.percentile(local, 1, axis=0), np.percentile(local, 99, axis=0)
    center = c + ((lo + hi) / 2) @ axes
    return center, axes, (hi - lo) / 2
