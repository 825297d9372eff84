"""Joints from motion: the static splat and the interaction frames (the default proposal route).

Steps (all in the world frame, metres):

1. Interaction frames are grouped into fixed cameras (same pose and intrinsics). Each camera's
   closed-state depth is its frame at time 0 when it has one, else the static splat rendered
   from it.
2. Depth noise per camera comes from second differences of its depth maps on smooth surfaces; the
   change threshold is a multiple of it (for a rendered closed state, of the render's error).
3. A static splat point that the closed-state view sees and that a later step sees *through*
   (measured depth farther than the point by more than the threshold, or no object there) belongs
   to a moving part: rigid scenes cannot reveal what was behind a surface. Such points are grouped
   into parts by 3D connectivity and the step at which they first vanish.
4. Each part is tracked through the steps. Pose hypotheses (previous pose, constant velocity,
   earlier poses, turns about the part's box edges and slides along its normal) are scored by
   projecting the part into the step's depth maps (:func:`projective_score`), the best refined by
   robust point-to-plane ICP against the step's measured points and then by a pattern search on
   the projective score (silhouettes pin what flat faces leave free). The part's model grows with
   the measured points that moved in with it (a door's inner face, a drawer's sides).
5. One revolute and one prismatic joint are fitted to all the part's poses jointly
   (core.rigid.fit_joint); the part is revolute if it turns and a slide explains it clearly
   worse. The joint is then refined on the measurements of all steps at once
   (core.rigid.refine_joint) using the splat's own part points. A slide within ``snap_deg`` of the
   part front's normal is taken along that normal (a flat front measures only that component).
6. Joint values per step are ``states`` (positive = open), the observed range is ``limit``;
   extent (oriented box of the part in the closed state), handle, bbox and confidence follow.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from scipy.ndimage import minimum_filter
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ...model.cameras import Camera
from ...model.capture import Capture, Frame
from ...model.joints import Joint, joint_transform, rotation_about_axis
from ...model.progress import QUIET, Progress
from ...geometry.rigid import (StepData, apply, fit_joint, icp, invert, make_transform, refine_joint,
                    rotation_log, tukey_weights)


#: The interaction time at which every part is closed (a camera's frame at this time, if it has
#: one, is its closed state; other cameras render the static splat instead).
CLOSED_TIME = 0


@dataclass
class MotionConfig:
    """Tuning of the motion route (defaults suit 2 mm-class depth noise)."""

    noise_sigmas: float = 5.0         # change threshold = this many noise sigmas (of a difference)
    min_threshold: float = 0.006      # ... but at least this (m)
    render_sigmas: float = 3.0        # closed state rendered from the splat: this many sigmas of
    render_threshold: float = 0.03    # its error, or this (m) when that cannot be measured
    min_opacity: float = 0.5          # splat points used as closed-state geometry
    link_pixels: float = 3.0          # 3D connectivity radius, in static-point spacings
    min_part_points: int = 40         # smaller groups of vanished points are noise
    min_part_fraction: float = 0.01   # ... or smaller than this share of the splat points
    track_points: int = 1200          # part points used for tracking
    min_angle_deg: float = 8.0        # revolute when the part turns at least this much ...
    min_rms_ratio: float = 3.0        # ... and a slide fits that much worse (core.rigid.fit_joint)
    icp_iterations: int = 30
    icp_candidates: int = 5           # best-scoring pose hypotheses refined by ICP per step
    jump_penalty: float = 0.5         # score cost of a pose far from the constant-velocity guess
    grow_score: float = 0.3           # steps tracked at least this well add points to the part
    grow_depth: float = 0.1           # ... from at most this far behind its closed front (m)
    refine_rounds: int = 10           # rounds of joint refinement on the measurements ...
    refine_point_weight: float = 0.2  # ... with this weight of point-to-point residuals
    snap_deg: float = 25.0            # a slide this close to the front's normal is taken along it


@dataclass
class View:
    """One fixed interaction camera: its object depth per step, free space per step (see
    :func:`object_depth`), and closed-state depth."""

    name: str
    camera: Camera
    depth: dict[int, np.ndarray]
    free: dict[int, np.ndarray]
    ref: np.ndarray
    ref_source: str
    threshold: float = 0.0            # change threshold between measurements (m)
    ref_threshold: float = 0.0        # ... between a measurement and the closed state (m)
    rays: np.ndarray = field(default=None, repr=False)  # type: ignore[assignment]
    ranges: dict[int | str, Any] = field(default_factory=dict, repr=False)   # per-step caches

    def changed_at(self, t: int) -> np.ndarray:
        """Pixels whose surface at step ``t`` came in front of the closed state's (boolean image):
        where a part opened to (parts open outwards from the closed state; what they reveal lies
        behind it). With a rendered closed state :func:`mark_changed` sets these."""
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


def mark_changed(views: list[View], points: np.ndarray, spacing: float) -> None:
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
            P, _, _ = _grid_points(v, d)
            valid = d > 0
            far = np.zeros(d.shape, bool)
            far[valid] = tree.query(P[valid], distance_upper_bound=tol)[0] > tol
            v.ranges[f"changed{t}"] = far & ((v.ref <= 0) | (d < v.ref + v.ref_threshold))


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


# --- views and thresholds ---------------------------------------------------------------------

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
               ) -> list[View]:
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
        v = View(f"cam{k}", g[0].camera, depth, free, ref, source)
        v.threshold, v.ref_threshold = _thresholds(v, config, source == "splat")
        v.rays = g[0].camera.pixel_rays()
        views.append(v)
    return views


def _depth(f: Frame) -> np.ndarray:
    d = np.zeros(f.rgb.shape[:2], np.float32) if f.depth is None else np.nan_to_num(f.depth)
    if f.mask is not None:
        d = np.where(f.mask, d, 0.0).astype(np.float32)
    return d


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
        tol = np.maximum(tolerance, 0.02 * robot)
        arm = (robot > 0) & ((raw <= 0) | (np.abs(raw - robot) < tol))
        obj &= ~arm
        raw = np.where(arm & (raw <= 0), robot, raw)
    free = np.where(obj, 0.0, np.where(raw > 0, raw, np.inf))
    return np.where(obj, raw, 0.0).astype(np.float32), free


def noise_sigma(depths: list[np.ndarray]) -> float:
    """Depth noise (m, one sigma) from second differences along image rows on smooth surfaces
    (median over the images; a robust spread, so edges do not count)."""
    sigmas = []
    for d in depths:
        a, b, c = d[:, :-2], d[:, 1:-1], d[:, 2:]
        ok = (a > 0) & (b > 0) & (c > 0)
        if ok.sum() > 20:
            sigmas.append(1.4826 * float(np.median(np.abs(a + c - 2 * b)[ok])) / math.sqrt(6.0))
    return float(np.median(sigmas)) if sigmas else 0.0


def _thresholds(v: View, config: MotionConfig, rendered: bool) -> tuple[float, float]:
    """Change thresholds of a view: between two measurements, and between a measurement and the
    closed state (larger when the closed state is a render of the splat: its error on pixels that
    no step changes sets it)."""
    thr = max(config.noise_sigmas * math.sqrt(2.0) * noise_sigma(list(v.depth.values())),
              config.min_threshold)
    if not rendered:
        return thr, thr
    stack = np.stack(list(v.depth.values()))
    still = np.all(stack > 0, axis=0) & (stack.max(0) - stack.min(0) < thr) & (v.ref > 0)
    if still.sum() < 20:
        return thr, max(thr, config.render_threshold)
    err = float(np.median(np.abs(np.median(stack, axis=0) - v.ref)[still]))
    return thr, max(thr, config.render_sigmas * 1.4826 * err)


def _pixels(v: View, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
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


def _lookup(v: View, t: int | str, points: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Project world points into ``v`` at step ``t``: inside-image flags, their z-depth, and the
    depth range (near, far) of the surface at their pixels (0 = no object there)."""
    inside, flat, z = _pixels(v, points)
    lo_img, hi_img = v.range_at(t)
    lo = np.where(inside, lo_img.reshape(-1)[flat], 0.0)
    hi = np.where(inside, hi_img.reshape(-1)[flat], 0.0)
    return inside, z, lo, hi


# --- vanished points and parts ------------------------------------------------------------------

def vanish_times(points: np.ndarray, views: list[View], times: list[int], spacing: float
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per point: first step at which a view sees through it (-1: never), how many times, and
    the earliest step it may have vanished at: before its first step, the steps in which every
    view that saw it closed had something in front of it (an arm, or an opened part) and an arm
    hid it in some view (then, or in the closed state) leave the onset open. Without an arm
    (nothing outside the masks in front of the object) the onset is the first step. ``spacing``: the points' typical spacing (m)."""
    first = np.full(len(points), -1, np.int64)
    count = np.zeros(len(points), np.int64)
    hidden = np.ones((len(points), len(times)), bool)
    behind_arm = np.zeros((len(points), len(times)), bool)
    for v in views:
        inside, z, lo, hi = _lookup(v, "ref", points)
        flat = _pixels(v, points)[1]
        if v.ref_source == "splat":   # splat points scatter about a spacing around surfaces
            seen = _front_points(v, points, spacing) & (z < hi + v.ref_threshold)
            margin = max(v.threshold, 1.5 * spacing)
        else:
            seen = inside & (lo > 0) & (z > lo - v.threshold) & (z < hi + v.threshold)
            margin = v.threshold
        for k, t in enumerate(times):
            if t not in v.depth:
                continue
            _, _, d, _ = _lookup(v, t, points)
            occ = np.where(inside, v.occluder(t).reshape(-1)[flat], np.inf)
            hidden[:, k] &= ~seen | (occ < z - margin) | ((d > 0) & (d < z - margin))
            behind_arm[:, k] |= occ < z - margin
            if CLOSED_TIME in v.free:   # an arm hid it in the closed state: this view's onset
                closed = np.where(inside, v.occluder(CLOSED_TIME).reshape(-1)[flat], np.inf)
                behind_arm[:, k] |= closed < z - margin
            # background where the part was counts only against a measured closed state (the
            # render's silhouette is blurred: points at its rim would all seem gone); an arm in
            # front of the point says nothing (object_depth)
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


def _front_points(v: View, points: np.ndarray, spacing: float) -> np.ndarray:
    """Which points are in front in ``v``: within ``max(threshold, 1.5 spacing)`` of the nearest
    point over their pixel (a point z-buffer; empty pixels take their 3x3 neighbourhood's). A
    rendered closed state blends depth layers, too loosely to tell the front points."""
    inside, flat, z = _pixels(v, points)
    zbuf = np.full(v.ref.size, np.inf)
    np.minimum.at(zbuf, flat[inside], z[inside])
    zbuf = zbuf.reshape(v.ref.shape)
    zbuf = np.where(np.isfinite(zbuf), zbuf, minimum_filter(zbuf, size=3, mode="nearest"))
    return inside & (z < zbuf.reshape(-1)[flat] + max(v.threshold, 1.5 * spacing))


def floaters(points: np.ndarray, frames: list[Frame], margin: float) -> np.ndarray:
    """Splat points that two or more static views see through (measured depth beyond the point
    by more than ``margin``): nothing moves in the static views, so these float off the surface
    and would pass for vanished part points."""
    through = np.zeros(len(points), np.int64)
    for f in frames:
        if f.depth is None:
            continue
        lo, _ = depth_range(_depth(f))
        uv, z = f.camera.project(points)
        h, w = lo.shape
        with np.errstate(invalid="ignore"):
            j = np.floor(uv[:, 0]).astype(np.int64)
            i = np.floor(uv[:, 1]).astype(np.int64)
        inside = (z > 1e-3) & (i >= 0) & (i < h) & (j >= 0) & (j < w)
        d = np.zeros(len(points))
        d[inside] = lo[i[inside], j[inside]]
        through += (d > 0) & (d - z > margin)
    return through >= 2


def moving_at(points: np.ndarray, views: list[View], times: list[int]) -> np.ndarray:
    """(N, steps) flags: some view's depth at the point's pixel changed from the step before."""
    active = np.zeros((len(points), len(times)), bool)
    for v in views:
        inside, flat, _ = _pixels(v, points)
        for k in range(1, len(times)):
            a, b = times[k - 1], times[k]
            if a not in v.depth or b not in v.depth:
                continue
            da, db = v.depth[a].reshape(-1)[flat], v.depth[b].reshape(-1)[flat]
            active[:, k] |= inside & (((da > 0) != (db > 0)) | (np.abs(db - da) > v.threshold))
    return active


def group_parts(points: np.ndarray, first: np.ndarray, active: np.ndarray, times: list[int],
                radius: float, min_points: int, onset_ratio: float = 2.5,
                earliest: np.ndarray | None = None) -> list[np.ndarray]:
    """Index arrays of moving parts, largest first.

    Vanished points within ``radius`` of each other are linked when they first vanish at the same
    step, or one step apart while the earlier one's pixels still change (``active``, from
    :func:`moving_at`): a door's hinge side vanishes steps after its edge. A group whose count of
    newly vanished points jumps by ``onset_ratio`` from one step to the next holds a second part
    starting there (a neighbouring drawer opened after the door); the links across that step are
    cut. ``earliest`` (from :func:`vanish_times`): a point hidden by an arm may have vanished as
    early as this step, so it links with points vanishing anywhere from there to its first step.
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


# --- measured points per step -------------------------------------------------------------------

def step_cloud(views: list[View], t: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """All views' measured points at step ``t``: points, unit normals (facing the camera), and
    whether each point is in front of the closed state (moved in)."""
    pts, nrm, moved = [], [], []
    for v in views:
        if t not in v.depth:
            continue
        d = v.depth[t]
        P, N, ok = _grid_points(v, d)
        sel = ok.reshape(-1)
        pts.append(P.reshape(-1, 3)[sel])
        nrm.append(N.reshape(-1, 3)[sel])
        ahead = (d > 0) & ((v.ref <= 0) | (d < v.ref - v.ref_threshold))
        moved.append(ahead.reshape(-1)[sel])
    if not pts:
        return np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, bool)
    return np.concatenate(pts), np.concatenate(nrm), np.concatenate(moved)


def _grid_points(v: View, d: np.ndarray, step: int = 2
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


# --- tracking ---------------------------------------------------------------------------------

def projective_score(points: np.ndarray, T: np.ndarray, views: list[View], t: int) -> float:
    """Agreement of closed-state part ``points`` placed by ``T`` at step ``t`` with the depth maps,
    per point (-1..1).

    A point on a measured surface scores up to 1 (less as it nears the threshold), provided the
    surface there came in front of the closed state's (:meth:`View.changed_at`) or the point
    stayed near its closed place (a moved part cannot sit on geometry that was already there).
    A point in front of every measured surface of its pixel's 3x3 neighbourhood, or over a
    neighbourhood showing no object, scores -1 (it would have been seen). A hidden point (behind
    the surface) or one outside every view scores 0. The best view counts.
    """
    Y = apply(T, points)
    stayed = np.linalg.norm(Y - points, axis=1)
    best = np.zeros(len(Y))
    wrong = np.zeros(len(Y), bool)
    for v in views:
        if t not in v.depth:
            continue
        inside, flat, z = _pixels(v, Y)
        lo_img, hi_img = v.range_at(t)
        lo = np.where(inside, lo_img.reshape(-1)[flat], 0.0)
        hi = np.where(inside, hi_img.reshape(-1)[flat], 0.0)
        has = inside & (lo > 0)
        off = np.maximum(np.maximum(lo - z, z - hi), 0.0) / v.threshold
        new = (inside & v.changed_at(t).reshape(-1)[flat]) | (stayed < 2 * v.threshold)
        best = np.maximum(best, np.where(has & new & (off < 1), 1.0 - off * off, 0.0))
        # contradictions only where the whole 3x3 neighbourhood agrees (edges are ambiguous)
        near = np.where(inside, v.nearest_at(t).reshape(-1)[flat], 0.0)
        wrong |= (inside & (near > 0) & (z < near - v.threshold)) \
            | (inside & (near <= 0) & (z < v.free_near(t).reshape(-1)[flat] - v.threshold))
    return float(np.where(best > 0, best, -wrong.astype(float)).sum()) / max(len(Y), 1)


def polish(T: np.ndarray, points: np.ndarray, views: list[View], t: int, step: float,
           min_step: float) -> tuple[np.ndarray, float]:
    """Pattern search of the pose ``T`` maximising :func:`projective_score` (translations of
    ``step`` metres and turns of the matching angle about the part's centre, halved down to
    ``min_step``). Silhouettes pin what flat faces leave free in point-to-plane ICP."""
    c = apply(T, points).mean(axis=0)
    size = max(float(np.linalg.norm(points - points.mean(axis=0), axis=1).max()), 1e-3)
    best = projective_score(points, T, views, t)
    while step >= min_step:
        improved = False
        for k in range(6):
            for sign in (-1.0, 1.0):
                if k < 3:
                    D = make_transform(np.eye(3), sign * step * np.eye(3)[k])
                else:
                    R = rotation_about_axis(np.eye(3)[k - 3], sign * step / size)
                    D = make_transform(R, c - R @ c)
                cand = D @ T
                s = projective_score(points, cand, views, t)
                if s > best + 1e-6:
                    best, T, improved = s, cand, True
        if not improved:
            step /= 2
    return T, best


def _visible(views: list[View], t: int):
    def keep(points: np.ndarray) -> np.ndarray:
        ok = np.zeros(len(points), bool)
        for v in views:
            if t not in v.depth:
                continue
            inside, z, _, hi = _lookup(v, t, points)   # a point behind an arm is not visible
            occ = np.where(inside, v.occluder(t).reshape(-1)[_pixels(v, points)[1]], np.inf)
            ok |= inside & (((hi <= 0) & (z < occ + v.threshold)) | (z - hi < v.threshold))
        return ok
    return keep


def box_of(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Oriented box (centre, axes rows thinnest first, half sizes) by PCA, robust percentiles."""
    c = np.median(points, axis=0)
    _, _, Vt = np.linalg.svd(points - c, full_matrices=False)
    axes = Vt[::-1].copy()
    local = (points - c) @ axes.T
    lo, hi = np.percentile(local, 1, axis=0), np.percentile(local, 99, axis=0)
    center = c + ((lo + hi) / 2) @ axes
    return center, axes, (hi - lo) / 2


def first_move_hypotheses(points: np.ndarray) -> list[np.ndarray]:
    """Plausible first motions of a panel-like part: turns about its box edges, slides along its
    thinnest axis."""
    c, axes, half = box_of(points)
    hyps = []
    for k_dir, k_off in ((1, 2), (2, 1)):
        for s in (-1.0, 1.0):
            p = c + s * half[k_off] * axes[k_off]
            for ang in (8.0, 16.0, 25.0, 35.0, 50.0):
                for sign in (-1.0, 1.0):
                    R = rotation_about_axis(axes[k_dir], math.radians(sign * ang))
                    hyps.append(make_transform(R, p - R @ p))
    for dist in (0.02, 0.04, 0.07, 0.1, 0.14, 0.2):
        for sign in (-1.0, 1.0):
            hyps.append(make_transform(np.eye(3), sign * dist * axes[0]))
    return hyps


@dataclass
class Track:
    """A part's pose per step (closed -> step) with per-step quality."""

    transforms: dict[int, np.ndarray]
    score: dict[int, float]
    rms: dict[int, float]


def _jump(T: np.ndarray, predicted: np.ndarray, points: np.ndarray) -> float:
    """How far pose ``T`` departs from the constant-velocity prediction beyond what a step's
    change of speed explains (0 within 25 degrees and 10 cm of it)."""
    D = T @ invert(predicted)
    angle = math.degrees(rotation_log(D[:3, :3])[1])
    c = points.mean(axis=0, keepdims=True)
    shift = float(np.linalg.norm(apply(T, c) - apply(predicted, c)))
    return max(0.0, (angle - 25.0) / 20.0) + max(0.0, (shift - 0.1) / 0.1)


def track_part(points: np.ndarray, views: list[View], times: list[int], start: int,
               clouds: dict[int, tuple[np.ndarray, np.ndarray, cKDTree, np.ndarray]],
               config: MotionConfig) -> Track:
    """Poses of a part (closed-state ``points``) at every step; identity before ``start``.

    The part's model grows as it moves: measured points that moved in with it (e.g. a door's inner
    face, a drawer's sides) are mapped back to the closed state and tracked from then on, so the
    part stays trackable when the face seen in the static views turns away.
    """
    thr = float(np.median([v.threshold for v in views]))
    model = points
    centre, axes, half = box_of(points)
    cams = np.mean([v.camera.center for v in views], axis=0)
    front = axes[0] if axes[0] @ (cams - centre) >= 0 else -axes[0]
    rng = np.random.default_rng(1)
    Ts: dict[int, np.ndarray] = {}
    score: dict[int, float] = {}
    rms: dict[int, float] = {}
    prev: list[np.ndarray] = []
    for t in times:
        if t < start:
            Ts[t], score[t], rms[t] = np.eye(4), 1.0, 0.0
            prev.append(np.eye(4))
            continue
        base = prev[-1] if prev else np.eye(4)
        hyps = [base]
        predicted = None
        if len(prev) >= 2 and t > start:
            predicted = base @ invert(prev[-2]) @ base
            hyps.append(predicted)
        hyps += prev[:-1]   # the part may go back through earlier poses (closing)
        hyps += [H @ base for H in first_move_hypotheses(apply(base, points))]
        scored = sorted(hyps, key=lambda H: -projective_score(model, H, views, t))
        P, N, tree, moved = clouds[t]
        best = None
        for H in scored[:config.icp_candidates]:
            res = icp(model, P, N, H, tree=tree, max_distance=max(0.05, 4 * thr),
                      min_distance=thr / 2, iterations=config.icp_iterations,
                      keep=_visible(views, t))
            for cand in (res.T, H):   # ICP can slide off along flat faces: keep its start too
                s = projective_score(model, cand, views, t)
                if predicted is not None:
                    s -= config.jump_penalty * _jump(cand, predicted, model)
                if best is None or s > best[0]:
                    best = (s, cand, res.rms)
        _, T, rms_t = best
        T, s = polish(T, model, views, t, 2 * thr, thr / 4)
        Ts[t], score[t], rms[t] = T, s, rms_t
        prev.append(T)
        if s > config.grow_score and moved.any():
            back = apply(invert(T), P[moved])
            rel = back - centre
            local = rel @ axes.T
            depth = rel @ front
            inside = (np.all(np.abs(local[:, 1:]) <= half[1:] + 0.02, axis=1)
                      & (depth <= half[0] + 0.02) & (depth >= -half[0] - config.grow_depth))
            new = back[inside]
            if len(new):
                new = new[cKDTree(model).query(new)[0] > thr]
                if len(new) > config.track_points // 2:
                    new = new[rng.choice(len(new), config.track_points // 2, replace=False)]
                model = np.concatenate([model, new])
                if len(model) > 2 * config.track_points:
                    keep = np.concatenate([np.arange(len(points)), len(points) + rng.choice(
                        len(model) - len(points), 2 * config.track_points - len(points),
                        replace=False)])
                    model = model[keep]
    return Track(Ts, score, rms)


# --- the route --------------------------------------------------------------------------------

def propose_motion(capture: Capture, splat_means: np.ndarray, splat_opacity: np.ndarray,
                   render_depth, progress: Progress = QUIET,
                   config: MotionConfig | None = None, robot_depth=None
                   ) -> tuple[list[Joint], dict[str, Any]]:
    """Joints of the parts that move in ``capture``'s interaction frames.

    ``splat_means`` (N,3) and ``splat_opacity`` (N,) (0..1) are the static splat's Gaussians;
    ``render_depth(camera) -> (H,W)`` renders the splat's depth (used only for cameras without a
    time-0 frame); ``robot_depth(frame) -> (H,W) | None`` the robot twin's depth in a frame
    (core/stages/robot_twin.py; None: no twin). Returns the joints (source ``motion``) and meta
    with per-part diagnostics.
    """
    cfg = config or MotionConfig()
    times = capture.times
    progress.update("propose", 0.02, "closed state per interaction camera")
    views = make_views(capture, render_depth, cfg, robot_depth)
    pts = np.asarray(splat_means, float)[np.asarray(splat_opacity) >= cfg.min_opacity]
    spacing = float(np.median(cKDTree(pts).query(pts, k=2)[0][:, 1])) if len(pts) > 1 else 0.01
    pts = pts[~floaters(pts, capture.static, max(cfg.min_threshold, 1.5 * spacing))]
    mark_changed(views, pts, spacing)
    first, count, earliest = vanish_times(pts, views, times, spacing)
    first[count < 2] = -1
    min_points = max(cfg.min_part_points, int(cfg.min_part_fraction * len(pts)))
    parts = group_parts(pts, first, moving_at(pts, views, times), times,
                        cfg.link_pixels * spacing, min_points, earliest=earliest)
    progress.update("propose", 0.1, f"{len(parts)} moving part(s)", parts=len(parts))

    clouds = {}
    for t in times:
        P, N, moved = step_cloud(views, t)
        clouds[t] = (P, N, cKDTree(P), moved)
    rng = np.random.default_rng(0)
    joints: list[Joint] = []
    diagnostics = []
    for k, idx in enumerate(parts):
        S = pts[idx]
        St = S[rng.choice(len(S), cfg.track_points, replace=False)] \
            if len(S) > cfg.track_points else S
        start = int(np.min(first[idx]))
        track = track_part(St, views, times, start, clouds, cfg)
        moving = [t for t in times if t >= start]
        weights = np.array([max(track.score[t], 0.05) for t in moving])
        fit = fit_joint(St, [track.transforms[t] for t in moving], cfg.min_angle_deg, weights,
                        cfg.min_rms_ratio)
        steps = [StepData(*clouds[t][:3], _visible(views, t)) for t in moving]
        thr = float(np.median([v.threshold for v in views]))
        fit = _refine(fit, St, steps, views, moving, thr, cfg)
        snapped = None
        if fit.type == "prismatic":
            fit, snapped = _snap_to_front(fit, S, cfg.snap_deg)
        values = {t: 0.0 for t in times if t < start}
        values.update({t: float(v) for t, v in zip(moving, fit.values)})
        joint = _make_joint(k, fit, values, moving, S, track, views, clouds)
        joints.append(joint)
        diagnostics.append({"name": joint.name, "points": int(len(S)), "first_step": start,
                            "rms_revolute_mm": _finite(1000 * fit.rms_revolute),
                            "rms_prismatic_mm": _finite(1000 * fit.rms_prismatic),
                            "max_angle_deg": _finite(fit.max_angle_deg),
                            "snapped_to_front_deg": snapped,
                            "score_min": _finite(min(track.score[t] for t in moving)),
                            "icp_rms_mm": _finite(1000 * np.median([track.rms[t]
                                                                    for t in moving]))})
        progress.update("propose", 0.1 + 0.9 * (k + 1) / len(parts), f"part {k + 1}: {joint.type}")
    meta = {"method": "motion",
            "view": _view_meta(views[0]) if views else None,
            "cameras": [{"name": v.name, "closed_state": v.ref_source,
                         "threshold_mm": 1000 * v.threshold,
                         "closed_state_threshold_mm": 1000 * v.ref_threshold} for v in views],
            "motion": diagnostics}
    return joints, meta


def _refine(fit, St: np.ndarray, steps: list[StepData], views: list[View], moving: list[int],
            thr: float, cfg: MotionConfig):
    """Refine the joint on the measurements with the splat's own part points (unbiased by
    tracking; a turning face pins its hinge). Revolute joints start also from hinges on the part's
    box edges parallel to the axis (tracking of a door seen edge-on can misplace its hinge by
    more than the refinement recovers); the start whose refined joint best explains the depth
    maps (:func:`projective_score` over the steps) is refined to the end."""
    def refined(f, rounds: int):
        return refine_joint(f, St, steps, rounds=rounds, min_distance=thr / 2,
                            max_distance=max(0.05, 4 * thr), point_weight=cfg.refine_point_weight)

    def score(f) -> float:
        return float(np.mean([projective_score(St, joint_transform(f.type, f.axis, f.origin, v),
                                               views, t) for t, v in zip(moving, f.values)]))

    starts = [fit]
    if fit.type == "revolute":
        c, axes, half = box_of(St)
        for k in (1, 2):
            if abs(axes[k] @ fit.axis) < 0.5:
                starts += [replace(fit, origin=c + s * half[k] * axes[k]) for s in (-1.0, 1.0)]
    if len(starts) == 1:
        return refined(fit, cfg.refine_rounds)
    first = cfg.refine_rounds // 2
    best = max((refined(f, first) for f in starts), key=score)
    return refined(best, cfg.refine_rounds - first)


def _finite(x: float) -> float | None:
    """A JSON-safe figure (None when not finite), rounded."""
    x = float(x)
    return round(x, 4) if math.isfinite(x) else None


def _view_meta(v: View) -> dict[str, Any]:
    """The view the joints' ``bbox`` refer to: the first interaction camera."""
    cam = v.camera
    return {"camera": v.name, "frame": v.ref_source, "K": cam.K.tolist(), "c2w": cam.c2w.tolist(),
            "width": cam.width, "height": cam.height}


def _make_joint(k: int, fit, values: dict[int, float], moving: list[int], S: np.ndarray,
                track: Track, views: list[View], clouds) -> Joint:
    """A proposal from a joint fit: limits, extent, handle, bbox and confidence."""
    lo, hi = min(0.0, min(values.values())), max(0.0, max(values.values()))
    part = _part_points(S, fit, _fit_transforms(fit, moving), clouds)
    cam_centre = np.mean([v.camera.center for v in views], axis=0)
    c, axes, half = box_of(part)
    facing = (cam_centre - c) @ axes.T
    n = axes[int(np.argmax(np.abs(facing) / np.linalg.norm(cam_centre - c)))]
    n = n * np.sign(n @ (cam_centre - c))
    if fit.type == "prismatic":
        n = fit.axis.copy()
        u = axes[0] - (axes[0] @ n) * n if abs(axes[0] @ n) < 0.9 else axes[1] - (axes[1] @ n) * n
        u /= np.linalg.norm(u)
        box_axes = np.stack([n, u, np.cross(n, u)])
    else:
        a = fit.axis
        n = n - (n @ a) * a
        n /= np.linalg.norm(n)
        box_axes = np.stack([a, n, np.cross(a, n)])
    local = (part - c) @ box_axes.T
    blo, bhi = np.percentile(local, 0.5, axis=0), np.percentile(local, 99.5, axis=0)
    centre = c + ((blo + bhi) / 2) @ box_axes
    extent = {"center": [float(x) for x in centre],
              "axes": [[float(x) for x in r] for r in box_axes],
              "half_size": [float(x) for x in (bhi - blo) / 2]}
    handle = {"point": [float(x) for x in handle_point(S, fit, n)],
              "approach": [float(x) for x in -n]}
    v0 = views[0]
    uv, _ = v0.camera.project(_corners(centre, box_axes, (bhi - blo) / 2))
    size = np.array([v0.camera.width, v0.camera.height], float)
    lo_uv, hi_uv = np.clip(uv.min(axis=0), 0, size), np.clip(uv.max(axis=0), 0, size)
    bbox = [float(lo_uv[0]), float(lo_uv[1]), float(hi_uv[0]), float(hi_uv[1])]
    quality = float(np.clip(np.median([track.score[t] for t in moving]), 0.0, 1.0))
    thr = float(np.median([v.threshold for v in views]))
    rms = fit.rms_revolute if fit.type == "revolute" else fit.rms_prismatic
    confidence = round(quality * math.exp(-rms / (2 * thr)), 3)
    name = f"{fit.type}_{k}"
    return Joint(name=name, type=fit.type, axis=fit.axis,
                 origin=fit.origin if fit.type == "revolute" else centre,
                 limit=(lo, hi), states=values, source="motion", confidence=confidence,
                 bbox=bbox, handle=handle, extent=extent)


def handle_point(S: np.ndarray, fit, n: np.ndarray) -> np.ndarray:
    """Where to grasp the part (closed state): on a revolute part, its band farthest from the axis
    (outer 15 % of the radius), on a prismatic one the whole front; there, the most protruding
    points along the front normal ``n`` (a handle sticks out), averaged."""
    band = S
    if fit.type == "revolute":
        rel = S - fit.origin
        radius = np.linalg.norm(rel - np.outer(rel @ fit.axis, fit.axis), axis=1)
        band = S[radius >= 0.85 * np.percentile(radius, 99)]
    height = band @ n
    return band[height >= np.percentile(height, 95)].mean(axis=0)


def _corners(c: np.ndarray, axes: np.ndarray, half: np.ndarray) -> np.ndarray:
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], float)
    return c + (signs * half) @ axes


def plane_normal(points: np.ndarray, iterations: int = 10) -> np.ndarray:
    """Unit normal of the dominant plane of ``points`` (PCA reweighted by a Tukey biweight)."""
    w = np.ones(len(points))
    n = np.array([0.0, 0.0, 1.0])
    for _ in range(iterations):
        c = (w @ points) / w.sum()
        _, vecs = np.linalg.eigh(((points - c) * w[:, None]).T @ (points - c))
        n = vecs[:, 0]
        r = (points - c) @ n
        w = tukey_weights(r, max(4.685 * 1.4826 * float(np.median(np.abs(r))), 1e-4))
        if w.sum() < 10:
            break
    return n


def _snap_to_front(fit, S: np.ndarray, max_deg: float):
    """A prismatic part slides along its front's normal when the measured slide is within
    ``max_deg`` of it (drawer runners are square to the front). A flat front pins the slide only
    along its normal, so its sideways drift is poorly measured; the front's plane fit over hundreds
    of points is not. Returns the fit and the correction in degrees (None if not snapped)."""
    n = plane_normal(S)
    n = n if n @ fit.axis >= 0 else -n
    angle = math.degrees(math.acos(float(np.clip(n @ fit.axis, -1.0, 1.0))))
    if angle > max_deg:
        return fit, None
    values = fit.values * float(n @ fit.axis)
    return replace(fit, axis=n, values=values), round(angle, 3)


def _fit_transforms(fit, times: list[int]) -> dict[int, np.ndarray]:
    """The fitted joint's motion (closed -> step) at each of ``times``."""
    return {t: joint_transform(fit.type, fit.axis, fit.origin, v)
            for t, v in zip(times, fit.values)}


def _part_points(S: np.ndarray, fit, transforms: dict[int, np.ndarray], clouds) -> np.ndarray:
    """The part in the closed state: its vanished splat points plus the measured points that moved
    in with it (e.g. a drawer's sides), mapped back to the closed state."""
    extra = []
    c, axes, half = box_of(S)
    for t, T in transforms.items():
        P, _, _, moved = clouds[t]
        if np.allclose(T, np.eye(4), atol=1e-4) or not moved.any():
            continue
        back = apply(invert(T), P[moved])
        local = (back - c) @ axes.T
        margin = 0.02
        inside = np.all(np.abs(local[:, 1:]) <= half[1:] + margin, axis=1)
        if fit.type == "prismatic":
            travel = max(abs(v) for v in fit.values) if len(fit.values) else 0.0
            depth = (back - c) @ fit.axis
            inside &= (depth <= half[0] + margin) & (depth >= -travel - margin)
        else:
            inside &= np.abs(local[:, 0]) <= half[0] + margin
        extra.append(back[inside])
    return np.concatenate([S] + extra) if extra else S
