"""Choosing, adding and dropping joints by evidence (the image loss), beyond the paper.

- Type: for each joint, hypotheses of the other type are made from its part (box edges as
  hinges, box axes as slides, and the fitted motion transferred), scored by rendering, the best
  few probed by short fits, the best probe fitted, and the type with the lower image loss over
  the frames where the part moves is kept (a proposal's type unless the other one is clearly
  better).
- Spurious parts: a part whose motion does not clearly explain the frames better than its part
  at rest (merged into the base) or gone (transparent) is removed.
- A joint whose start explains its frames no worse than the fit keeps the start's axis and point.

Missed parts are added in :mod:`.missed`; what the frames show moving is found in :mod:`.seen`.
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np
import torch

from ...geometry.rectangle import smallest_rectangle
from ...geometry.rigid import JointFit, fit_both, kabsch
from .fit import part_level, score_level, search_states, skip_draws
from .kinematics import PRISMATIC, REVOLUTE
from .model import ArticulatedSplat, farther, restore, snapshot, unshaded, vanished
from .plausible import HIDDEN_SHARE, box_span, into_body
from .seen import seen_moving

#: Relative loss increase below which a part's removal is taken (float noise of the evaluation).
REMOVE_TOL = 1e-3
#: Paired t statistic over the frames where a part moves above which its motion explains them
#: better than its absence (a part whose motion only fits noise wins on some frames, loses on
#: others).
SIGNIFICANT = 3.0
#: Hypotheses of each type probed by a short fit before one is fitted in full (:func:`probe`).
PROBES = 3
#: A probe's steps: the fit's iterations over this.
PROBE_DIVISOR = 6
#: Hypotheses within this angle of each other (either sign) and, revolute, on lines within
#: ``SAME_LINE`` of the object's size are one start (:func:`distinct`): a fit's basin spans
#: 10-30 deg (the basin benchmark), so closer starts probe one basin twice.
PROBE_SPREAD_DEG = 20.0


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
    return bool(b.mean() < a.mean() * (1 - REMOVE_TOL) and paired_t(a - b) > SIGNIFICANT)


def paired_t(d: np.ndarray) -> float:
    """The paired t statistic of per-frame differences ``d`` (0 for fewer than 2; +-inf for a
    difference without spread, 0 without either)."""
    if len(d) < 2:
        return 0.0
    se = float(d.std(ddof=1)) / np.sqrt(len(d))
    return float(d.mean() / se) if se > 0 else float(np.sign(d.mean()) * np.inf)

def state_candidates(model: ArticulatedSplat, k: int) -> np.ndarray:
    """Values searched for a joint without states: ±120° in 15° steps, or ±40 % of the object
    size in 5 % steps."""
    if model.types[k] == REVOLUTE:
        return np.radians(np.linspace(-120, 120, 17))
    return np.linspace(-0.4, 0.4, 17) * model.size

def part_points(model: ArticulatedSplat, k: int, limit: int = 400,
                members: np.ndarray | None = None) -> np.ndarray:
    """Canonical means of part ``k``'s Gaussians (or of ``members``, bool (N,)), an even
    subsample of at most ``limit``."""
    sel = model.labels() == k + 1 if members is None else members
    pts = model.splat.means.cpu().numpy()[sel].astype(float)
    return pts[:: max(1, len(pts) // limit)]

def hidden_share(run, k: int) -> float:
    """Share of joint ``k``'s part that its current fit, at its widest state, moves behind
    surfaces the static views measured, when reversed it would hide less; 0 otherwise
    (:func:`.plausible.into_body` in ``run.space``)."""
    model = run.model
    axes, origins = model.joint_lines()
    return into_body(run.space, model.types[k], axes[k], origins[k],
                     np.array(list(model.joint_values(k).values())),
                     part_points(model, k, limit=model.splat.n))

def turn_outwards(run, k: int) -> bool:
    """Negate each state of joint ``k`` that moves its part into the body (more than
    ``HIDDEN_SHARE`` of it behind surfaces the static views measured) where the negated state
    does not: a part hidden inside the body and the same part opened into space differ by the
    state's sign, and where the frames show the body's inside a fit can land on either. True
    when a state was turned."""
    model, space = run.model, run.space
    if space is None:
        return False
    axes, origins = model.joint_lines()
    kind, pts = model.types[k], part_points(model, k, limit=300)
    share = lambda v: space.hidden_share(kind, axes[k], origins[k], v, pts)  # noqa: E731
    values = model.joint_values(k)
    turned = {t: -v if v and share(v) > HIDDEN_SHARE and share(-v) <= HIDDEN_SHARE else v
              for t, v in values.items()}
    if turned == values:
        return False
    model.set_type(k, kind, axes[k], origins[k], turned)
    return True

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

def box_edges(pts: np.ndarray, axes: np.ndarray | None = None
              ) -> list[tuple[np.ndarray, np.ndarray]]:
    """The 12 edges of the part's box (:func:`box_span`) as (direction, point) lines: along
    the part's principal axes, or the rows of ``axes`` (3,3)."""
    c = pts.mean(0)
    vt = np.linalg.svd(pts - c, full_matrices=False)[2] if axes is None else axes
    lo, hi = box_span((pts - c) @ vt.T)
    lines = []
    for a in range(3):
        b, d = [i for i in range(3) if i != a]
        for sb in (lo[b], hi[b]):
            for sd in (lo[d], hi[d]):
                p = c + sb * vt[b] + sd * vt[d] + 0.5 * (lo[a] + hi[a]) * vt[a]
                lines.append((vt[a].copy(), p))
    return lines

def hinge_lines(model: ArticulatedSplat, pts: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """Candidate hinges of a part: the edges of its box along its own principal axes, and
    along the object's (a round or square part, a washing machine's porthole door, has no
    principal axes of its own: its box turns at random in its plane, while hinges run along
    the body's edges), and the edges of the object's face the part lies in
    (:func:`face_edges`)."""
    means = model.splat.means.cpu().numpy().astype(float)
    body = np.linalg.svd(means - means.mean(0), full_matrices=False)[2]
    return box_edges(pts) + box_edges(pts, body) + face_edges(means, pts, 0.01 * model.size)


def face_edges(means: np.ndarray, pts: np.ndarray, tol: float
               ) -> list[tuple[np.ndarray, np.ndarray]]:
    """Hinges of a part that is a piece of a panel: the 4 edges of the face of the object that
    the part lies in (the object's Gaussians within the part's thickness plus ``tol`` of its
    mid-plane, the part's thinnest principal axis its normal), along the sides of the face's
    smallest 2-98 % rectangle in that plane (core.geometry.rectangle). The motion route often
    gives the part of a door that moved most (its free edge): its own box edges run through the
    door's middle, while its hinge lies on the edge of the face it belongs to. The object's
    principal axes are no frame for it: a realistic oven's lay 13-15 deg off its faces."""
    c = pts.mean(0)
    u = np.linalg.svd(pts - c, full_matrices=False)[2]
    lo, hi = box_span((pts - c) @ u.T)
    mid = 0.5 * (lo[2] + hi[2])
    rel = means - c
    face = rel[np.abs(rel @ u[2] - mid) <= 0.5 * (hi[2] - lo[2]) + tol]
    if len(face) < 10:
        return []
    a = smallest_rectangle(face @ u[:2].T, (2.0, 98.0), limit=3000)[0]
    sides = np.array([[np.cos(a), np.sin(a)], [-np.sin(a), np.cos(a)]]) @ u[:2]   # in-plane
    flo, fhi = box_span(face @ sides.T)
    lines = []
    for along, across in ((0, 1), (1, 0)):
        for s in (flo[across], fhi[across]):
            p = c + mid * u[2] + s * sides[across] + 0.5 * (flo[along] + fhi[along]) * sides[along]
            lines.append((sides[along].copy(), p))
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
    part box's and the object box's axes. Revolute: every edge of the part's box as a hinge
    (:func:`hinge_lines`), with the per-time angles that best reproduce the fitted part
    positions.
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
    for axis, point in hinge_lines(model, pts):
        values, _ = revolute_from_motion(pts, posed, axis, point)
        if values[np.argmax(np.abs(values))] < 0:
            axis, values = -axis, -values
        hyps.append((REVOLUTE, axis, point, values))
    return hyps

def alternative_of(joint, times: list[int]) -> list[tuple[str, np.ndarray, np.ndarray,
                                                           np.ndarray | None]]:
    """The proposal's best joint of the other type (``extra["alternative"]`` of the motion
    route, where both types are refined on the measured points: ``choose_type`` in
    core/stages/propose/motion/assemble.py) as a hypothesis, with its values at ``times``;
    none when the proposal has none."""
    alt = joint.extra.get("alternative")
    if not alt or alt.get("type") not in (PRISMATIC, REVOLUTE):
        return []
    states = alt.get("states") or {}
    values = np.array([float(states.get(str(t), 0.0)) for t in times]) if states else None
    axis = np.asarray(alt["axis"], float)
    return [(alt["type"], axis / np.linalg.norm(axis), np.asarray(alt["origin"], float), values)]

def tool_hypotheses(model: ArticulatedSplat, frames, k: int
                    ) -> list[tuple[str, np.ndarray, np.ndarray, None]]:
    """Joints from the robot's tool path (``frames.tool``, time -> world <- tool pose), when the
    capture has one, placed at part ``k``: a hand that holds a handle moves with it, so while it
    holds one part its positions lie on a circle about the hinge or a line along the slide
    (:func:`tool_segments`). Per segment a hinge (normal of the positions' plane, through the
    centre of their circle, at the point nearest the part) when it turns, and a slide (its
    principal direction). Only positions are used: a grasp holds a handle's position firmly but
    may let it turn (and an arm's IK trades orientation for reach). Which segment, if any, is
    part ``k``'s is left to rendering: they are scored like any other hypothesis, and those of
    other parts (or of the hand's approach) lose."""
    if not frames.tool:
        return []
    pts = part_points(model, k)
    times = sorted(frames.tool)
    path = np.array([frames.tool[t][:3, 3] for t in times])
    centre = pts.mean(0) if len(pts) else path.mean(0)
    hyps: list[tuple[str, np.ndarray, np.ndarray, None]] = []
    for seg in tool_segments(path, 0.01 * model.size, 0.02 * model.size, 0.05 * model.size):
        P = path[seg]
        _, _, vt = np.linalg.svd(P - P.mean(0), full_matrices=False)
        hinge = circle_centre(P, vt) if len(np.unique(P.round(6), axis=0)) >= 3 else None
        if hinge is not None and np.linalg.norm(hinge - P.mean(0)) < 10 * model.size:
            hyps.append((REVOLUTE, vt[2], hinge + ((centre - hinge) @ vt[2]) * vt[2], None))
        hyps.append((PRISMATIC, vt[0], centre, None))
    return hyps

def tool_segments(path: np.ndarray, tol: float, min_move: float, jump: float
                  ) -> list[np.ndarray]:
    """Runs of consecutive positions of ``path`` (T,3) that one circle or line explains within
    ``tol`` (RMS, m), each grown as far as it goes, and ended before a jump: a step longer
    than ``jump`` (m) and than ``JUMP`` times the run's longest step so far (the hand moving to
    another handle between two frames: a realistic cabinet's two drawers, 53 cm apart, lay on
    one wide circle within 1.6 cm); those spanning at least ``min_move``. Index arrays."""
    segments, a = [], 0
    steps = np.r_[0.0, np.linalg.norm(np.diff(path, axis=0), axis=1)]   # steps[i]: into i
    while a < len(path) - 1:
        b = a + 2
        while (b <= len(path) and path_residual(path[a:b]) <= tol
               and (b - 1 == a + 1 or steps[b - 1] <= max(jump, JUMP * steps[a + 1:b - 1].max()))):
            b += 1
        seg = np.arange(a, b - 1)
        if len(seg) >= 2 and np.linalg.norm(path[seg] - path[seg[0]], axis=1).max() >= min_move:
            segments.append(seg)
        a = max(b - 1, a + 1)   # the next run starts after this one (a jump between parts)
    return segments

#: a step of the hand this many times the longest of its run so far ends the run (see
#: :func:`tool_segments`)
JUMP = 4.0


def path_residual(P: np.ndarray) -> float:
    """RMS distance (m) of the positions ``P`` from their best line or circle (whichever is
    closer); 0 for two positions."""
    if len(P) < 3:
        return 0.0
    _, line, _, circle = line_and_circle(P)
    return min(line, circle)


def line_and_circle(P: np.ndarray) -> tuple[np.ndarray, float, np.ndarray | None, float]:
    """The positions' principal axes (rows), their RMS distance (m) from their best line, the
    centre of their circle in the plane of the first two axes (None when collinear) and their
    RMS distance from that circle (inf without one). Three positions or more."""
    c = P.mean(0)
    _, _, vt = np.linalg.svd(P - c, full_matrices=False)
    d = P - c
    line = float(np.sqrt(np.mean(np.sum((d - np.outer(d @ vt[0], vt[0])) ** 2, 1))))
    hinge = circle_centre(P, vt)
    if hinge is None:
        return vt, line, None, np.inf
    r = np.linalg.norm((P - hinge) @ vt[:2].T, axis=1)
    return vt, line, hinge, float(np.sqrt(np.mean((r - r.mean()) ** 2 + (d @ vt[2]) ** 2)))

def circle_centre(path: np.ndarray, basis: np.ndarray) -> np.ndarray | None:
    """Centre of the circle through ``path`` (M,3) in the plane of ``basis``'s first two rows
    (algebraic least squares, x² + y² + D x + E y + F = 0); None when the points are collinear."""
    xy = (path - path.mean(0)) @ basis[:2].T
    A = np.column_stack([xy, np.ones(len(xy))])
    sol, *_ = np.linalg.lstsq(A, -(xy ** 2).sum(1), rcond=None)
    if not np.all(np.isfinite(sol)) or np.linalg.cond(A) > 1e8:
        return None
    return path.mean(0) + (-sol[:2] / 2) @ basis[:2]

@torch.no_grad()
def score_at(model: ArticulatedSplat, frames, cfg, k: int, ti: int, values: np.ndarray) -> \
        tuple[float, float]:
    """Lowest image loss (at :func:`.fit.score_level`) at time index ``ti`` over joint ``k``'s
    candidate ``values`` (rad / m), and the value reaching it."""
    from .fit import best_value, frame_loss
    level = score_level(model, frames, k, cfg)
    ids = frames.at_time(ti)
    unit = model.unit_of(model.types[k])

    def loss_at(v: float) -> float:
        model.states[k, ti] = v / unit
        return sum(float(frame_loss(model, frames, level, i, cfg)) for i in ids) / len(ids)

    return best_value(loss_at, values)

def moving_frames(model: ArticulatedSplat, frames, k: int) -> list[int]:
    """Frames where joint ``k`` is away from 0 by more than 10 % of its largest value."""
    v = np.abs(model.states[k].detach().cpu().numpy() * model.moving.cpu().numpy())
    if v.max() <= 0:
        return []
    return [i for i, ti in enumerate(frames.time_index) if v[ti] > 0.1 * v.max()]

@torch.no_grad()
def key_time(run, k: int, changed: np.ndarray | None = None) -> int:
    """The time index where joint ``k`` at rest (others as fitted) explains the frames worst:
    where its part is furthest from closed, whatever the current hypothesis says. Never time
    0, where every joint is at rest: were it the worst explained (a realistic washing
    machine's), every hypothesis would score alike there and the first would win. ``changed``
    (per time index, e.g. the share of a new part's Gaussians the frames show changing): only
    times with at least half its largest value, where the part itself is seen moving; the
    worst-explained time can be another part's doing (a realistic cabinet's drawers were
    scored at a time only its door was open, and slid sideways)."""
    model, frames = run.model, run.frames
    snap = snapshot(model)
    model.states = model.states.clone()
    model.states[k] = 0.0
    per_time = np.zeros(len(frames.times))
    np.add.at(per_time, np.asarray(frames.time_index),
              run.evaluate(score_level(model, frames, k, run.cfg)))
    restore(model, snap)
    per_time[model.moving.cpu().numpy() == 0] = -np.inf
    if changed is not None and np.max(changed) > 0:
        per_time[changed < 0.5 * np.max(changed)] = -np.inf
    return int(np.argmax(per_time))

def select_types(run, share: float, fixed: list[bool]) -> dict[str, dict[str, Any]]:
    """Keep, per joint, the type and line whose fit explains the frames where it moves best.

    ``fixed`` joints (trusted user joints, locked joints) keep their type and line. The joint's
    hypotheses of both types (:func:`tool_hypotheses` when a robot held the parts, the
    proposal's joint of the other type, :func:`alternative_of`, :func:`hypotheses_of`) are
    scored by rendering at half resolution at the time the part moves most (its value
    searched). The best few of each type are probed by short fits (:func:`probe`), and the
    best probe of each type is fitted (coarse-to-fine with only this joint free): of the other
    type, and of the joint's own type as a restart (a
    hinge proposed on the wrong edge, or one the main fit could not carry far enough: a PartNet
    oven's hinge proposed 0.9 deg but 9 cm off stayed in a basin that a slide beat, 0.5488
    against 0.5393, while the restart from its box edge reached 0.5387 and 1.5 deg / 1.0 cm).
    The fit with the lowest image loss over the frames where the part moves is kept (a hinge
    off its part, :func:`.missed.hinge_off_part`, is not refused here: a proposal's part is
    often a piece, and a realistic oven door's true hinge passed 0.23 of the piece's size from
    it), and of none that opens its part into the body (:func:`chosen`); the other type only
    when it explains those frames clearly better (:func:`clearly_better`): the joint's type (a
    proposal's, or the one an invented part was found as) is a prior, and a type decided by
    0.1 % of the loss is decided by noise (a realistic oven's part flipped on 0.09 % with a
    change of the colour code; a PartNet washing machine's door, found as a hinge, became a
    slide on 0.05 %, 46 deg off). Returns per joint the evidence: each type's loss, the kept
    type, the relative margin between the types, whether a restart of its own type was kept,
    and the types whose every fit opened the part into the body (:func:`into_space`; each
    type's loss is over the fits that did not, where it has any). A fit that opens its part into
    the body is also fitted again from its states turned outwards (:func:`turn_outwards`): where
    the frames show the body's inside, the part hidden in it costs little there and a fit can
    land on it (a test cabinet's door, fitted on the right hinge line with its last states
    swung inwards, lost to a slide into the body and was dropped; turned, 2.5 deg / 0.5 cm).
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
        given = tool_hypotheses(model, frames, k) + run.alternatives.get(name, [])
        hyps = {t: [h for h in given if h[0] == t] + hypotheses_of(model, k, t, core)
                for t in (own, other)}
        if not ids or not hyps[other]:
            run.done += share / len(todo)
            continue
        kept = snapshot(model)
        here = run.evaluate(0, ids)
        key = key_time(run, k)
        flat = [h for options in hyps.values() for h in options]
        scored: dict[str, list[tuple]] = {}
        for (kind, axis, point, _), loss in zip(flat, score_all(run, k, key, flat)):
            scored.setdefault(kind, []).append((loss, axis, point))
        # (per-frame loss, state, type, restart, opens into the body)
        fitted = [(here, kept, own, False, hidden_share(run, k) > HIDDEN_SHARE)]
        branches = [(k, kind, own, scored[kind], ids, share / len(todo) / 4, steps)
                    for kind in (other, own) if kind in scored]
        fitted += fit_types(run, branches)
        turned = []
        for f in [f for f in fitted if f[4]]:
            restore(model, f[1])
            if turn_outwards(run, k):
                turned.append((k, snapshot(model), f[2], f[3], ids, steps))
            restore(model, kept)
        for pair in (turned[i:i + 2] for i in range(0, len(turned), 2)):
            fitted += in_turn(run, refit, pair, steps)
        fitted = on_path(model, k, fitted, kept)
        allowed = into_space(fitted)
        losses = {t: min(float(f[0].mean()) for f in allowed if f[2] == t)
                  for t in dict.fromkeys(f[2] for f in allowed)}
        inward = [t for t in dict.fromkeys(f[2] for f in fitted) if t not in losses]
        losses.update({t: min(float(f[0].mean()) for f in fitted if f[2] == t) for t in inward})
        _, snap, _, restarted, _ = chosen(fitted, own, np.array([frames.camera[i] for i in ids]))
        restore(model, snap)
        kind = model.types[k]
        lo, hi = min(losses.values()), max(losses.values())
        margin = (hi - lo) / max(lo, 1e-12)
        evidence[name] = {f"loss_{t}": round(v, 6) for t, v in losses.items()}
        evidence[name].update(type=kind, margin=round(margin, 6), restarted=restarted,
                              into_body=sorted(inward))
        run.progress.log(f"{name}: {kind}{' (restarted from a box edge)' if restarted else ''}"
                         " (image loss " + ", ".join(f"{v:.4f} {t}" for t, v in losses.items())
                         + ")")
    return evidence

def on_path(model, k: int, fitted: list[tuple], kept: tuple) -> list[tuple]:
    """Of joint ``k``'s ``fitted`` hypotheses (tuples whose second item is a :func:`snapshot`),
    those that carry the robot's tool positions the joint held nearly as well as the best of
    them (:meth:`.model.ArticulatedSplat.leaves_path`); all when it held none. Leaves the
    model at ``kept``."""
    paths = []
    for f in fitted:
        restore(model, f[1])
        paths.append(model.held_residual(k))
    restore(model, kept)
    if paths[0] is None:
        return fitted
    return [f for f, p in zip(fitted, paths) if not farther(p, min(paths), model.size)]


def score_hypotheses(run, k: int, key: int, hyps: list[tuple]) -> list[float]:
    """Per hypothesis ``(type, axis, point, values or None)`` of joint ``k``: its lowest image
    loss at time index ``key`` over the state candidates (and its own value there), by
    :func:`score_at`; leaves the model as it was."""
    model = run.model
    kept = snapshot(model)
    losses = []
    for kind, axis, point, values in hyps:
        model.set_type(k, kind, axis, point, np.zeros(len(run.frames.times)))
        grid = state_candidates(model, k)
        if values is not None:
            grid = np.append(grid, values[key])
        losses.append(score_at(model, run.frames, run.cfg, k, key, grid)[0])
        restore(model, kept)
        run.progress.check_cancel()
    return losses

def score_all(run, k: int, key: int, hyps: list[tuple]) -> list[float]:
    """:func:`score_hypotheses` of ``hyps``: the first half in the helper process, where there
    is one (:mod:`.parallel`), the rest here at once (the same losses as one process)."""
    from . import parallel
    helper = parallel.helper(run) if len(hyps) > 1 else None
    if helper is None:
        return score_hypotheses(run, k, key, hyps)
    half = len(hyps) // 2
    a, b = helper.call(run, score_hypotheses, (k, key, hyps[:half]),
                       lambda: score_hypotheses(run, k, key, hyps[half:]))
    return a + b

def fit_type(run, k: int, kind: str, own: str, scored: list[tuple], ids: list[int],
             share: float, steps: int) -> tuple:
    """Joint ``k`` fitted as ``kind`` from the best of its ``scored`` hypotheses
    (:func:`probe`, then ``steps`` of a coarse-to-fine fit with only this joint free): (its
    losses over the frames ``ids``, its state, ``kind``, whether it restarts the joint's own
    type ``own``, whether it opens the part into the body). Reports progress for twice
    ``share``; leaves the model as it was."""
    model, frames, cfg = run.model, run.frames, run.cfg
    kept = snapshot(model)
    name = model.names[k]
    label = f"{name} as {kind}" if kind != own else f"{name} restarted"
    start = probe(run, k, kind, scored, ids, label, share)
    restore(model, start)
    run.run_fit(steps, label, share, free=[i == k for i in range(model.k)], coarse=cfg.coarse,
                coarse_level=part_level(model, frames, k))
    fitted = (run.evaluate(0, ids), snapshot(model), kind, kind == own,
              hidden_share(run, k) > HIDDEN_SHARE)
    restore(model, kept)
    return fitted

def refit(run, k: int, start: tuple, kind: str, restarted: bool, ids: list[int],
          steps: int) -> tuple:
    """Joint ``k`` fitted ``steps`` from ``start`` (:func:`snapshot`; a fit into the body
    turned outwards) as :func:`fit_type` fits: the same result tuple; leaves the model as it
    was."""
    model, frames, cfg = run.model, run.frames, run.cfg
    kept = snapshot(model)
    restore(model, start)
    run.run_fit(steps, f"{model.names[k]} turned outwards", 0.0,
                free=[i == k for i in range(model.k)], coarse=cfg.coarse,
                coarse_level=part_level(model, frames, k))
    fitted = (run.evaluate(0, ids), snapshot(model), kind, restarted,
              hidden_share(run, k) > HIDDEN_SHARE)
    restore(model, kept)
    return fitted

def refits_alike(run, k: int, starts: list[tuple[np.ndarray, np.ndarray]], steps: int,
                 label: str, subset: list[int] | None = None, search: bool = False,
                 **fit: Any) -> list[tuple[np.ndarray, tuple, float | None]]:
    """Joint ``k`` refitted from each start ``(axis, point)`` alike: from the model as it is
    (its type, states and the part's brightness kept), the same ``steps`` on the same draws of
    the run's random generator (``fit``: :func:`.fit.fit`'s options), its states first searched
    again when ``search``. Returns per start (per-frame image losses of the frames ``subset``,
    all when None; its :func:`snapshot`; :meth:`held_residual`). Leaves the model at its last
    refit and the generator where that fit left it."""
    model = run.model
    fitted = snapshot(model)
    draws = run.rng.bit_generator.state
    out = []
    for axis, point in starts:
        restore(model, fitted)
        run.rng.bit_generator.state = draws
        model.set_type(k, model.types[k], axis, point, model.joint_values(k), shading=True)
        if search:
            search_states(model, run.frames, k, run.cfg, state_candidates(model, k))
        run.run_fit(steps, label, 0.0, free=[i == k for i in range(model.k)], **fit)
        out.append((run.evaluate(0, subset), snapshot(model), model.held_residual(k)))
    return out

def fit_draws(run, kind: str, scored: list[tuple], steps: int) -> int:
    """How many times :func:`fit_type` draws from the run's random generator: a draw per fit
    step, of the probes' short fits (when more than one is probed) and of the full fit."""
    top = probed(sorted(scored, key=lambda h: h[0]), kind, run.model.size)
    probe_steps = max(run.options.iterations // PROBE_DIVISOR, 1)
    return (len(top) * probe_steps if len(top) > 1 else 0) + steps

def fit_types(run, branches: list[tuple]) -> list[tuple]:
    """:func:`fit_type` of each of ``branches`` (its arguments after ``run``), in order
    (:func:`in_turn`)."""
    if len(branches) != 2:
        return [fit_type(run, *b) for b in branches]
    first = branches[0]
    return in_turn(run, fit_type, branches, fit_draws(run, first[1], first[3], first[6]),
                   2 * first[5])

def in_turn(run, fn: Callable, calls: list[tuple], draws: int, share: float = 0.0
            ) -> list:
    """``fn(run, *args)`` for each of ``calls`` (one or two) in order, each leaving the model
    as it was: with two and a helper process (:mod:`.parallel`), the first there and the second
    here at once, with the same results and random draws as one after the other (``draws``:
    the first call's, ``share``: its progress)."""
    from . import parallel
    helper = parallel.helper(run) if len(calls) == 2 else None
    if helper is None:
        return [fn(run, *args) for args in calls]
    first, second = calls

    def here():     # runs once the helper has the generator's state
        skip_draws(run.rng, run.frames, draws)
        run.done += share
        return fn(run, *second)

    return list(helper.call(run, fn, first, here))

def probe(run, k: int, kind: str, scored: list[tuple], ids: list[int], label: str,
          share: float) -> tuple:
    """The start of joint ``k``'s fit as ``kind``: of its ``PROBES`` best-scored hypotheses
    ``(loss, axis, point)``, each with its states searched and a short fit at the part's coarse
    level (only this joint free), the one then explaining the moving frames ``ids`` best (model
    state, :func:`snapshot`; the model is left as it was). One render at one time ranks
    hypotheses by margins of 0.2 %: on a tight oven the hinge 58 deg off scored 0.6710 and the
    true one 0.6725, and the fit from the first never reached the second's basin (:func:`probed`)."""
    model, frames, cfg = run.model, run.frames, run.cfg
    kept = snapshot(model)
    level = part_level(model, frames, k)
    steps = max(run.options.iterations // PROBE_DIVISOR, 1)
    best: tuple[float, tuple] | None = None     # (loss, state)
    top = probed(sorted(scored, key=lambda h: h[0]), kind, model.size)
    for _, axis, point in top:
        model.set_type(k, kind, axis, point, np.zeros(len(frames.times)))
        search_states(model, frames, k, cfg, state_candidates(model, k))
        if len(top) > 1:
            run.run_fit(steps, f"{label} (probe)", share / len(top),
                        free=[i == k for i in range(model.k)], coarse=1.0, coarse_level=level)
        loss = float(run.evaluate(score_level(model, frames, k, run.cfg), ids).mean())
        key = (hidden_share(run, k) > HIDDEN_SHARE, loss)
        if best is None or key < best[0]:
            best = (key, snapshot(model))
        restore(model, kept)
    if len(top) <= 1:
        run.done += share
    return best[1]

def probed(ranked: list[tuple], kind: str, size: float) -> list[tuple]:
    """The hypotheses ``(loss, axis, point)``, in rank order, that are probed: the ``PROBES``
    best, and when they are all one start (:func:`distinct`) also the best other one. A tight
    cabinet's drawer, started as a hinge, had its three best-scored slides all within 13 deg
    of vertical, and the probes never tried the pull direction (fitted 89 deg off). Probing
    the best three distinct starts instead fixed it but lost ovens in the benchmarks (a PartNet
    oven 2.0 -> 90 deg, a realistic one 2.8 -> 9.1 deg)."""
    top = ranked[:PROBES]
    if len(distinct(top, kind, size)) > 1:
        return top
    # the three are one start: distinct's second is the best hypothesis outside it
    return top + distinct(ranked, kind, size)[1:2]

def distinct(ranked: list[tuple], kind: str, size: float) -> list[tuple]:
    """Of hypotheses ``(loss, axis, point)`` in rank order, those not within
    ``PROBE_SPREAD_DEG`` (and, revolute, ``SAME_LINE`` · ``size``) of a better-ranked one: the
    states are searched over both signs, so a direction and its opposite are one start."""
    kept: list[tuple] = []
    cos = np.cos(np.radians(PROBE_SPREAD_DEG))
    for h in ranked:
        a = h[1] / np.linalg.norm(h[1])
        if not any(abs(float(a @ (g[1] / np.linalg.norm(g[1])))) > cos and
                   (kind != REVOLUTE or off_line(h[2] - g[2], a) <= SAME_LINE * size)
                   for g in kept):
            kept.append(h)
    return kept

def off_line(d: np.ndarray, axis: np.ndarray) -> float:
    """Length of ``d``'s component across the unit ``axis``."""
    return float(np.linalg.norm(d - (d @ axis) * axis))

def into_space(fitted: list[tuple]) -> list[tuple]:
    """Of fits ``(per-frame losses, state, type, restarted, into the body)``, those that do not
    open the part into the body; all of them when every one does."""
    return [f for f in fitted if not f[4]] or fitted

def chosen(fitted: list[tuple], own: str, cameras: np.ndarray | None = None) -> tuple:
    """Of fits ``(per-frame losses, state, type, restarted, into the body)``, the one with the
    lowest mean loss of type ``own`` unless one of the other type is clearly better
    (:func:`clearly_better`) and lower in the frames of every camera (``cameras``: per frame
    of the losses, its camera). Fits that open the part into the body are left out unless all
    do: a part opens into space, and the static views measured where the body is (a realistic
    cabinet's invented door: its restart, the lower image loss, swung it inwards, and the part
    was then dropped as going into the body). The cameras are independent views of one
    motion: a type that fits one of them better and the other worse explains a view, not the
    motion (a PartNet drawer, 21 Gaussians seen from 1.2-3 m, went from a slide 8 deg off to a
    hinge turning it 59 deg on 0.12 % of the loss, won in one camera and lost in the other)."""
    fitted = into_space(fitted)
    best = min(fitted, key=lambda f: f[0].mean())
    mine = min((f for f in fitted if f[2] == own), key=lambda f: f[0].mean(), default=best)
    if best[2] != own and not (clearly_better(mine[0], best[0], [])
                               and every_camera_lower(mine[0], best[0], cameras)):
        return mine
    return best


def every_camera_lower(without: np.ndarray, with_: np.ndarray,
                       cameras: np.ndarray | None) -> bool:
    """Whether per-frame losses ``with_`` are lower than ``without`` on average over the frames
    of each camera (``cameras``: per frame, its camera; None: one camera)."""
    if cameras is None:
        return bool(with_.mean() < without.mean())
    return all(with_[cameras == c].mean() < without[cameras == c].mean()
               for c in np.unique(cameras))


def remove_spurious(run, locked: list[bool], join: bool = False) -> list[str]:
    """Remove the joints whose motion does not clearly explain the frames where the part moves
    (:func:`clearly_better`) better than the part left at rest (state 0 at every time, i.e.
    merged into the base) and better than the part gone (its Gaussians transparent: a motion
    that only takes wrong Gaussians out of the way, such as a PartNet drawer unit's slides of
    40 cm for a drawer opened 10, is no evidence of a joint); returns their names.

    ``join``: also better than the part moving with each other joint (:func:`alternatives`),
    the final test: a piece of a door that its own joint explains no better than the door's
    joint is the door's. The weakest joint (smallest mean gain over its worst alternative) goes
    first and the others are tested again without it; a removed joint's Gaussians go to the
    outcome that explains the frames best: the base, or with ``join`` another joint's part,
    whose joint is then refitted with them (a quarter of the iterations, only it free, as
    :func:`merge_duplicates` does). The model must be hardened.

    The last joint is not removed: an interaction capture shows something moving, and where
    the frames tell it only weakly (a door opened 10 deg in centimetres of depth noise) the
    joint that explains them best is a better start for the user than none (the PartNet drawer
    unit 20279's drawer, 10 cm out, lost every proposal). It is kept with its name in
    ``run.weak`` (reported as weak evidence), which holds the joints kept so by this call only.

    A joint whose part the robot's tool held (:attr:`.model.ArticulatedSplat.held`) is not
    removed at rest or gone: the robot's record shows its part moving. With ``join`` it may
    join another joint, which, of its type, then holds its runs of the tool path (a realistic
    robot microwave's door: the piece the hand held, on the path's hinge 0.2 cm from the true
    one, was removed as gone beside the door's larger piece, whose line stayed 4 cm off)."""
    model, frames = run.model, run.frames
    removed = []
    run.weak = set()
    while True:
        weakest = None      # (gain, k, what failed, its loss, the loss moving, outcome)
        with unshaded(model):
            here = run.evaluate()       # the model as it is, the same for every joint
        for k in range(model.k):
            if locked[k]:
                continue
            ids = moving_frames(model, frames, k)
            alts = alternatives(run, k, join)
            if model.held.get(model.names[k]):     # the robot's record shows it moving
                alts = [a for a in alts if a[2]]
                if not alts:
                    continue
            sel = ids or list(range(len(here)))
            failed = [a for a in alts if not clearly_better(a[1], here, ids)]
            if not failed:
                continue
            gain = min(float((a[1] - here)[sel].mean()) for a in alts)
            outcome = min((a for a in alts if a[2] is not None), key=lambda a: a[1].mean())
            if weakest is None or gain < weakest[0]:
                weakest = (gain, k, failed[0][0], float(failed[0][1][sel].mean()),
                           float(here[sel].mean()), outcome)
        if weakest is None:
            return removed
        _, k, what, loss, moving, (_, _, label) = weakest
        name = model.names[k]
        if model.k == 1:
            run.weak.add(name)
            run.progress.log(f"{name}: kept, the only joint, though the frames show its motion "
                             f"only weakly ({what} the loss is {loss:.4f} where it moves, "
                             f"moving {moving:.4f})")
            return removed
        goes = "" if label == 0 else f"; its part joins {model.names[label - 1]}'s"
        run.progress.log(f"{name}: removed ({what} the loss is {loss:.4f} where it moves, "
                         f"moving {moving:.4f}){goes}")
        removed.append(name)
        if label:
            model.reassign(model.labels() == k + 1, label)
            model.pass_runs(k, label - 1)
        run.drop_joint(k)
        locked = locked[:k] + locked[k + 1:]
        if label:       # the joint refitted with its new Gaussians, as a merge does
            j = label - 1 - int(label - 1 > k)
            run.run_fit(max(run.options.iterations // 4, 1), f"{name} with {model.names[j]}",
                        0.0, free=[i == j for i in range(model.k)], lr_scale=0.3)


def alternatives(run, k: int, join: bool) -> list[tuple]:
    """What else could explain joint ``k``'s part: ``(what, per-frame image losses (unshaded),
    label)`` with ``label`` the part its Gaussians would join as that outcome (0 = the base;
    None: no outcome, only evidence). At rest (state 0 at every time), gone
    (:func:`.model.vanished`) and, with ``join``, moving with each other joint."""
    model = run.model
    with unshaded(model):
        snap = snapshot(model)
        with torch.no_grad():
            model.states = model.states.clone()
            model.states[k] = 0.0
        rest = run.evaluate()
        restore(model, snap)
        with vanished(model, k):
            gone = run.evaluate()
        alts = [("at rest", rest, 0), ("gone", gone, None)]
        if join:
            alts += [(f"moving with {model.names[j]}", moved_with(run, k, j), j + 1)
                     for j in range(model.k) if j != k]
    return alts


@torch.no_grad()
def moved_with(run, k: int, j: int) -> np.ndarray:
    """Per-frame image losses of the model with joint ``k``'s Gaussians moved by joint ``j``
    instead (the hard assignment changed for the evaluation only)."""
    model = run.model
    hard = model.hard
    h = hard.clone()
    h[torch.as_tensor(model.labels() == k + 1, device=hard.device)] = j + 1
    model.hard = h
    try:
        return run.evaluate()
    finally:
        model.hard = hard


#: Joints fitted this close are one joint (axes within the angle, lines within the share of
#: the object's size, states within the share of their range): :func:`merge_duplicates`.
SAME_AXIS_DEG = 5.0
SAME_LINE = 0.05
SAME_STATES = 0.1


def same_joint(model: ArticulatedSplat, i: int, j: int) -> bool:
    """Whether joints ``i`` and ``j`` move their parts alike: same type, axes within
    ``SAME_AXIS_DEG`` (either sign, the states' sign following), hinge lines within
    ``SAME_LINE`` of the object's size, states at every time within ``SAME_STATES`` of the
    larger range."""
    if model.types[i] != model.types[j]:
        return False
    a, o = model.joint_lines()
    cos = float(a[i] @ a[j])
    if np.degrees(np.arccos(min(abs(cos), 1.0))) > SAME_AXIS_DEG:
        return False
    if model.types[i] == REVOLUTE:
        if off_line(o[j] - o[i], a[i]) > SAME_LINE * model.size:
            return False
    vi = np.array(list(model.joint_values(i).values()))
    vj = np.sign(cos) * np.array(list(model.joint_values(j).values()))
    span = max(np.abs(vi).max(), np.abs(vj).max())
    return bool(span > 0 and np.abs(vi - vj).max() <= SAME_STATES * span)


@torch.no_grad()
def one_explains_both(run, fixed: list[bool]) -> list[tuple[int, int]]:
    """Pairs ``(i, j)`` of joints that move in some of the same frames and where joint ``i``,
    moving part ``j`` too, explains the frames where either moves clearly better
    (:func:`clearly_better`) than the two joints apart (part ``j``'s Gaussians only reassigned,
    nothing refitted), and clearly better than part ``j`` at rest (a proposal on a piece of a
    test cabinet's body that never moves, fitted with a hinge, was explained better by the
    drawer's slide, and better still by no motion); the best first. Two joints
    fitted apart always explain their pieces a little better than one, so this holds only where
    a piece's own fit is wrong: the fits of a realistic washing machine's round door,
    proposed as two halves, ended 10 and 50 deg off, the worse moving its half 17 cm (rms) from
    where the true hinge does; :func:`same_joint` could not see them as one."""
    model, frames = run.model, run.frames
    moving = [set(moving_frames(model, frames, k)) for k in range(model.k)]
    logits, hard = model.logits, model.hard
    found = []
    labels = model.labels()
    apart: dict[int, float] = {}                # per frame, the model as it is
    rest_of: dict[int, dict[int, float]] = {}   # per frame, part j at rest (the same for every i)

    def losses(todo: list[int]) -> np.ndarray:
        return run.evaluate(0, todo)

    for i in range(model.k):
        for j in range(model.k):
            if i == j or fixed[i] or fixed[j] or not moving[i] & moving[j]:
                continue
            ids = sorted(moving[i] | moving[j])
            part = labels == j + 1
            here = memo_losses(apart, ids, losses)
            model.reassign(part, 0)
            rest = memo_losses(rest_of.setdefault(j, {}), ids, losses)
            model.reassign(part, i + 1)
            one = run.evaluate(0, ids)
            model.logits, model.hard = logits, hard
            every = list(range(len(ids)))
            if clearly_better(here, one, every) and clearly_better(rest, one, every):
                found.append((one.mean() / here.mean(), i, j))
    return [(i, j) for _, i, j in sorted(found)]


def memo_losses(memo: dict[int, float], ids: list[int],
                losses: Callable[[list[int]], np.ndarray]) -> np.ndarray:
    """Per-frame losses of frames ``ids``: those in ``memo`` from it, the others computed by
    ``losses`` (of a frame list) and added to it."""
    todo = [i for i in ids if i not in memo]
    if todo:
        memo.update(zip(todo, (float(x) for x in losses(todo))))
    return np.array([memo[i] for i in ids])


@torch.no_grad()
def joint_for_both(model: ArticulatedSplat, i: int, j: int) -> list[JointFit]:
    """The revolute and the prismatic joint (:func:`.rigid.fit_both`) that best move parts
    ``i`` and ``j`` together as their own joints move them apart: per time the rigid motion of
    both parts' points (:func:`.rigid.kabsch`), then one joint fitted to those motions."""
    pi, pj = part_points(model, i, 200), part_points(model, j, 200)
    X = np.concatenate([pi, pj])
    transforms = []
    for ti in range(len(model.times)):
        R, t, _ = (x.cpu().numpy().astype(float) for x in model.motions(ti))
        transforms.append(kabsch(X, np.concatenate([pi @ R[i].T + t[i], pj @ R[j].T + t[j]])))
    return list(fit_both(X, transforms))


@torch.no_grad()
def start_best(run, k: int, fits: list[JointFit], ids: list[int]) -> str:
    """Joint ``k`` as it is or as one of ``fits``, whichever explains the frames ``ids`` best
    (image loss); returns which (``"kept"`` or the fit's type)."""
    model = run.model
    best, chosen = float(run.evaluate(0, ids).mean()), "kept"
    keep = snapshot(model)
    for f in fits:
        restore(model, keep)
        model.set_type(k, f.type, f.axis, f.origin, f.values)
        loss = float(run.evaluate(0, ids).mean())
        if loss < best:
            best, chosen, better = loss, f.type, snapshot(model)
    restore(model, keep if chosen == "kept" else better)
    return chosen


def merge_duplicates(run, fixed: list[bool]) -> list[list[str]]:
    """One joint for parts that move alike (:func:`same_joint`): the motion route often splits a
    door or a drawer front into pieces, each proposed with its own joint; fitted to the frames
    separately, their joints agree (the evidence that they are one), and each piece's motion
    explains its pixels, so none is spurious. The smaller part joins the larger one's joint,
    which is refitted with it: started from whichever explains the pieces' frames best, that
    joint or one joint fitted to both pieces' motions (:func:`joint_for_both`; where the larger
    piece's own fit is the wrong one), then a quarter of the main fit's steps, only that joint
    free. Two joints fitted apart always explain the frames a little better than one (on the
    test cabinet's door cut in two, 0.6 % of the image loss), so the loss is reported, not used
    to keep them apart; where the joints do not agree, one joint that explains both pieces
    clearly better than the two apart and than the other piece at rest
    (:func:`one_explains_both`) takes both. ``fixed`` joints (trusted user joints, locked ones,
    parts the robot opened) are never merged into another, and keep their own joint when a
    piece that moves alike joins them (a leftover of a door the robot's path gave its own
    part stayed as an extra joint). The runs of the robot's tool path the merged piece was held
    along pass to the joint it joins (:meth:`.model.ArticulatedSplat.pass_runs`). Returns
    ``[kept, merged]`` name pairs. The model must be hardened."""
    model, frames = run.model, run.frames
    merged: list[list[str]] = []
    fixed = list(fixed)
    steps = max(run.options.iterations // 4, 1)
    while True:
        counts = np.bincount(model.labels(), minlength=model.k + 1)[1:]
        pairs = [(i, j) for i in range(model.k) for j in range(model.k)
                 if i != j and not fixed[j]
                 and (fixed[i] or (counts[i], -i) > (counts[j], -j)) and same_joint(model, i, j)]
        alike = bool(pairs)
        if not pairs:
            pairs = one_explains_both(run, fixed)
        if not pairs:
            return merged
        i, j = pairs[0]
        here = float(run.evaluate().mean())
        fits = joint_for_both(model, i, j)
        ids = sorted(set(moving_frames(model, frames, i)) | set(moving_frames(model, frames, j)))
        model.reassign(model.labels() == j + 1, i + 1)
        model.pass_runs(j, i)      # the robot's runs along the piece: the joint moves it now
        names = model.names[i], model.names[j]
        run.drop_joint(j)
        del fixed[j]
        i -= int(j < i)
        start = "kept" if fixed[i] else start_best(run, i, fits, ids)
        run.run_fit(steps, f"{names[1]} with {names[0]}", 0.0,
                    free=[k == i for k in range(model.k)], lr_scale=0.3)
        joined = float(run.evaluate().mean())
        why = "moves as {} does" if alike else "{}'s joint explains its part better"
        start = "" if start == "kept" else f", refitted from one {start} joint for both"
        run.progress.log(f"{names[1]}: {why.format(names[0])}; its part joins {names[0]}'s"
                         f"{start} (image loss {here:.5f} -> {joined:.5f})")
        merged.append(list(names))


def keep_better_start(run, start_axes: np.ndarray, start_origins: np.ndarray,
                      start_types: list[str], names: list[str]) -> list[str]:
    """Per joint whose type did not change: if the start's axis and point, with the fitted states
    and parts, explain the frames where the joint moves no worse (within ``REMOVE_TOL``, the
    resolution of the evaluation) than the fitted ones, take them back (a precise proposal is
    not traded for a fit that wandered along a flat valley: the image loss of a joint 0.5° off
    differs by 1e-5–1e-3 relative on 160x120 frames).
    Returns the names of the joints that kept their start."""
    model, frames = run.model, run.frames
    kept = []
    for k in range(model.k):
        s = names.index(model.names[k]) if model.names[k] in names else None
        if s is None or model.types[k] != start_types[s] or bool(model.locked[k]):
            continue
        ids = moving_frames(model, frames, k)
        if not ids:
            continue
        fitted = snapshot(model)
        path = model.held_residual(k)
        here = float(run.evaluate(0, ids).mean())
        with torch.no_grad():
            model.axes = model.axes.clone()
            model.origins = model.origins.clone()
            a = torch.as_tensor(start_axes[s], dtype=torch.float32, device=model.axes.device)
            if float((a * model.joint_axes()[k]).sum()) < 0:   # the fitted states' sign
                a = -a
            model.axes[k] = a
            model.origins[k] = torch.as_tensor(start_origins[s], dtype=torch.float32)
        there = float(run.evaluate(0, ids).mean())
        if there < here * (1 + REMOVE_TOL) and not model.leaves_path(k, path):
            # the frames cannot tell them apart (nor the robot's tool): the start
            kept.append(model.names[k])
            run.progress.log(f"{model.names[k]}: the start explains the frames better "
                             f"({there:.5f} < {here:.5f}); kept")
        else:
            restore(model, fitted)
    return kept
