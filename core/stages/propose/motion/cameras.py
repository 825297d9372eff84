"""The fixed interaction cameras: depth per step, closed-state depth, change thresholds, and
projecting world points into them.

Everything change detection (core/stages/propose/motion/change.py) and tracking compare comes
from an :class:`InteractionView`'s ``depth`` / ``mask`` per step and its closed state ``ref``, all
built in :func:`make_views`; a source of known occluders (a robot twin rendering the arm per step)
joins there, before any comparison.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.ndimage import minimum_filter

from ....model.cameras import Camera
from ....geometry.consistency import depth_range
from ....geometry.noise import noise_sigma
from ....geometry.occlusion import object_depth
from ....model.capture import Capture, Frame
from .config import CLOSED_TIME, MotionConfig


@dataclass
class InteractionView:
    """One fixed interaction camera: its object depth per step, free space per step (see
    :func:`object_depth`), and closed-state depth."""

    name: str
    camera: Camera
    depth: dict[int, np.ndarray]
    free: dict[int, np.ndarray]
    ref: np.ndarray
    ref_source: str
    pool: int = 1                     # depth is the median over pool x pool pixels
    threshold: float = 0.0            # change threshold between measurements (m)
    ref_threshold: float = 0.0        # ... between a measurement and the closed state (m)
    rays: np.ndarray = field(default=None, repr=False)  # type: ignore[assignment]
    ranges: dict[int | str, Any] = field(default_factory=dict, repr=False)   # per-step caches

    def changed_at(self, t: int) -> np.ndarray:
        """Pixels whose surface at step ``t`` came in front of the closed state's (boolean image):
        where a part opened to (parts open outwards from the closed state; what they reveal lies
        behind it). With a rendered closed state :func:`change.mark_changed` sets these."""
        key = f"changed{t}"
        if key not in self.ranges:
            d = self.depth[t]
            self.ranges[key] = (d > 0) & ((self.ref <= 0) | (d < self.ref - self.ref_threshold))
        return self.ranges[key]

    def free_near(self, t: int) -> np.ndarray:
        """Free space (:func:`object_depth`) that a pixel's whole 3x3 neighbourhood agrees on."""
        key = f"free{t}"
        if key not in self.ranges:
            self.ranges[key] = minimum_filter(self.free[t], size=3, mode="nearest")
        return self.ranges[key]

    def occluder(self, t: int) -> np.ndarray:
        """Depth of something in front that is not the object (robot, hand), inf where none."""
        f = self.free[t]
        return np.where((f > 0) & np.isfinite(f), f, np.inf)

    def nearest_at(self, t: int) -> np.ndarray:
        """Nearest valid depth in each pixel's 3x3 neighbourhood at step ``t`` (0: none)."""
        key = f"near{t}"
        if key not in self.ranges:
            d = self.depth[t]
            near = minimum_filter(np.where(d > 0, d, np.inf), size=3, mode="nearest")
            self.ranges[key] = np.where(np.isfinite(near), near, 0.0)
        return self.ranges[key]

    def range_at(self, t: int | str) -> tuple[np.ndarray, np.ndarray]:
        """Near and far depth of each pixel's surface at step ``t`` (``"ref"``: closed state), see
        :func:`depth_range`; comparing a point's depth with this range tolerates grazing views."""
        if t not in self.ranges:
            self.ranges[t] = depth_range(self.ref if t == "ref" else self.depth[t])
        return self.ranges[t]


def group_views(frames: list[Frame]) -> list[list[Frame]]:
    """Interaction frames grouped by fixed camera (same pose and intrinsics), sorted by time."""
    groups: list[list[Frame]] = []
    for f in frames:
        for g in groups:
            c = g[0].camera
            if (np.allclose(c.c2w, f.camera.c2w, atol=1e-6) and np.allclose(c.K, f.camera.K)
                    and (c.width, c.height) == (f.camera.width, f.camera.height)):
                g.append(f)
                break
        else:
            groups.append([f])
    return [sorted(g, key=lambda f: f.time) for g in groups]


def make_views(capture: Capture, render_depth, config: MotionConfig, robot_depth=None
               ) -> list[InteractionView]:
    """Views of the interaction cameras; ``render_depth(camera) -> (H,W)`` gives the closed state
    where a camera has no time-0 frame; ``robot_depth(frame) -> (H,W) | None`` the robot twin's
    depth (0 where it does not cover the pixel; see :func:`object_depth`)."""
    t0 = CLOSED_TIME
    views = []
    for k, g in enumerate(group_views(capture.interaction)):
        depth, free = {}, {}
        for f in g:
            depth[f.time], free[f.time] = object_depth(
                f, None if robot_depth is None else robot_depth(f), config.min_threshold)
        if g[0].time == t0:
            ref, source = depth[t0], g[0].file_path
        else:
            ref, source = render_depth(g[0].camera).astype(np.float32), "splat"
        v = InteractionView(f"cam{k}", g[0].camera, depth, free, ref, source)
        v.threshold, v.ref_threshold = _thresholds(v, noise_sigma(list(depth.values())), config,
                                                   source == "splat")
        v.rays = g[0].camera.pixel_rays()
        views.append(v)
    return views


def pooled_views(views: list[InteractionView], config: MotionConfig, window: int = 0
                 ) -> list[InteractionView]:
    """``views`` with each camera's depth the median over ``window`` x ``window`` pixels
    (:func:`pooled`; 0: per camera, :func:`pool_size`), a measured closed state with it, and
    the thresholds of the pooled noise; free space, rendered closed states and rays are
    shared (nothing is measured or rendered again)."""
    out = []
    for v in views:
        sigma = noise_sigma(list(v.depth.values()))
        k = window or pool_size(sigma, next(iter(v.depth.values())), v.camera, config)
        if k <= 1:
            out.append(v)
            continue
        depth = {t: pooled(d, k) for t, d in v.depth.items()}
        rendered = v.ref_source == "splat"
        p = InteractionView(v.name, v.camera, depth, v.free,
                            v.ref if rendered else depth[CLOSED_TIME], v.ref_source, k)
        p.threshold, p.ref_threshold = _thresholds(p, sigma * MEDIAN_EFFICIENCY / k, config,
                                                   rendered)
        p.rays = v.rays
        out.append(p)
    return out


#: Noise of a median of n Gaussian samples is sqrt(pi / 2) / sqrt(n) sigma.
MEDIAN_EFFICIENCY = math.sqrt(math.pi / 2.0)


def pool_size(sigma: float, depth: np.ndarray, camera: Camera, config: MotionConfig) -> int:
    """The smallest odd window (at most ``config.max_pool``) whose pooled change threshold is no
    larger than its footprint on the object: depth then resolves motion as finely as the pooled
    pixels do sideways. Near cameras with millimetre noise keep single pixels; a camera 6 m away
    with 8 cm noise pools 5 x 5."""
    z = float(np.median(depth[depth > 0])) if np.any(depth > 0) else 0.0
    if z <= 0 or sigma <= 0:
        return 1
    need = config.noise_sigmas * math.sqrt(2.0) * MEDIAN_EFFICIENCY * sigma * camera.K[0, 0] / z
    k = 1
    while k < config.max_pool and k * k < need:
        k += 2
    return k


def pooled(depth: np.ndarray, k: int) -> np.ndarray:
    """Median of the measured depths in each measured pixel's k x k neighbourhood (0 stays 0).
    A median keeps depth edges (the majority surface wins) and divides the noise by about
    ``k / MEDIAN_EFFICIENCY``; far cameras need it to see parts that move centimetres."""
    pad = k // 2
    d = np.pad(np.where(depth > 0, depth, np.nan), pad, constant_values=np.nan)
    windows = np.lib.stride_tricks.sliding_window_view(d, (k, k)).reshape(*depth.shape, k * k)
    with warnings.catch_warnings():   # all-NaN windows (unmeasured pixels) are dropped below
        warnings.simplefilter("ignore", RuntimeWarning)
        med = np.nanmedian(windows, axis=-1)
    return np.where(depth > 0, med, 0.0).astype(np.float32)


def _thresholds(v: InteractionView, sigma: float, config: MotionConfig, rendered: bool
                ) -> tuple[float, float]:
    """Change thresholds of a view from its depth noise ``sigma`` (m): between two measurements,
    and between a measurement and the closed state (larger when the closed state is a render of
    the splat: its error on pixels that no step changes sets it)."""
    thr = max(config.noise_sigmas * math.sqrt(2.0) * sigma, config.min_threshold)
    if not rendered:
        return thr, thr
    stack = np.stack(list(v.depth.values()))
    still = np.all(stack > 0, axis=0) & (stack.max(0) - stack.min(0) < thr) & (v.ref > 0)
    if still.sum() < 20:
        return thr, max(thr, config.render_threshold)
    err = float(np.median(np.abs(np.median(stack, axis=0) - v.ref)[still]))
    return thr, max(thr, config.render_sigmas * 1.4826 * err)


def pixels_of(v: InteractionView, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Project world points into ``v``: inside-image flags, flat pixel indices (0 outside), and
    z-depths."""
    if "proj" not in v.ranges:
        w2c = v.camera.w2c
        v.ranges["proj"] = (w2c[:3, :3].T.copy(), w2c[:3, 3].copy())
    Rt, tr = v.ranges["proj"]
    cam = points @ Rt + tr
    z = cam[:, 2]
    K = v.camera.K
    h, w = v.ref.shape
    with np.errstate(divide="ignore", invalid="ignore"):
        j = np.floor(cam[:, 0] / z * K[0, 0] + K[0, 2])
        i = np.floor(cam[:, 1] / z * K[1, 1] + K[1, 2])
    inside = (z > 1e-3) & (i >= 0) & (i < h) & (j >= 0) & (j < w)
    flat = np.where(inside, i * w + j, 0).astype(np.int64)
    return inside, flat, z


def lookup(v: InteractionView, t: int | str, points: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Project world points into ``v`` at step ``t``: inside-image flags, their z-depth, and the
    depth range (near, far) of the surface at their pixels (0 = no object there)."""
    inside, flat, z = pixels_of(v, points)
    lo_img, hi_img = v.range_at(t)
    lo = np.where(inside, lo_img.reshape(-1)[flat], 0.0)
    hi = np.where(inside, hi_img.reshape(-1)[flat], 0.0)
    return inside, z, lo, hi


def step_cloud(views: list[InteractionView], t: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """All views' measured points at step ``t``: points, unit normals (facing the camera), and
    whether each point is in front of the closed state (moved in)."""
    pts, nrm, moved = [], [], []
    for v in views:
        if t not in v.depth:
            continue
        d = v.depth[t]
        P, N, ok = grid_points(v, d)
        sel = ok.reshape(-1)
        pts.append(P.reshape(-1, 3)[sel])
        nrm.append(N.reshape(-1, 3)[sel])
        ahead = (d > 0) & ((v.ref <= 0) | (d < v.ref - v.ref_threshold))
        moved.append(ahead.reshape(-1)[sel])
    if not pts:
        return np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, bool)
    return np.concatenate(pts), np.concatenate(nrm), np.concatenate(moved)


def grid_points(v: InteractionView, d: np.ndarray, step: int = 2
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World points (H,W,3) of a depth map, normals from neighbours ``step`` pixels away, valid."""
    cam = v.rays * d[..., None]
    c2w = np.linalg.inv(v.camera.w2c)
    P = cam @ c2w[:3, :3].T + c2w[:3, 3]
    du = np.zeros_like(P)
    dv = np.zeros_like(P)
    du[:, step:-step] = P[:, 2 * step:] - P[:, :-2 * step]
    dv[step:-step] = P[2 * step:] - P[:-2 * step]
    N = np.cross(du, dv)
    n = np.linalg.norm(N, axis=-1, keepdims=True)
    N = N / np.maximum(n, 1e-12)
    towards = v.camera.center - P
    N *= np.sign(np.sum(N * towards, axis=-1, keepdims=True) + 1e-12)
    valid = d > 0
    # normals only where the neighbourhood is one surface (no depth jumps)
    dd = np.zeros_like(d)
    for a, b in ((np.s_[:, step:-step], (np.s_[:, 2 * step:], np.s_[:, :-2 * step])),
                 (np.s_[step:-step], (np.s_[2 * step:], np.s_[:-2 * step]))):
        jump = np.maximum(np.abs(d[b[0]] - d[a]), np.abs(d[b[1]] - d[a]))
        jump = np.where((d[b[0]] > 0) & (d[b[1]] > 0), jump, np.inf)
        dd[a] = np.maximum(dd[a], jump)
    dd[:, :step] = dd[:, -step:] = dd[:step] = dd[-step:] = np.inf
    ok = valid & (n[..., 0] > 0) & (dd < 0.05 * np.maximum(d, 1e-3))
    return P, N, ok
