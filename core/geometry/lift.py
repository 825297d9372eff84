"""Lifting the VLM's image answers to 3D joints with the rendered depth (ArtGS paper, Sec. III-B).

- The part's front plane: back-project the pixels inside its box (shrunk, away from the edges),
  fit a plane by PCA, drop points off the plane (handles, background seen through gaps), refit.
- Revolute: sample points along the segment between the two image points, each with the median of
  the valid depths in a small window (robust at depth edges), back-project, drop samples off the
  part's plane, PCA; the dominant direction is the axis and the mean of the samples a point on it.
  When the dominant eigenvalue does not dominate (too few points, a bent or blob-like set) the 2D
  segment is lifted onto the part's plane instead. An axis within :data:`AXIS_SNAP_DEG` of plumb or
  level is snapped to it (:func:`snap_axis`). The sign makes a positive angle open the part
  towards the camera.
- Prismatic: the cross product of the box's horizontal and vertical edge directions in 3D (the box
  edges' midpoints lifted onto the part's plane), pointing towards the camera (pulling out), made
  level when within :data:`AXIS_SNAP_DEG` of it.
- Handle: the 3D centre of the handle box's pixels (those standing out of the part's plane if
  any), approached along minus the part's normal (the VLM route then turns it against the
  joint's opening motion, as every route writes it).
- Extent: the part box's corners lifted onto the plane, a thin oriented box around the front
  (:data:`FRONT_MARGIN` in front for handles, :data:`BACK_MARGIN` behind).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model.cameras import Camera

FRONT_MARGIN = 0.05  # m in front of the part's plane kept in its extent (handles)
BACK_MARGIN = 0.02   # m behind it
DOMINANCE = 20.0     # first PCA eigenvalue over the second for a trusted hinge direction
AXIS_SNAP_DEG = 8.0  # a joint axis this close to level or plumb (in the part's plane) is snapped
_SHRINK = 0.12       # fraction of the box trimmed on each side before fitting the plane


@dataclass
class Plane:
    """A part's front plane: a point on it and the unit normal pointing towards the camera."""

    point: np.ndarray
    normal: np.ndarray
    coverage: float  # fraction of the (shrunk) box pixels with valid depth


def rays(camera: Camera, uv: np.ndarray) -> np.ndarray:
    """World-frame ray directions (N,3) through image points ``uv`` (N,2), scaled to z-depth 1."""
    uv = np.asarray(uv, float).reshape(-1, 2)
    cam = np.stack([(uv[:, 0] - camera.K[0, 2]) / camera.K[0, 0],
                    (uv[:, 1] - camera.K[1, 2]) / camera.K[1, 1], np.ones(len(uv))], axis=1)
    return cam @ np.linalg.inv(camera.w2c)[:3, :3].T


def backproject_uv(camera: Camera, uv: np.ndarray, z: np.ndarray) -> np.ndarray:
    """World points (N,3) at z-depths ``z`` (N,) along the rays through ``uv`` (N,2)."""
    return camera.center + rays(camera, uv) * np.asarray(z, float).reshape(-1, 1)


def robust_depth(depth: np.ndarray, uv: np.ndarray, radius: int = 2) -> np.ndarray:
    """Per image point, the median of the valid depths in a (2r+1)^2 window, keeping only the
    nearest depth layer (a window straddling a depth edge votes for the surface in front);
    0 if none.
    """
    h, w = depth.shape
    uv = np.asarray(uv, float).reshape(-1, 2)
    j = np.clip(np.floor(uv[:, 0]).astype(int), 0, w - 1)
    i = np.clip(np.floor(uv[:, 1]).astype(int), 0, h - 1)
    offs = np.arange(-radius, radius + 1)
    ii = np.clip(i[:, None, None] + offs[None, :, None], 0, h - 1)
    jj = np.clip(j[:, None, None] + offs[None, None, :], 0, w - 1)
    win = depth[ii, jj].reshape(len(uv), -1).astype(float)
    win[~(np.isfinite(win) & (win > 0))] = np.nan
    near = np.nanmin(np.where(np.isnan(win).all(axis=1, keepdims=True), 1.0, win), axis=1)
    win[win > near[:, None] * 1.05 + 0.01] = np.nan  # other layers, > 5% + 1 cm behind
    with np.errstate(all="ignore"):
        out = np.nanmedian(np.where(np.isnan(win).all(axis=1, keepdims=True), 0.0, win), axis=1)
    return np.nan_to_num(out)


def box_pixels(depth: np.ndarray, box: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Centres (M,2) and depths (M,) of the pixels in ``box`` with valid depth, and their share."""
    x1, y1, x2, y2 = np.asarray(box, float)
    h, w = depth.shape
    c0, c1 = int(np.clip(np.floor(x1), 0, w - 1)), int(np.clip(np.ceil(x2), 1, w))
    r0, r1 = int(np.clip(np.floor(y1), 0, h - 1)), int(np.clip(np.ceil(y2), 1, h))
    sub = depth[r0:r1, c0:c1]
    jj, ii = np.meshgrid(np.arange(c0, c1) + 0.5, np.arange(r0, r1) + 0.5)
    valid = np.isfinite(sub) & (sub > 0)
    share = float(valid.mean()) if valid.size else 0.0
    return np.stack([jj[valid], ii[valid]], axis=1), sub[valid], share


def fit_plane(camera: Camera, depth: np.ndarray, box: np.ndarray) -> Plane | None:
    """The part's front plane from the depth inside ``box`` (x1, y1, x2, y2 pixels), or None."""
    x1, y1, x2, y2 = np.asarray(box, float)
    dx, dy = _SHRINK * (x2 - x1), _SHRINK * (y2 - y1)
    uv, z, coverage = box_pixels(depth, np.array([x1 + dx, y1 + dy, x2 - dx, y2 - dy]))
    if len(z) < 6:
        return None
    pts = backproject_uv(camera, uv, z)
    keep = np.ones(len(pts), bool)
    for _ in range(3):
        center = pts[keep].mean(axis=0)
        normal = np.linalg.svd(pts[keep] - center, full_matrices=False)[2][2]
        resid = np.abs((pts - center) @ normal)
        mad = np.median(resid[keep])
        keep = resid <= max(3.0 * 1.4826 * mad, 0.002)
        if keep.sum() < 6:
            return None
    if normal @ (camera.center - center) < 0:
        normal = -normal
    return Plane(center, normal, coverage)


def on_plane(camera: Camera, uv: np.ndarray, plane: Plane) -> np.ndarray:
    """World points (N,3) where the rays through ``uv`` meet ``plane``."""
    d = rays(camera, uv)
    t = ((plane.point - camera.center) @ plane.normal) / (d @ plane.normal)
    return camera.center + d * t[:, None]


def revolute_axis(camera: Camera, depth: np.ndarray, points: np.ndarray, plane: Plane | None,
                  samples: int = 32, radius: int = 2) -> tuple[np.ndarray, np.ndarray, bool]:
    """Axis direction and a point on it from two image points (2,2); True if PCA was trusted."""
    p1, p2 = np.asarray(points, float)
    uv = p1 + np.linspace(0.0, 1.0, samples)[:, None] * (p2 - p1)
    z = robust_depth(depth, uv, radius)
    pts = backproject_uv(camera, uv[z > 0], z[z > 0])
    if plane is not None and len(pts):
        tol = max(0.02, 0.1 * np.linalg.norm(pts.max(axis=0) - pts.min(axis=0)))
        pts = pts[np.abs((pts - plane.point) @ plane.normal) <= tol]
    if len(pts) >= max(4, samples // 4):
        center = pts.mean(axis=0)
        s, vt = np.linalg.svd(pts - center, full_matrices=False)[1:]
        ev = s ** 2
        if ev[0] >= DOMINANCE * max(ev[1], 1e-12):
            axis = vt[0] if vt[0] @ (pts[-1] - pts[0]) >= 0 else -vt[0]
            return axis, center, True
    if plane is not None:
        ends = on_plane(camera, np.stack([p1, p2]), plane)
    else:
        zs = z[z > 0]
        zm = float(np.median(zs)) if len(zs) else float(np.median(depth[depth > 0]))
        ends = backproject_uv(camera, np.stack([p1, p2]), np.array([zm, zm]))
    return _unit(ends[1] - ends[0]), ends.mean(axis=0), False


def snap_axis(axis: np.ndarray, normal: np.ndarray, up: np.ndarray, kind: str,
              max_deg: float = AXIS_SNAP_DEG) -> np.ndarray:
    """Furniture prior: hinges run plumb or level along the part's front, drawers slide level.

    ``axis`` is replaced by the nearest such direction (same sign) if within ``max_deg``:
    revolute -> ``up`` or the level direction within the plane of ``normal``; prismatic -> the
    level part of the ``normal``.
    """
    if kind == "revolute":
        candidates = [up - (up @ normal) * normal, np.cross(normal, up)]
    else:
        candidates = [normal - (normal @ up) * up]
    for c in candidates:
        if np.linalg.norm(c) < 0.3:  # a lid facing up: every direction in it is level
            continue
        c = _unit(c)
        c = c if c @ axis >= 0 else -c
        if c @ axis >= np.cos(np.radians(max_deg)):
            return c
    return axis


def handle_reach(camera: Camera, box: np.ndarray, plane: Plane, axis: np.ndarray,
                 origin: np.ndarray, point: np.ndarray) -> float:
    """Distance of ``point`` (the handle) from the hinge line, over that of the part's farthest box
    corner: near 1 for a handle at the free edge, near 0 for one beside the hinge."""
    x1, y1, x2, y2 = np.asarray(box, float)
    corners = on_plane(camera, np.array([[x1, y1], [x2, y1], [x2, y2], [x1, y2]]), plane)
    radial = np.linalg.norm(np.cross(np.vstack([corners, point]) - origin, axis), axis=1)
    return float(radial[-1] / max(radial[:-1].max(), 1e-9))


def opening_sign(axis: np.ndarray, origin: np.ndarray, part_center: np.ndarray,
                 towards: np.ndarray) -> np.ndarray:
    """``axis`` flipped if needed so a positive rotation moves ``part_center`` along ``towards``."""
    velocity = np.cross(axis, part_center - origin)
    return -axis if velocity @ towards < 0 else axis


def box_frame(camera: Camera, box: np.ndarray, plane: Plane) -> tuple[np.ndarray, np.ndarray,
                                                                       np.ndarray, np.ndarray]:
    """The box's 3D centre, unit horizontal and vertical edge directions and edge lengths."""
    x1, y1, x2, y2 = np.asarray(box, float)
    xm, ym = (x1 + x2) / 2, (y1 + y2) / 2
    left, right, top, bottom, center = on_plane(
        camera, np.array([[x1, ym], [x2, ym], [xm, y1], [xm, y2], [xm, ym]]), plane)
    return center, _unit(right - left), _unit(bottom - top), np.array(
        [np.linalg.norm(right - left), np.linalg.norm(bottom - top)])


def prismatic_axis(camera: Camera, box: np.ndarray, plane: Plane) -> np.ndarray:
    """Cross product of the box's horizontal and vertical 3D directions, towards the camera."""
    _, h, v, _ = box_frame(camera, box, plane)
    n = _unit(np.cross(h, v))
    return n if n @ (camera.center - plane.point) >= 0 else -n


def extent(camera: Camera, box: np.ndarray, plane: Plane) -> dict[str, list]:
    """The part's oriented box (``model.joints`` ``extent``): front rectangle, thin in depth."""
    center, h, v, size = box_frame(camera, box, plane)
    n = plane.normal
    v = _unit(v - (v @ h) * h)
    v = v if np.cross(h, v) @ n >= 0 else -v
    half = np.array([size[0] / 2, size[1] / 2, (FRONT_MARGIN + BACK_MARGIN) / 2])
    c = center + n * (FRONT_MARGIN - BACK_MARGIN) / 2
    return {"center": [float(x) for x in c], "axes": [[float(x) for x in a] for a in (h, v, n)],
            "half_size": [float(x) for x in half]}


def handle(camera: Camera, depth: np.ndarray, box: np.ndarray, plane: Plane
           ) -> dict[str, list[float]]:
    """Grasp point (3D centre of the handle's pixels) and approach (minus the part's normal)."""
    uv, z, _ = box_pixels(depth, box)
    if len(z):
        pts = backproject_uv(camera, uv, z)
        height = (pts - plane.point) @ plane.normal
        proud = pts[(height > 0.005) & (height < FRONT_MARGIN)]
        point = np.median(proud if len(proud) >= 3 else pts, axis=0)
    else:
        x1, y1, x2, y2 = np.asarray(box, float)
        point = on_plane(camera, np.array([[(x1 + x2) / 2, (y1 + y2) / 2]]), plane)[0]
    return {"point": [float(x) for x in point], "approach": [float(x) for x in -plane.normal]}


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v)
    return v / n if n > 0 else v
