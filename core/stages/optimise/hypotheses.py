"""Choosing, adding and dropping joints by evidence (the image loss), beyond the paper.

- Type: for each joint, hypotheses of the other type are made from its part (box edges as
  hinges, box axes as slides, and the fitted motion transferred), scored by rendering, the best
  one fitted, and the type with the lower image loss over the frames where the part moves is kept.
- Spurious parts: a part whose removal (its Gaussians to the base) does not raise the image loss
  over all frames is removed.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from .fit import evaluate, part_level, search_states
from .kinematics import PRISMATIC, REVOLUTE
from .model import ArticulatedSplat
from .plausible import plausible

#: Relative loss increase below which a part's removal is taken (float noise of the evaluation).
REMOVE_TOL = 1e-3
#: Paired t statistic over the frames where a part moves above which its motion explains them
#: better than its absence (a part whose motion only fits noise wins on some frames, loses on
#: others).
SIGNIFICANT = 3.0


def clearly_better(without: np.ndarray, with_: np.ndarray, ids: list[int]) -> bool:
    """Whether per-frame losses ``with_`` (all frames) beat ``without``: over all frames by more
    than ``REMOVE_TOL`` (the resolution of the evaluation), or on the frames ``ids`` where a
    part moves, lower by ``REMOVE_TOL`` there and consistently (paired t over those frames above
    ``SIGNIFICANT``). A small motion (a door opened 10 degrees) changes few pixels, so its gain
    is also judged on its own frames, where it is not diluted by all the others."""
    if with_.mean() < without.mean() * (1 - REMOVE_TOL):
        return True
    if len(ids) < 2:
        return False
    a, b = without[ids], with_[ids]
    d = a - b
    se = d.std(ddof=1) / np.sqrt(len(d))
    return bool(b.mean() < a.mean() * (1 - REMOVE_TOL) and (se == 0 or
                                                           d.mean() / se > SIGNIFICANT))


def state_candidates(model: ArticulatedSplat, k: int) -> np.ndarray:
    """Values searched for a joint without states: ±120° in 15° steps, or ±40 % of the object
    size in 5 % steps."""
    if model.types[k] == REVOLUTE:
        return np.radians(np.linspace(-120, 120, 17))
    return np.linspace(-0.4, 0.4, 17) * model.size


def _snapshot(model: ArticulatedSplat) -> tuple:
    return (list(model.types), model.axes.detach().clone(), model.origins.detach().clone(),
            model.states.detach().clone())


def _restore(model: ArticulatedSplat, snap: tuple) -> None:
    model.types = list(snap[0])
    model.axes, model.origins, model.states = (t.clone() for t in snap[1:])


def part_points(model: ArticulatedSplat, k: int, limit: int = 400,
                members: np.ndarray | None = None) -> np.ndarray:
    """Canonical means of part ``k``'s Gaussians (or of ``members``, bool (N,)), an even
    subsample of at most ``limit``."""
    sel = model.labels() == k + 1 if members is None else members
    pts = model.splat.means.cpu().numpy()[sel].astype(float)
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


def part_normal(model: ArticulatedSplat, k: int) -> np.ndarray:
    """Mean surface normal of part ``k``: each Gaussian's shortest axis, signs aligned."""
    s = model.splat
    sel = torch.as_tensor(model.labels() == k + 1, device=s.means.device)
    q = s.quats[sel] / s.quats[sel].norm(dim=-1, keepdim=True)
    w, x, y, z = q.unbind(-1)
    R = torch.stack([torch.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
                     torch.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
                     torch.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1)],
                    -2)
    shortest = s.log_scales[sel].argmin(-1)
    n = R[torch.arange(len(q)), :, shortest].cpu().numpy().astype(float)
    # principal direction of the normals (sign-free), as the eigenvector of their scatter
    return np.linalg.eigh(n.T @ n)[1][:, -1]


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


def hypotheses_of(model: ArticulatedSplat, k: int, kind: str, members: np.ndarray | None = None
                  ) -> list[tuple[str, np.ndarray, np.ndarray, np.ndarray | None]]:
    """Joint ``k`` as a ``kind`` joint: (type, axis, point, values per time or None) each, made
    from its part's Gaussians or from ``members`` (bool (N,), those seen moving) where given.

    Prismatic: the principal direction of the part's fitted mean displacements (with its
    values), the part's mean surface normal (drawers slide along their front's normal), the
    part box's and the object box's axes. Revolute: every edge of the part's box as a hinge,
    with the per-time angles that best reproduce the fitted part positions.
    """
    pts = part_points(model, k, members=members)
    if len(pts) < 10:
        return []
    posed = posed_part(model, k, pts)
    if kind == PRISMATIC:
        disp = (posed - pts[None]).mean(1)                        # (T,3) best translations
        _, _, vt = np.linalg.svd(disp, full_matrices=False)
        axis = vt[0]
        values = disp @ axis
        if values[np.argmax(np.abs(values))] < 0:
            axis, values = -axis, -values
        directions = [axis, part_normal(model, k)]
        for p in (pts, model.splat.means.cpu().numpy()):   # the part's and the object's box axes
            directions += list(np.linalg.svd(p - p.mean(0), full_matrices=False)[2])
        return [(PRISMATIC, d, pts.mean(0), values if i == 0 else None)
                for i, d in enumerate(directions)]
    hyps = []
    for axis, point in box_edges(pts):
        values, _ = revolute_from_motion(pts, posed, axis, point)
        if values[np.argmax(np.abs(values))] < 0:
            axis, values = -axis, -values
        hyps.append((REVOLUTE, axis, point, values))
    return hyps


def score_level(frames) -> int:
    """Pyramid level of hypothesis scoring: half resolution (the coarsest can be too small to
    see a part's motion)."""
    return min(1, len(frames.levels) - 1)


@torch.no_grad()
def score_at(model: ArticulatedSplat, frames, cfg, k: int, ti: int, values: np.ndarray) -> \
        tuple[float, float]:
    """Lowest image loss (half resolution) at time index ``ti`` over joint ``k``'s candidate ``values``
    (rad / m) that keep its part out of the body (:func:`.plausible.allowed_values`), and the
    value reaching it (inf, 0 when none does)."""
    from .fit import frame_loss
    from .plausible import allowed_values
    level = score_level(frames)
    ids = frames.at_time(ti)
    unit = model.unit_of(model.types[k])
    best = (np.inf, 0.0)
    for v in np.asarray(values)[allowed_values(model, frames, k, values)]:
        model.states[k, ti] = float(v) / unit
        loss = sum(float(frame_loss(model, frames, level, i, cfg)) for i in ids) / len(ids)
        best = min(best, (loss, float(v)))
    return best


def moving_frames(model: ArticulatedSplat, frames, k: int) -> list[int]:
    """Frames where joint ``k`` is away from 0 by more than 10 % of its largest value."""
    v = np.abs(model.states[k].detach().cpu().numpy() * model.moving.cpu().numpy())
    if v.max() <= 0:
        return []
    return [i for i, ti in enumerate(frames.time_index) if v[ti] > 0.1 * v.max()]


@torch.no_grad()
def key_time(model: ArticulatedSplat, frames, cfg, k: int) -> int:
    """The time index where joint ``k`` at rest (others as fitted) explains the frames worst:
    where its part is furthest from closed, whatever the current hypothesis says."""
    from .fit import frame_loss
    level = score_level(frames)
    snap = _snapshot(model)
    model.states = model.states.clone()
    model.states[k] = 0.0
    per_time = np.zeros(len(frames.times))
    for i, ti in enumerate(frames.time_index):
        per_time[ti] += float(frame_loss(model, frames, level, i, cfg))
    _restore(model, snap)
    return int(np.argmax(per_time))


def select_types(run, share: float, fixed: list[bool], tries: int = 16) -> dict[str, dict[str, Any]]:
    """Keep, per joint, the type and line whose fit explains the frames where it moves best.

    ``fixed`` joints (trusted user joints, locked joints) keep their type and line. The joint's
    hypotheses of both types (:func:`hypotheses_of`) are scored by rendering at half resolution
    at the time the part moves most (its value searched). The best of the other type is fitted
    (states searched at every time, coarse-to-fine with only this joint free), and so is the
    best of the joint's own type when it scores better than the joint itself (a hinge proposed
    on the wrong edge); the fit with the lowest image loss over the frames where the part moves
    is kept, among those that keep the part out of the body (:func:`.plausible.plausible`)
    when any does. Returns per joint the evidence: each type's loss, the kept type, the relative
    margin between the types and whether a restart of its own type was kept.
    """
    model, frames, cfg = run.model, run.frames, run.cfg
    evidence: dict[str, dict[str, Any]] = {}
    todo = [k for k in range(model.k) if not fixed[k]]
    steps = max(run.options.iterations // 2, 1)
    for k in todo:
        name = model.names[k]
        ids = moving_frames(model, frames, k)
        own = model.types[k]
        other = PRISMATIC if own == REVOLUTE else REVOLUTE
        core = seen_moving(model, frames, cfg, k)
        hyps = {t: hypotheses_of(model, k, t, core)[:tries] for t in (own, other)}
        if not ids or not hyps[other]:
            run.done += share / len(todo)
            continue
        kept = _snapshot(model)
        here = float(evaluate(model, frames, cfg, 0, ids).mean())
        key = key_time(model, frames, cfg, k)
        unit = model.unit_of(own)
        current = score_at(model, frames, cfg, k, key,
                           np.array([float(model.states[k, key]) * unit]))[0]
        _restore(model, kept)
        best: dict[str, tuple] = {}
        for kind, options in hyps.items():
            for _, axis, point, values in options:
                model.set_type(k, kind, axis, point, np.zeros(len(frames.times)))
                grid = state_candidates(model, k)
                if values is not None:
                    grid = np.append(grid, values[key])
                loss = score_at(model, frames, cfg, k, key, grid)[0]
                if kind not in best or loss < best[kind][0]:
                    best[kind] = (loss, axis, point)
                _restore(model, kept)
                run.progress.check_cancel()
        fitted = [(here, kept, False, plausible(model, frames, k))]
        losses = {own: here}
        for kind in (other, own):
            if kind not in best or (kind == own and best[kind][0] >= current):
                continue
            _, axis, point = best[kind]
            model.set_type(k, kind, axis, point, np.zeros(len(frames.times)))
            search_states(model, frames, k, cfg, state_candidates(model, k))
            label = f"{name} as {kind}" if kind != own else f"{name} restarted"
            run.run_fit(steps, label, share / len(todo) / 2,
                        free=[i == k for i in range(model.k)], coarse=cfg.coarse,
                        coarse_level=part_level(model, frames, k))
            there = float(evaluate(model, frames, cfg, 0, ids).mean())
            fitted.append((there, _snapshot(model), kind == own, plausible(model, frames, k)))
            losses[kind] = min(losses.get(kind, np.inf), there)
            _restore(model, kept)
        # a fit that moves its part into the body is no candidate while another keeps it out
        fitted = [f for f in fitted if f[3]] or fitted
        _, snap, restarted, _ = min(fitted, key=lambda f: f[0])
        _restore(model, snap)
        kind = model.types[k]
        lo, hi = min(losses.values()), max(losses.values())
        margin = (hi - lo) / max(lo, 1e-12)
        evidence[name] = {f"loss_{t}": round(v, 6) for t, v in losses.items()}
        evidence[name].update(type=kind, margin=round(margin, 6), restarted=restarted)
        run.progress.log(f"{name}: {kind}{' (restarted from a box edge)' if restarted else ''}"
                         " (image loss " + ", ".join(f"{v:.4f} {t}" for t, v in losses.items())
                         + ")")
    return evidence


@torch.no_grad()
def seen_static(model: ArticulatedSplat, frames, cfg, k: int, pixels: float = 2.0) -> np.ndarray:
    """Gaussians of joint ``k``'s part that the frames show staying put: in front in the closed
    render, moved by the joint by ``pixels`` or more on the image at a time, yet their pixel is
    unchanged from the camera's closed state (:func:`.changes.frame_changes`) at two or more
    such times and never changed. Gaussians no camera sees give no evidence and are not
    listed. Bool (N,)."""
    means = model.splat.means
    part = torch.as_tensor(model.labels() == k + 1, device=means.device)
    still = torch.zeros(model.splat.n, dtype=torch.long, device=means.device)
    moved = torch.zeros(model.splat.n, dtype=torch.bool, device=means.device)
    for ti, v, _, change, (px, py), front, _ in closed_views(model, frames, cfg):
        (qx, qy), _, _ = _project(v, model.posed(ti)[0])
        shift = ((qx - px) ** 2 + (qy - py) ** 2).float().sqrt() >= pixels
        here = change[py, px]
        still += (part & front & shift & ~here).long()
        moved |= part & front & here
    return ((still >= 2) & ~moved).cpu().numpy()


def closed_views(model: ArticulatedSplat, frames, cfg):
    """Per frame that has a change map (:func:`.changes.frame_changes`): its time index, view,
    its camera's closed render, the change map, every Gaussian's pixel (column, row) and whether
    the Gaussian is in front in the closed render: widely (within the splat's own spread about
    its surfaces, :func:`layer_spread`, plus the surface's depth step to the next pixel,
    :func:`surface_slope`: any evidence that a part's Gaussian stays put) and narrowly (within
    the depth scale of the loss: the surface itself, whose change marks a missed part)."""
    from .changes import frame_changes
    changed = frame_changes(frames)
    means = model.splat.means
    tol = cfg.sigma_depth * 0.01 * model.size
    closed: dict[int, Any] = {}
    for i, ti in enumerate(frames.time_index):
        if i not in changed:
            continue
        v = frames.levels[0][i]
        cam = frames.camera[i]
        if cam not in closed:
            closed[cam] = model.render(v, frames.times.index(0), cfg.backend)
        r0 = closed[cam]
        (px, py), z, inside = _project(v, means)
        gap = z - r0.depth[py, px]
        band = max(tol, 3 * layer_spread(gap[inside & (gap < 0)])) + surface_slope(r0.depth)
        yield ti, v, r0, changed[i], (px, py), inside & (gap.abs() < band[py, px]), \
            inside & (gap.abs() < tol)


def _project(v, pts: torch.Tensor) -> tuple[tuple[torch.Tensor, torch.Tensor], torch.Tensor,
                                            torch.Tensor]:
    """Pixel (column, row) of world points in view ``v`` (clamped into the image), their depth,
    and whether they fall inside the image in front of the camera."""
    cam = pts @ v.w2c[:3, :3].T + v.w2c[:3, 3]
    z = cam[:, 2]
    uv = cam[:, :2] / z.clamp_min(1e-6)[:, None] * v.K[[0, 1], [0, 1]] + v.K[:2, 2]
    px, py = uv[:, 0].floor().long(), uv[:, 1].floor().long()
    inside = (z > 0) & (px >= 0) & (py >= 0) & (px < v.width) & (py < v.height)
    return (px.clamp(0, v.width - 1), py.clamp(0, v.height - 1)), z, inside


def seen_moving(model: ArticulatedSplat, frames, cfg, k: int, share: float = 0.1
                ) -> np.ndarray | None:
    """Gaussians of joint ``k``'s part where the frames show a change that the model with this
    joint at rest does not (:func:`unexplained`): the part's Gaussians seen moving, the ones to
    draw its hypotheses from (a part's box also holds what no camera sees). None when fewer
    than ``share`` of the part (no evidence)."""
    part = model.labels() == k + 1
    snap = _snapshot(model)
    with torch.no_grad():
        model.states = model.states.clone()
        model.states[k] = 0.0
    core = unexplained(model, frames, cfg, part).any(0) & part
    _restore(model, snap)
    return core if core.sum() >= max(10, share * part.sum()) else None


def trim_parts(run, locked: list[bool]) -> dict[str, int]:
    """Each unlocked joint's part (its proposal's box) gives to the base the Gaussians the frames
    show staying put where the joint would move them (:func:`seen_static`): a box drawn around
    a door also holds the cabinet's front beside it, and hypotheses made from such a part hinge
    on the wrong edges. Gaussians no camera sees stay. The soft skinning later gives back to a
    part what moves with it. Returns per joint the Gaussians moved to the base."""
    model, frames, cfg = run.model, run.frames, run.cfg
    moved: dict[str, int] = {}
    for k in range(model.k):
        if locked[k]:
            continue
        part = model.labels() == k + 1
        drop = seen_static(model, frames, cfg, k) & part
        if not drop.any() or drop.sum() > 0.9 * part.sum():   # nothing, or the joint is wrong
            continue
        model.reassign(drop, 0)
        moved[model.names[k]] = int(drop.sum())
        run.progress.log(f"{model.names[k]}: {int(drop.sum())} of {int(part.sum())} Gaussians of "
                         f"its box stay put in the frames; given to the base")
    return moved


def remove_spurious(run, locked: list[bool]) -> list[str]:
    """Remove the joints whose motion does not clearly explain the frames where the part moves
    better than the part left at rest (state 0 at every time, i.e. merged into the base):
    :func:`clearly_better`; returns their names."""
    model, frames, cfg = run.model, run.frames, run.cfg
    removed = []
    k = 0
    while k < model.k:
        if locked[k]:
            k += 1
            continue
        ids = moving_frames(model, frames, k)
        here = evaluate(model, frames, cfg)
        snap = _snapshot(model)
        with torch.no_grad():
            model.states = model.states.clone()
            model.states[k] = 0.0
        rest = evaluate(model, frames, cfg)
        _restore(model, snap)
        if not clearly_better(rest, here, ids):
            run.progress.log(f"{model.names[k]}: removed (at rest the loss is "
                             f"{rest[ids].mean() if ids else rest.mean():.4f} where it moves, "
                             f"moving {here[ids].mean() if ids else here.mean():.4f})")
            removed.append(model.names[k])
            model.drop(k)
            run.trust = torch.cat([run.trust[:k], run.trust[k + 1:]])
            locked = locked[:k] + locked[k + 1:]
        else:
            k += 1
    return removed


def keep_better_start(run, start_axes: np.ndarray, start_origins: np.ndarray,
                      start_types: list[str], names: list[str]) -> list[str]:
    """Per joint whose type did not change: if the start's axis and point, with the fitted states
    and parts, explain the frames where the joint moves no worse (within ``REMOVE_TOL``, the
    resolution of the evaluation) than the fitted ones, take them back (a precise proposal is
    not traded for a fit that wandered along a flat valley: the image loss of a joint 0.5° off
    differs by 1e-5–1e-3 relative on 160x120 frames).
    Returns the names of the joints that kept their start."""
    model, frames, cfg = run.model, run.frames, run.cfg
    kept = []
    for k in range(model.k):
        s = names.index(model.names[k]) if model.names[k] in names else None
        if s is None or model.types[k] != start_types[s] or bool(model.locked[k]):
            continue
        ids = moving_frames(model, frames, k)
        if not ids:
            continue
        fitted = _snapshot(model)
        here = float(evaluate(model, frames, cfg, 0, ids).mean())
        with torch.no_grad():
            model.axes = model.axes.clone()
            model.origins = model.origins.clone()
            a = torch.as_tensor(start_axes[s], dtype=torch.float32, device=model.axes.device)
            if float((a * model.joint_axes()[k]).sum()) < 0:   # the fitted states' sign
                a = -a
            model.axes[k] = a
            model.origins[k] = torch.as_tensor(start_origins[s], dtype=torch.float32)
        there = float(evaluate(model, frames, cfg, 0, ids).mean())
        if there < here * (1 + REMOVE_TOL):   # the frames cannot tell them apart: the start
            kept.append(model.names[k])
            run.progress.log(f"{model.names[k]}: the start explains the frames better "
                             f"({there:.5f} < {here:.5f}); kept")
        else:
            _restore(model, fitted)
    return kept


def surface_slope(depth: torch.Tensor) -> torch.Tensor:
    """Per pixel, the largest depth step to a 4-neighbour where both are rendered (0 = nothing):
    how deep a surface seen at a grazing angle reaches within one pixel."""
    d = torch.nn.functional.pad(depth[None, None], (1, 1, 1, 1), mode="replicate")[0, 0]
    c = d[1:-1, 1:-1]
    steps = [(n - c).abs() * ((n > 0) & (c > 0)) for n in (d[:-2, 1:-1], d[2:, 1:-1],
                                                              d[1:-1, :-2], d[1:-1, 2:])]
    return torch.stack(steps).amax(0)


def layer_spread(ahead: torch.Tensor) -> float:
    """Spread (one sigma, m) of a splat's Gaussians about the surface it renders, from the
    distances by which Gaussians lie in front of the rendered depth (``ahead``, negative; nothing
    but the front layer itself is in front of it); a splat made from noisy depth is centimetres
    thick. 0 without any."""
    return 1.4826 * float(ahead.abs().median()) if len(ahead) else 0.0


@torch.no_grad()
def unexplained(model: ArticulatedSplat, frames, cfg, candidates: np.ndarray | None = None
                ) -> np.ndarray:
    """Base Gaussians (or ``candidates``, bool (N,)) where the frames show a change the model
    does not, at two consecutive times: bool (T-1, N), row ``t`` for times ``t`` and ``t+1``.

    A change is a pixel whose measurement differs from its camera's closed state
    (:func:`.changes.frame_changes`); the model explains it where its own render at that time
    differs from its closed render there (alpha, depth or colour). A base Gaussian is hit when
    it is in front in the closed render at such a pixel (:func:`closed_views`): something that
    was there has moved.
    """
    means = model.splat.means
    base = torch.as_tensor(model.labels() == 0 if candidates is None else candidates,
                           device=means.device)
    tol = cfg.sigma_depth * 0.01 * model.size
    hits = torch.zeros(len(frames.times), model.splat.n, dtype=torch.bool, device=means.device)
    for ti, v, r0, change, (px, py), _, front in closed_views(model, frames, cfg):
        r = model.render(v, ti, cfg.backend)
        moved = ((r.alpha - r0.alpha).abs() > 0.5) | ((r.depth - r0.depth).abs() > tol) | \
            ((r.rgb - r0.rgb).abs().mean(-1) > 0.1)
        hits[ti] |= base & front & (change & ~moved)[py, px]
    return (hits[1:] & hits[:-1]).cpu().numpy()


def clusters(points: np.ndarray, min_size: int) -> list[np.ndarray]:
    """Connected groups of ``points`` (neighbours closer than 3 median neighbour distances),
    largest first, each of at least ``min_size`` points; index arrays."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree
    if len(points) < min_size:
        return []
    tree = cKDTree(points)
    d = tree.query(points, 2)[0][:, 1]
    pairs = tree.query_pairs(3 * float(np.median(d)), output_type="ndarray")
    n = len(points)
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    _, comp = connected_components(graph, directed=False)
    groups = [np.flatnonzero(comp == c) for c in np.unique(comp)]
    return sorted([g for g in groups if len(g) >= min_size], key=len, reverse=True)


def first_mover(points: np.ndarray, onset: np.ndarray, min_size: int, link: int = 2
                ) -> np.ndarray | None:
    """Of changed points (N,3) with the time step each started to change, the part that moves
    first in the largest group: the group's most common onset within ``link`` steps, its largest
    connected piece (parts side by side that move at different times are split; what a moving
    part hid or uncovered starts with it and stays). Index array, or None."""
    groups = clusters(points, min_size)
    if not groups:
        return None
    g = groups[0]
    mode = int(np.bincount(onset[g]).argmax())
    sub = g[np.abs(onset[g] - mode) <= link]
    pieces = clusters(points[sub], min_size)
    return sub[pieces[0]] if pieces else None


def add_missed(run, share: float, tries: int = 3) -> list[str]:
    """Missed parts, one at a time: Gaussians of the base where the frames show changes the model
    does not (:func:`unexplained`), grouped into connected clusters (at least 1 % of the
    Gaussians), of which the part that starts moving first (:func:`first_mover`) becomes a part
    hypothesis: hinges at its box edges and slides
    along its normal and box axes are scored by rendering at its key time, the best is fitted,
    and the part is kept only if it clearly lowers the image loss of the frames where it moves
    (:func:`clearly_better`). A kept part explains
    its changes (and those of what it hid), so the changes are found again before the next of
    at most ``tries`` parts. Returns the names of the added joints."""
    model, frames, cfg = run.model, run.frames, run.cfg
    means = model.splat.means.cpu().numpy().astype(float)
    added: list[str] = []
    steps = max(run.options.iterations // 2, 1)
    for attempt in range(tries):
        hits = unexplained(model, frames, cfg)
        flagged = np.flatnonzero(hits.any(0))
        g = first_mover(means[flagged], hits[:, flagged].argmax(0),
                        max(10, model.splat.n // 100))
        if g is None:
            break
        members = np.zeros(model.splat.n, bool)
        members[flagged[g]] = True
        before_frames = evaluate(model, frames, cfg)
        before = float(before_frames.mean())
        kept = _snapshot(model)
        name = f"part_{len(model.names) + 1}"
        while name in model.names:
            name += "_"
        k = model.add(name, REVOLUTE, np.array([0.0, 0.0, 1.0]), means[members].mean(0), members)
        run.trust = torch.cat([run.trust, torch.zeros(1, device=run.trust.device)])
        pts = part_points(model, k)
        hyps = [(REVOLUTE, a, p) for a, p in box_edges(pts)]
        hyps += [(PRISMATIC, d, pts.mean(0)) for d in
                 [part_normal(model, k)] + list(np.linalg.svd(pts - pts.mean(0))[2])]
        key = key_time(model, frames, cfg, k)
        scored = []
        for kind, axis, point in hyps:
            model.set_type(k, kind, axis, point, np.zeros(len(frames.times)))
            scored.append((score_at(model, frames, cfg, k, key, state_candidates(model, k))[0],
                           kind, axis, point))
            run.progress.check_cancel()
        # the best-scoring hypothesis is fitted; if it does not explain the frames better, the
        # best of the other type is (a small part's score at one time can mislead)
        order = sorted(scored, key=lambda s: s[0])
        first = order[0][1]
        second = [s for s in order if s[1] != first][:1]
        for _, kind, axis, point in order[:1] + second:
            model.set_type(k, kind, axis, point, np.zeros(len(frames.times)))
            search_states(model, frames, k, cfg, state_candidates(model, k))
            run.run_fit(steps, f"new part {name} as {kind}", share / tries / 2,
                        free=[i == k for i in range(model.k)], coarse=cfg.coarse,
                        coarse_level=part_level(model, frames, k))
            after_frames = evaluate(model, frames, cfg)
            after = float(after_frames.mean())
            # a part the optimisation invents has only the loss it lowers as evidence: over
            # all frames, not on the frames it picks itself (the local test is for proposals)
            gain = clearly_better(before_frames, after_frames, [])
            if gain:
                break
        run.progress.log(f"{name}: {len(g)} Gaussians where the frames change and the model "
                         f"does not; as a {kind} part the image loss is {after:.5f} "
                         f"(without {before:.5f})")
        if not gain:
            model.drop(k)
            run.trust = run.trust[:-1]
            _restore(model, kept)
            break
        into = merge_target(model, frames, cfg, k, after)
        if into is None:
            added.append(name)
            continue
        run.progress.log(f"{name}: moves with {model.names[into]}; merged into its part")
        fitted = _snapshot(model)
        model.reassign(model.labels() == k + 1, into + 1)
        model.drop(k)
        run.trust = run.trust[:-1]
        _restore(model, (fitted[0][:-1], fitted[1][:-1], fitted[2][:-1], fitted[3][:-1]))
    return added


@torch.no_grad()
def merge_target(model: ArticulatedSplat, frames, cfg, k: int, loss: float) -> int | None:
    """The joint of the same type whose motion explains joint ``k``'s part as well as ``k`` does
    (within ``REMOVE_TOL`` of ``loss``, the image loss over all frames): a new part that is the
    rest of an existing one (Gaussians its box missed) is merged into it. None if none."""
    best = None
    hard = model.hard.clone()
    members = torch.as_tensor(model.labels() == k + 1, device=hard.device)
    for j in range(model.k):
        if j == k or model.types[j] != model.types[k]:
            continue
        h = hard.clone()
        h[members] = j + 1
        model.hard = h
        states = model.states.clone()
        model.states = states.clone()
        model.states[k] = 0.0
        merged = float(evaluate(model, frames, cfg).mean())
        model.states, model.hard = states, hard
        if merged <= loss * (1 + REMOVE_TOL) and (best is None or merged < best[0]):
            best = (merged, j)
    return None if best is None else best[1]
