"""The crop box applied to a capture: object masks for captures without masks (numpy only).

A capture without masks sees the floor, walls and furniture, and every stage would otherwise spend
its time (and its change thresholds, its missed-part search) on the room. So the first stage that
has depth points, reconstruct, separates the object in the static views' fused depth
(:func:`core.geometry.separate.separate_object`, seeded where the interaction cameras look) and
writes the object's closed box to ``OUT/crop.json`` (``source: "separation"``; a box the user drew
is kept). Every stage then sees the capture through :func:`crop_capture`:

- a pixel with depth is object when its point lies inside the box grown by its largest horizontal
  extent sideways and upwards (a door or a drawer leaves the closed box by at most the object's
  size, a lid rises by at most its depth) and not below the box's bottom (the floor stays out);
  the static views use the same region as the interaction frames, so that what an interaction
  frame's mask holds beside the object (a wall, furniture) is in the splat and explained as
  static, not mistaken for motion; the export keeps only the box itself;
- a pixel without depth (dark, grazing, a depth edge) is object when its ray passes through that
  box, so a black door keeps its colour pixels;
- where the capture has a mask, the result is the mask AND the box.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..model.capture import Capture, Frame
from ..model.crop import CropBox
from .consistency import unsupported
from .separate import camera_up, separate_object

SEPARATION = "separation"
SEPARATED_BY = "reconstruct"   # the stage that writes the separation's crop.json
MAX_POINTS = 200_000
BAND = 2.5           # raw depth: a wall goes with 2.5 plane tolerances on either side of it


def needs_separation(capture: Capture) -> bool:
    """True when no static view has a mask (the splat would hold the room)."""
    return all(f.mask is None for f in capture.static)


def fused_points(frames: list[Frame], limit: int = MAX_POINTS, seed: int = 0,
                 margin: float = 0.03) -> np.ndarray:
    """The frames' back-projected depth (world, N x 3), at most ``limit`` points (random subset),
    without the points two views see through (flying pixels and far noise: streaks along the
    rays that would join the object to everything around it; :func:`unsupported`)."""
    pts = [f.camera.backproject(f.depth, f.mask)[0] for f in frames if f.depth is not None]
    points = np.concatenate(pts) if pts else np.zeros((0, 3))
    if len(points) > limit:
        points = points[np.random.default_rng(seed).choice(len(points), limit, replace=False)]
    return points[~unsupported(points, frames, margin)]


def separation_crop(capture: Capture) -> tuple[CropBox, dict] | None:
    """The object's closed box from the static views' depth, and how it was found (None when the
    separation keeps nothing). Box axes: the cameras' up and the object's two principal
    horizontal directions; extents from the 0.5-99.5 percentiles of its points, + 2 %."""
    points = fused_points(capture.static)
    if len(points) < 100:
        return None
    c2ws = np.array([f.camera.c2w for f in capture.static])
    inter = np.array([f.camera.c2w for f in capture.interaction]).reshape(-1, 4, 4)
    sep = separate_object(points, c2ws, inter, band=BAND)
    obj = points[sep.mask]
    if len(obj) < 100:
        return None
    up = sep.up
    flat = obj - np.outer(obj @ up, up)
    flat = flat - flat.mean(0)
    _, _, vt = np.linalg.svd(flat[:: max(1, len(flat) // 20000)], full_matrices=False)
    a = vt[0] - (vt[0] @ up) * up
    a /= np.linalg.norm(a)
    axes = np.array([a, np.cross(up, a), up])
    local = obj @ axes.T
    lo, hi = np.percentile(local, 0.5, axis=0), np.percentile(local, 99.5, axis=0)
    pad = 0.02 * (hi - lo).max()
    lo, hi = lo - pad, hi + pad
    if sep.floor is not None:             # the box stands on the floor, never below it
        n, d = sep.floor
        lo[2] = d / max(float(n @ up), 1e-6) + 0.5 * pad
    box = CropBox((0.5 * (lo + hi)) @ axes, axes, 0.5 * (hi - lo), SEPARATION)
    how = {"points": int(len(points)), "object_points": int(len(obj)), "removed": sep.removed,
           "floor": None if sep.floor is None else {"normal": sep.floor[0].tolist(),
                                                    "offset": float(sep.floor[1])}}
    return box, how


def moving_box(box: CropBox, up: np.ndarray) -> tuple[CropBox, float]:
    """The region the moving parts may reach: ``box`` grown by its largest extent across ``up``
    on every side and on top; and the height (along ``up``) below which nothing counts."""
    bottom = float(np.min(box.corners() @ up))
    size = 2.0 * box.half_size
    across = np.abs(box.axes @ up) < 0.9
    grow = float(size[across].max()) if across.any() else float(size.max())
    return dataclasses.replace(box, half_size=box.half_size + grow), bottom


def ray_hits_box(origin: np.ndarray, dirs: np.ndarray, box: CropBox) -> np.ndarray:
    """Bool per ray (dirs N x 3, world): the ray from ``origin`` passes through ``box`` (slabs)."""
    o = (origin - box.center) @ box.axes.T
    d = dirs @ box.axes.T
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (-box.half_size - o) / d
        t2 = (box.half_size - o) / d
    t1 = np.where(np.isnan(t1), -np.inf, t1)
    t2 = np.where(np.isnan(t2), np.inf, t2)
    near = np.minimum(t1, t2).max(1)
    far = np.maximum(t1, t2).min(1)
    return (far >= np.maximum(near, 0.0))


def frame_crop_mask(frame: Frame, box: CropBox, bottom: float | None, up: np.ndarray
                    ) -> np.ndarray:
    """The pixels of ``frame`` that belong to ``box`` (see the module docstring), (H, W) bool."""
    cam = frame.camera
    rays = cam.pixel_rays().reshape(-1, 3) @ np.linalg.inv(cam.w2c)[:3, :3].T
    origin = cam.c2w[:3, 3]
    depth = frame.depth.reshape(-1) if frame.depth is not None else \
        np.zeros(cam.height * cam.width, np.float32)
    has = np.isfinite(depth) & (depth > 0)
    pts = origin + rays[has] * depth[has, None]
    inside = box.contains(pts)
    if bottom is not None:
        inside &= pts @ up >= bottom
    mask = np.zeros(len(depth), bool)
    mask[np.flatnonzero(has)] = inside
    missing = np.flatnonzero(~has)
    mask[missing] = ray_hits_box(origin, rays[missing], box)
    mask = mask.reshape(cam.height, cam.width)
    return mask if frame.mask is None else mask & frame.mask.astype(bool)


def crop_capture(capture: Capture, box: CropBox | None) -> Capture:
    """``capture`` as the stages see it with ``box`` (None: unchanged): every frame's mask becomes
    its box mask (AND its own mask). Frames are shallow copies; the input is not changed."""
    if box is None:
        return capture
    up = camera_up(np.array([f.camera.c2w for f in capture.frames]))
    grown, bottom = moving_box(box, up)
    frames = [dataclasses.replace(f, mask=frame_crop_mask(f, grown, bottom, up))
              for f in capture.frames]
    return dataclasses.replace(capture, frames=frames)
