"""Choosing, adding and dropping joints by evidence (the image loss), beyond the paper.

- Type: for each joint the alternative type is made from the fitted motion of its part
  (revolute -> prismatic: the principal direction of the part's mean displacements; prismatic ->
  revolute: every edge of the part's box as a hinge, each with the per-time angles that best
  reproduce the fitted part positions), the best few are scored by rendering, the winner is
  fitted, and the hypothesis with the lower image loss over the frames where the part moves is kept.
- Spurious parts: a part whose removal (its Gaussians to the base) does not raise the image loss
  over all frames is removed.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from .fit import evaluate, search_states
from .kinematics import PRISMATIC, REVOLUTE
from .model import ArticulatedSplat

#: Relative loss increase below which a part's removal is taken (float noise of the evaluation).
REMOVE_TOL = 1e-3


def state_candidates(model: ArticulatedSplat, k: int) -> np.ndarray:
    """Values searched for a joint without states: ±90° in 15° steps, or ±40 % of the object size."""
    if model.types[k] == REVOLUTE:
        return np.radians(np.linspace(-90, 90, 13))
    return np.linspace(-0.4, 0.4, 17) * model.size


def _snapshot(model: ArticulatedSplat) -> tuple:
    return (list(model.types), model.axes.detach().clone(), model.origins.detach().clone(),
            model.states.detach().clone())


def _restore(model: ArticulatedSplat, snap: tuple) -> None:
    model.types = list(snap[0])
    model.axes, model.origins, model.states = (t.clone() for t in snap[1:])


def part_points(model: ArticulatedSplat, k: int, limit: int = 400) -> np.ndarray:
    """Canonical means of part ``k``'s Gaussians (an even subsample of at most ``limit``)."""
    pts = model.splat.means.cpu().numpy()[model.labels() == k + 1].astype(float)
    return pts[:: max(1, len(pts) // limit)]


def posed_part(model: ArticulatedSplat, k: int, pts: np.ndarray) -> np.ndarray:
    """Part ``k``'s points moved by its current joint at every time: (T, M, 3)."""
    from ...model.joints import joint_transform
    axis = model.joint_axes()[k].detach().cpu().numpy()
    origin = model.joint_origins()[k].detach().cpu().numpy()
    out = []
    for t, v in model.joint_values(k).items():
        T = joint_transform(model.types[k], axis, origin, v)
        out.append(pts @ T[:3, :3].T + T[:3, 3])
    return np.stack(out)


def box_edges(pts: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """The 12 edges of the part's PCA box (2–98 % percentiles) as (direction, point) lines."""
    c = pts.mean(0)
    _, _, vt = np.linalg.svd(pts - c, full_matrices=False)
    local = (pts - c) @ vt.T
    lo, hi = np.percentile(local, 2, axis=0), np.percentile(local, 98, axis=0)
    lines = []
    for a in range(3):
        b, d = [i for i in range(3) if i != a]
        for sb in (lo[b], hi[b]):
            for sd in (lo[d], hi[d]):
                p = c + sb * vt[b] + sd * vt[d] + 0.5 * (lo[a] + hi[a]) * vt[a]
                lines.append((vt[a].copy(), p))
    return lines


def revolute_from_motion(pts: np.ndarray, posed: np.ndarray, axis: np.ndarray, point: np.ndarray
                         ) -> tuple[np.ndarray, float]:
    """Per-time angles about the line (axis, point) that best reproduce ``posed`` (T, M, 3), and
    the mean squared point residual (m^2)."""
    grid = np.radians(np.linspace(-120, 120, 241))
    x = pts - point
    par = (x @ axis)[:, None] * axis
    perp = x - par
    cross = np.cross(axis, perp)
    values, err = [], 0.0
    for Y in posed:
        # R(θ)x = par + cos θ perp + sin θ (a × perp): residual for every grid angle at once
        moved = (par[None] + np.cos(grid)[:, None, None] * perp[None]
                 + np.sin(grid)[:, None, None] * cross[None]) + point
        res = ((moved - Y[None]) ** 2).sum(-1).mean(-1)
        i = int(np.argmin(res))
        values.append(grid[i])
        err += float(res[i])
    return np.array(values), err / len(posed)


def alternatives(model: ArticulatedSplat, k: int) -> list[tuple[str, np.ndarray, np.ndarray,
                                                               np.ndarray, float]]:
    """Hypotheses of the other type for joint ``k``, made from its part's fitted motion:
    (type, axis, point, values per time, point residual), best first."""
    pts = part_points(model, k)
    if len(pts) < 10:
        return []
    posed = posed_part(model, k, pts)
    if model.types[k] == REVOLUTE:
        disp = (posed - pts[None]).mean(1)                        # (T,3) best translations
        _, _, vt = np.linalg.svd(disp, full_matrices=False)
        axis = vt[0]
        values = disp @ axis
        if values[np.argmax(np.abs(values))] < 0:
            axis, values = -axis, -values
        res = float((((pts[None] + values[:, None, None] * axis) - posed) ** 2).sum(-1).mean())
        return [(PRISMATIC, axis, pts.mean(0), values, res)]
    hyps = []
    for axis, point in box_edges(pts):
        values, res = revolute_from_motion(pts, posed, axis, point)
        if values[np.argmax(np.abs(values))] < 0:
            axis, values = -axis, -values
        hyps.append((REVOLUTE, axis, point, values, res))
    return sorted(hyps, key=lambda h: h[4])


def moving_frames(model: ArticulatedSplat, frames, k: int) -> list[int]:
    """Frames where joint ``k`` is away from 0 by more than 10 % of its largest value."""
    v = np.abs(model.states[k].detach().cpu().numpy() * model.moving.cpu().numpy())
    if v.max() <= 0:
        return []
    return [i for i, ti in enumerate(frames.time_index) if v[ti] > 0.1 * v.max()]


def select_types(run, share: float, fixed: list[bool], tries: int = 3) -> dict[str, dict[str, Any]]:
    """Keep, per joint, the type whose fit explains the frames where it moves better.

    ``fixed`` joints (trusted user joints, locked joints) keep their type. The ``tries`` best
    alternatives (by point residual) are scored by rendering; the best one is fitted with only
    this joint free and kept if its image loss is lower. Returns per joint the evidence:
    both losses, the kept type and the relative margin.
    """
    model, frames, cfg = run.model, run.frames, run.cfg
    evidence: dict[str, dict[str, Any]] = {}
    todo = [k for k in range(model.k) if not fixed[k]]
    steps = max(run.options.iterations // 3, 1)
    for k in todo:
        name = model.names[k]
        ids = moving_frames(model, frames, k)
        hyps = alternatives(model, k)
        if not ids or not hyps:
            run.done += share / len(todo)
            continue
        kept = _snapshot(model)
        here = float(evaluate(model, frames, cfg, 0, ids).mean())
        scored = []
        for kind, axis, point, values, _ in hyps[:tries]:
            model.set_type(k, kind, axis, point, values)
            scored.append((float(evaluate(model, frames, cfg, 0, ids).mean()), axis, point, values))
            _restore(model, kept)
        _, axis, point, values = min(scored, key=lambda s: s[0])
        kind = hyps[0][0]
        model.set_type(k, kind, axis, point, values)
        run.run_fit(steps, f"{name} as {kind}", share / len(todo),
                    free=[i == k for i in range(model.k)])
        there = float(evaluate(model, frames, cfg, 0, ids).mean())
        losses = {kept[0][k]: here, kind: there}
        if there >= here:
            _restore(model, kept)
        best = model.types[k]
        margin = (max(here, there) - min(here, there)) / max(min(here, there), 1e-12)
        evidence[name] = {f"loss_{t}": round(v, 6) for t, v in losses.items()}
        evidence[name].update(type=best, margin=round(margin, 6))
        run.progress.log(f"{name}: {best} (image loss {losses[REVOLUTE]:.4f} revolute, "
                         f"{losses[PRISMATIC]:.4f} prismatic)")
    return evidence


def remove_spurious(run, locked: list[bool]) -> list[str]:
    """Remove the joints whose part, left at rest (state 0 at every time, i.e. merged into the
    base), explains the frames no worse than moving (within ``REMOVE_TOL``); returns their names."""
    model, frames, cfg = run.model, run.frames, run.cfg
    removed = []
    k = 0
    while k < model.k:
        if locked[k]:
            k += 1
            continue
        here = float(evaluate(model, frames, cfg).mean())
        snap = _snapshot(model)
        with torch.no_grad():
            model.states = model.states.clone()
            model.states[k] = 0.0
        rest = float(evaluate(model, frames, cfg).mean())
        _restore(model, snap)
        if rest <= here * (1 + REMOVE_TOL):
            run.progress.log(f"{model.names[k]}: removed (at rest the loss is {rest:.4f}, "
                             f"moving {here:.4f})")
            removed.append(model.names[k])
            model.drop(k)
            run.trust = torch.cat([run.trust[:k], run.trust[k + 1:]])
            locked = locked[:k] + locked[k + 1:]
        else:
            k += 1
    return removed
