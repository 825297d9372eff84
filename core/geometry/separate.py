"""The object, not the room: which splat points belong to the object (numpy/scipy only).

For captures without masks, whose splat also holds floor, walls and furniture:

1. ``up`` = the mean of the cameras' up vectors (people and robots hold cameras upright);
2. the floor = the plane found by RANSAC among planes whose normal is within 20 degrees of ``up``
   that has the most points and nearly all others above it; it and everything below go;
3. walls = large planes perpendicular to the floor whose points reach well outside the region the
   interaction cameras look at (``focus``, the point nearest all their optical axes, and the moving
   parts' boxes); they go;
4. what is left is voxelised (``voxel``, at least twice the points' typical spacing) and the connected pieces that touch a seed (the focus, the
   moving parts' boxes) are the object.

Every step's outcome is in :class:`Separation`, so a stage can write the masks and say how the
object was separated.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree


@dataclass
class Separation:
    """Per-point object mask and what was removed (floor plane ``n.x = d``, wall planes)."""

    mask: np.ndarray
    up: np.ndarray
    floor: tuple[np.ndarray, float] | None
    walls: list[tuple[np.ndarray, float]] = field(default_factory=list)
    removed: dict[str, int] = field(default_factory=dict)


def camera_up(c2ws: np.ndarray) -> np.ndarray:
    """World up from camera poses (N,4,4, OpenGL axes: +y is the image's up). Cameras are held
    level (no roll) but tilted up or down, so up is the direction perpendicular to all their x
    axes (least squares), signed by their mean y; the mean y alone leans toward the object when
    the cameras look down at it from one side. With fewer than two distinct x axes, the mean y."""
    c2ws = np.asarray(c2ws, float)
    mean_y = c2ws[:, :3, 1].sum(0)
    mean_y /= np.linalg.norm(mean_y)
    x = c2ws[:, :3, 0]
    _, sv, vt = np.linalg.svd(x, full_matrices=False)
    if len(x) < 2 or sv[1] < 0.1 * sv[0]:
        return mean_y
    up = vt[2]
    return up if up @ mean_y > 0 else -up


def focus_point(c2ws: np.ndarray) -> np.ndarray:
    """The point nearest (least squares) to the optical axes of the cameras (N,4,4, OpenGL)."""
    c2ws = np.asarray(c2ws, float)
    A, b = np.zeros((3, 3)), np.zeros(3)
    for T in c2ws:
        d = -T[:3, 2] / np.linalg.norm(T[:3, 2])
        P = np.eye(3) - np.outer(d, d)
        A += P
        b += P @ T[:3, 3]
    return np.linalg.lstsq(A + 1e-9 * np.eye(3), b, rcond=None)[0]


def ransac_plane(points: np.ndarray, normal_ok, tol: float, iterations: int = 400,
                 seed: int = 0, accept=None) -> tuple[np.ndarray, float, np.ndarray] | None:
    """Plane ``(n, d, inliers)`` with the most points within ``tol`` among the sampled planes whose
    unit normal passes ``normal_ok(n)`` (and ``accept(n, d, inliers)`` if given); None if none."""
    rng = np.random.default_rng(seed)
    if len(points) < 3:
        return None
    best, best_count = None, 0
    tri = rng.integers(0, len(points), size=(iterations, 3))
    for i, j, k in tri:
        n = np.cross(points[j] - points[i], points[k] - points[i])
        norm = np.linalg.norm(n)
        if norm < 1e-12:
            continue
        n = n / norm
        if not normal_ok(n):
            continue
        d = float(n @ points[i])
        inliers = np.abs(points @ n - d) < tol
        count = int(inliers.sum())
        if count > best_count and (accept is None or accept(n, d, inliers)):
            best, best_count = (n, d, inliers), count
    if best is None:
        return None
    n, d, inliers = best                       # refit on the inliers (least squares)
    c = points[inliers].mean(0)
    n2 = np.linalg.svd(points[inliers] - c, full_matrices=False)[2][2]
    n2 = n2 if n2 @ n > 0 else -n2
    d2 = float(n2 @ c)
    return n2, d2, np.abs(points @ n2 - d2) < tol


def separate_object(points: np.ndarray, c2ws: np.ndarray, interaction_c2ws: np.ndarray,
                    boxes: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = (),
                    voxel: float = 0.02, tol: float | None = None, band: float = 1.0
                    ) -> Separation:
    """Object mask over ``points`` (N,3); ``boxes`` = moving parts' (centre, axes rows, half).
    The floor and walls are found with ``tol``; ``band`` x ``tol`` on either side of a wall goes
    too (raw depth, noisier than a splat, scatters a far wall's points beyond ``tol``); the floor
    takes its own noise into account (:func:`_plane_band`)."""
    points = np.asarray(points, float)
    up = camera_up(np.concatenate([c2ws, interaction_c2ws]) if len(interaction_c2ws) else c2ws)
    scale = float(np.linalg.norm(np.percentile(points, 95, 0) - np.percentile(points, 5, 0)))
    tol = tol if tol is not None else max(0.01, 0.005 * scale)
    keep = np.ones(len(points), bool)
    removed: dict[str, int] = {}

    def floor_like(n: np.ndarray, d: float, inliers: np.ndarray) -> bool:
        above = np.sign(n @ up) * (points[~inliers] @ n - d)
        return inliers.mean() > 0.05 and np.mean(above > -tol) > 0.95

    floor = ransac_plane(points, lambda n: abs(n @ up) > np.cos(np.deg2rad(20)), tol,
                         accept=floor_like)
    if floor is not None:
        n, d, _ = floor
        if n @ up < 0:
            n, d = -n, -d
        d, spread = _plane_band(points @ n, d, tol)
        gone = points @ n - d < max(band * tol, spread)
        removed["floor"] = int(gone.sum())
        keep &= ~gone
        floor = (n, d)

    seeds = [focus_point(interaction_c2ws)] if len(interaction_c2ws) else []
    seed_pts = np.array(seeds + [c for c, _, _ in boxes]).reshape(-1, 3)
    if len(seed_pts) == 0:
        seed_pts = np.median(points[keep], 0, keepdims=True)
    region = _seed_radius(seed_pts, boxes, scale)
    walls = []
    for it in range(3):
        rest = points[keep]

        def wall_like(n: np.ndarray, d: float, inliers: np.ndarray) -> bool:
            far = np.min(np.linalg.norm(rest[inliers][:, None] - seed_pts[None], axis=2), 1) > region
            return inliers.mean() > 0.1 and far.mean() > 0.5

        wall = ransac_plane(rest, lambda n: abs(n @ up) < np.sin(np.deg2rad(15)), tol,
                            seed=it + 1, accept=wall_like)
        if wall is None:
            break
        n, d, inl = wall
        inl = inl | (np.abs(rest @ n - d) < band * tol)
        idx = np.flatnonzero(keep)[inl]
        keep[idx] = False
        removed[f"wall_{it}"] = int(len(idx))
        walls.append((n, d))

    mask = keep & _connected_to(points, keep, seed_pts, boxes, voxel)
    removed["disconnected"] = int((keep & ~mask).sum())
    return Separation(mask, up, floor, walls, removed)


def _plane_band(heights: np.ndarray, d: float, tol: float) -> tuple[float, float]:
    """A plane's offset at the middle of its points (RANSAC's plane, accepted with nearly all
    points above it, hugs the bottom of a noisy floor) and its half thickness: ``tol`` or 3
    robust sigmas of the points near it, whichever is larger."""
    spread = tol
    for _ in range(3):
        near = np.abs(heights - d) < 3 * spread
        if near.sum() < 10:
            break
        d = float(np.median(heights[near]))
        spread = max(tol, 3 * 1.4826 * float(np.median(np.abs(heights[near] - d))))
    return d, spread


def _seed_radius(seed_pts: np.ndarray, boxes, scale: float) -> float:
    """How far from a seed the object may reach: its largest part box, at least 25 % of the scene."""
    half = max([float(np.linalg.norm(h)) for _, _, h in boxes], default=0.0)
    return max(2.5 * half, 0.25 * scale)


def _connected_to(points: np.ndarray, keep: np.ndarray, seed_pts: np.ndarray, boxes,
                  voxel: float) -> np.ndarray:
    """Points of ``keep`` in voxel-connected pieces that touch a seed point or a part box."""
    pts = points[keep]
    if len(pts) == 0:
        return np.zeros(len(points), bool)
    sample = pts[:: max(1, len(pts) // 5000)]
    spacing = float(np.median(cKDTree(sample).query(sample, k=2)[0][:, 1]))
    voxel = max(voxel, 2.0 * spacing)                  # sparse splats still connect
    lo = pts.min(0) - voxel
    shape = np.ceil((pts.max(0) + voxel - lo) / voxel).astype(int) + 1
    occ = np.zeros(shape, bool)
    ijk = np.floor((pts - lo) / voxel).astype(int)
    occ[tuple(ijk.T)] = True
    occ = ndimage.binary_closing(occ, iterations=1) | occ
    labels, count = ndimage.label(occ, structure=np.ones((3, 3, 3)))
    point_label = labels[tuple(ijk.T)]
    wanted = set()
    for c, axes, half in boxes:
        inside = np.all(np.abs((pts - c) @ np.asarray(axes).T) <= np.asarray(half) + voxel, axis=1)
        wanted |= set(np.unique(point_label[inside]).tolist())
    for s in seed_pts[: 1 if boxes else len(seed_pts)]:
        nearest = int(np.argmin(np.linalg.norm(pts - s, axis=1)))
        wanted.add(int(point_label[nearest]))
    wanted.discard(0)
    out = np.zeros(len(points), bool)
    out[np.flatnonzero(keep)] = np.isin(point_label, list(wanted))
    return out
