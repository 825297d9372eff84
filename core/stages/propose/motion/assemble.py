"""Joint assembly: from a part's fitted joint to a proposal (refined joint, slide snapped to the
front, limits, extent, handle, bbox, confidence)."""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np

from ....model.joints import Joint, joint_transform, opening_approach
from ....geometry.parts import handle_point
from ....geometry.rigid import StepData, apply, invert, refine_joint, tukey_weights
from .cameras import InteractionView
from .config import MotionConfig
from .parts import box_of
from .track import Track, projective_score


def refine_on_steps(fit, St: np.ndarray, steps: list[StepData], thr: float, cfg: MotionConfig,
                    rounds: int):
    """``rounds`` of :func:`refine_joint` of ``fit`` with the part points ``St`` on the measured
    ``steps``, with the distances of views whose change threshold is ``thr`` (m)."""
    return refine_joint(fit, St, steps, rounds=rounds, min_distance=thr / 2,
                        max_distance=max(0.05, 4 * thr), point_weight=cfg.refine_point_weight)


def refine_fit(fit, St: np.ndarray, steps: list[StepData], views: list[InteractionView],
               moving: list[int], thr: float, cfg: MotionConfig):
    """Refine the joint on the measurements with the splat's own part points (unbiased by
    tracking; a turning face pins its hinge). Revolute joints start also from hinges on the part's
    box edges parallel to the axis (tracking of a door seen edge-on can misplace its hinge by
    more than the refinement recovers); the start whose refined joint best explains the depth
    maps (:func:`projective_score` over the steps) is refined to the end."""
    def refined(f, rounds: int):
        return refine_on_steps(f, St, steps, thr, cfg, rounds)

    def score(f) -> float:
        return motion_score(f, St, views, moving)

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


def motion_score(fit, St: np.ndarray, views: list[InteractionView], moving: list[int]) -> float:
    """How well the joint ``fit`` places the part points ``St`` on the depth maps of the steps
    ``moving``: the mean :func:`projective_score` (-1..1)."""
    return float(np.mean([projective_score(St, joint_transform(fit.type, fit.axis, fit.origin, v),
                                           views, t) for t, v in zip(moving, fit.values)]))


def choose_type(fit, both: tuple, St: np.ndarray, steps: list[StepData],
                views: list[InteractionView], moving: list[int], thr: float,
                cfg: MotionConfig) -> tuple[Any, Any, dict[str, float]]:
    """The joint of the part and the best joint of the other type, both refined on the
    measurements (:func:`refine_fit`), and the :func:`motion_score` of each type.

    ``both`` are the two models fitted to the tracked poses (``rigid.fit_both``), ``fit`` the
    motion rule's choice between them (``rigid.by_motion``: a turn the tracked poses show and
    a slide cannot explain). On far, noisy cameras the tracked poses drift by tens of degrees and
    tens of millimetres, so the rule calls nearly everything a slide (a microwave door tracked
    through 104 degrees: both models 45 mm RMS); where the other type places the part on the
    depth maps better by ``cfg.type_margin`` it is taken instead. The margin keeps drawers
    slides: a hinge far away mimics a slide and scores within a few thousandths of it."""
    scores, fits = {}, {}
    for cand in both:
        cand = refine_fit(cand, St, steps, views, moving, thr, cfg)
        fits[cand.type], scores[cand.type] = cand, motion_score(cand, St, views, moving)
    other = "prismatic" if fit.type == "revolute" else "revolute"
    if scores[other] > scores[fit.type] + cfg.type_margin:
        return fits[other], fits[fit.type], scores
    return fits[fit.type], fits[other], scores


def finite(x: float) -> float | None:
    """A JSON-safe figure (None when not finite), rounded."""
    x = float(x)
    return round(x, 4) if math.isfinite(x) else None


def view_meta(v: InteractionView) -> dict[str, Any]:
    """The view the joints' ``bbox`` refer to: the first interaction camera."""
    cam = v.camera
    return {"camera": v.name, "frame": v.ref_source, "K": cam.K.tolist(), "c2w": cam.c2w.tolist(),
            "width": cam.width, "height": cam.height}


def make_joint(k: int, fit, values: dict[int, float], moving: list[int], S: np.ndarray,
                track: Track, views: list[InteractionView], clouds) -> Joint:
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
    point = handle_point(S, fit, n)
    approach = opening_approach(fit.type, fit.axis, fit.origin, point,
                                max(values.values(), key=abs))
    if approach is None:         # on the hinge's line: against the front's normal
        approach = -n
    handle = {"point": [float(x) for x in point], "approach": [float(x) for x in approach]}
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


def snap_to_front(fit, S: np.ndarray, max_deg: float):
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
