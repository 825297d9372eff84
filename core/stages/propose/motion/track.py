"""Tracking: a part's pose at every interaction step, scored against the depth maps.

Pose hypotheses (previous pose, constant velocity, earlier poses, turns about the part's box edges
and slides along its normal) are scored by projecting the part into the step's depth maps
(:func:`projective_score`), the best refined by robust point-to-plane ICP against the step's
measured points and then by a pattern search on the projective score (:func:`polish`). The part's
model grows with the measured points that moved in with it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from ....model.joints import rotation_about_axis
from ....geometry.rigid import apply, icp, invert, make_transform, rotation_log
from .cameras import InteractionView, lookup, pixels_of
from .config import MotionConfig
from .parts import box_of


def projective_score(points: np.ndarray, T: np.ndarray, views: list[InteractionView],
                     t: int) -> float:
    """Agreement of closed-state part ``points`` placed by ``T`` at step ``t`` with the depth maps,
    per point (-1..1).

    A point on a measured surface scores up to 1 (less as it nears the threshold), provided the
    surface there came in front of the closed state's (:meth:`InteractionView.changed_at`) or the
    point stayed near its closed place (a moved part cannot sit on geometry that was already
    there).
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
        inside, flat, z = pixels_of(v, Y)
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


def polish(T: np.ndarray, points: np.ndarray, views: list[InteractionView], t: int, step: float,
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


def visible_filter(views: list[InteractionView], t: int):
    def keep(points: np.ndarray) -> np.ndarray:
        ok = np.zeros(len(points), bool)
        for v in views:
            if t not in v.depth:
                continue
            inside, z, _, hi = lookup(v, t, points)
            occ = np.where(inside, v.occluder(t).reshape(-1)[pixels_of(v, points)[1]], np.inf)
            ok |= inside & (((hi <= 0) & (z < occ + v.threshold)) | (z - hi < v.threshold))
        return ok
    return keep


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


def track_part(points: np.ndarray, views: list[InteractionView], times: list[int], start: int,
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
                      keep=visible_filter(views, t))
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
