"""Which part each point belongs to, from the joints' ``extent`` boxes (numpy only).

A joint's ``extent`` is the moving part's oriented box in the closed state: ``center`` (xyz),
``axes`` (three unit row vectors) and ``half_size`` (xyz, along those axes); see core/model/joints.py.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..model.errors import ArtgsError
from ..model.joints import Joint


def assign_parts(points: np.ndarray, joints: Sequence[Joint], margin: float = 0.05) -> np.ndarray:
    """Part label per point: 0 = base, ``i + 1`` = the part moved by ``joints[i]``.

    A point belongs to a joint's part if it lies in the joint's ``extent`` box grown on every side
    by ``margin`` times the box's largest half-size (splat points scatter a little around surfaces).
    A point inside several boxes goes to the smallest box (a drawer inside a cabinet door's box
    goes to the drawer); equal volumes go to the nearest centre. Joints without ``extent`` get no
    points.
    """
    points = np.asarray(points, float).reshape(-1, 3)
    labels = np.zeros(len(points), dtype=np.int64)
    best_volume = np.full(len(points), np.inf)
    best_dist = np.full(len(points), np.inf)
    for i, joint in enumerate(joints):
        if joint.extent is None:
            continue
        center, axes, half = _box(joint)
        local = (points - center) @ axes.T
        grown = half + margin * half.max()
        inside = np.all(np.abs(local) <= grown, axis=1)
        volume = float(np.prod(half))
        dist = np.linalg.norm(points - center, axis=1)
        better = inside & ((volume < best_volume) | ((volume == best_volume) & (dist < best_dist)))
        labels[better] = i + 1
        best_volume[better] = volume
        best_dist[better] = dist[better]
    return labels


def _box(joint: Joint) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(center (3,), axes (3, 3) unit rows, half_size (3,))`` of a joint's extent, validated."""
    ext = joint.extent
    try:
        center = np.asarray(ext["center"], float).reshape(3)
        axes = np.asarray(ext["axes"], float).reshape(3, 3)
        half = np.asarray(ext["half_size"], float).reshape(3)
    except (KeyError, TypeError, ValueError) as exc:
        raise ArtgsError(f"joint '{joint.name}', field 'extent': needs 'center' (3 numbers), "
                         f"'axes' (3 unit vectors) and 'half_size' (3 numbers) ({exc})") from exc
    norms = np.linalg.norm(axes, axis=1)
    if not (np.all(np.isfinite(axes)) and np.all(np.isfinite(center)) and np.all(np.isfinite(half))
            and np.all(norms > 1e-9) and np.all(half >= 0)):
        raise ArtgsError(f"joint '{joint.name}', field 'extent': axes must be non-zero and "
                         f"half_size non-negative, all finite")
    return center, axes / norms[:, None], half


def handle_point(S: np.ndarray, fit, n: np.ndarray) -> np.ndarray:
    """Where to grasp the part ``S`` (its points in the closed state) moved by ``fit`` (anything
    with ``type``, ``axis``, ``origin``, e.g. a Joint): on a revolute part, its band farthest
    from the axis (outer 15 % of the radius), on a prismatic one the whole front; there, the
    most protruding points along the front normal ``n`` (a handle sticks out), averaged."""
    band = S
    if fit.type == "revolute":
        rel = S - fit.origin
        radius = np.linalg.norm(rel - np.outer(rel @ fit.axis, fit.axis), axis=1)
        band = S[radius >= 0.85 * np.percentile(radius, 99)]
    height = band @ n
    return band[height >= np.percentile(height, 95)].mean(axis=0)
