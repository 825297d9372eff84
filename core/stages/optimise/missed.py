"""Missed parts: where the frames change and the model does not, a new part is fitted and kept only
when it clearly lowers the image loss; a new part that moves with an existing one is merged."""

from __future__ import annotations

import numpy as np
import torch

from .fit import part_level, search_states
from ...model.joints import joint_transform
from .hypotheses import (REMOVE_TOL, clearly_better, hidden_share, hinge_lines, key_time,
                         line_and_circle, moved_with, part_normal, part_points, score_at,
                         state_candidates, tool_segments)
from .kinematics import PRISMATIC, REVOLUTE
from .model import ArticulatedSplat, restore, snapshot, unshaded
from .plausible import HIDDEN_SHARE, little_motion, off_part
from .seen import seen_static, unexplained


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
    """Of changed points (N,3) with the time step each started to change, one part of the
    largest group: the group's points whose onset lies within ``link`` steps of its most common
    onset, their largest connected piece (parts side by side that move at different times are
    split; what a moving part hid or uncovered starts with it and stays). When that gives no
    piece of ``min_size``, the next most common onset is tried, and the whole group is the part
    when none does: a door that swings slowly changes its pixels over many steps (a PartNet
    glass door's onsets spread over six steps, and its most common one split it into pieces
    too small to fit). Index array, or None without a group."""
    groups = clusters(points, min_size)
    if not groups:
        return None
    g = groups[0]
    counts = np.bincount(onset[g])
    for mode in np.argsort(-counts, kind="stable"):
        if not counts[mode]:
            break
        sub = g[np.abs(onset[g] - mode) <= link]
        pieces = clusters(points[sub], min_size)
        if pieces:
            return sub[pieces[0]]
    return g

def add_missed(run, share: float, tries: int = 3) -> list[str]:
    """Missed parts, one at a time: Gaussians of the base where the frames show changes the model
    does not (:func:`unexplained`), grouped into connected clusters (at least 1 % of the
    Gaussians), of which the part that starts moving first (:func:`first_mover`) becomes a part
    hypothesis: hinges at its box edges and slides along its normal and box axes are scored by
    rendering at its key time (:func:`.hypotheses.key_time`, among the times its Gaussians
    change), the best is fitted (then, if needed, the best of the other type), and the part is
    kept only if it clearly lowers the image loss of the frames where it moves
    (:func:`clearly_better`) and its motion is plausible (:func:`implausible`). A kept
    part explains its changes (and those of what it hid), so the changes are found again before
    the next of at most ``tries`` attempts; a rejected cluster is left out of the next ones (the
    frames may show another part moving beside a piece no joint explains). Returns the names of
    the added joints."""
    model, frames, cfg = run.model, run.frames, run.cfg
    means = model.splat.means.cpu().numpy().astype(float)
    added: list[str] = []
    tried = np.zeros(model.splat.n, bool)
    steps = max(run.options.iterations // 2, 1)
    for attempt in range(tries):
        hits = unexplained(model, frames, cfg)
        flagged = np.flatnonzero(hits.any(0) & ~tried)
        g = first_mover(means[flagged], hits[:, flagged].argmax(0),
                        max(10, model.splat.n // 100))
        if g is None:
            break
        members = np.zeros(model.splat.n, bool)
        members[flagged[g]] = True
        with unshaded(model):
            before_frames = run.evaluate()
        before = float(before_frames.mean())
        kept = snapshot(model)
        k = run.add_joint(REVOLUTE, np.array([0.0, 0.0, 1.0]), means[members].mean(0), members)
        name = model.names[k]
        pts = part_points(model, k)
        hyps = [(REVOLUTE, a, p) for a, p in hinge_lines(model, pts)]
        hyps += [(PRISMATIC, d, pts.mean(0)) for d in
                 [part_normal(model, k)] + list(np.linalg.svd(pts - pts.mean(0))[2])]
        # scored where its own Gaussians change (hits' row r: times r and r + 1)
        key = key_time(run, k, np.concatenate([[0.0], hits[:, members].mean(1)]))
        scored = []
        for kind, axis, point in hyps:
            model.set_type(k, kind, axis, point, np.zeros(len(frames.times)))
            scored.append((score_at(model, frames, cfg, k, key, state_candidates(model, k))[0],
                           kind, axis, point))
            run.progress.check_cancel()
        # the best-scoring hypothesis is fitted; if it does not explain the frames better or
        # moves implausibly, the best of the other type is (a small part's score at one time
        # can mislead)
        order = sorted(scored, key=lambda s: s[0])
        first = order[0][1]
        second = [s for s in order if s[1] != first][:1]
        for _, kind, axis, point in order[:1] + second:
            model.set_type(k, kind, axis, point, np.zeros(len(frames.times)))
            search_states(model, frames, k, cfg, state_candidates(model, k))
            run.run_fit(steps, f"new part {name} as {kind}", share / tries / 2,
                        free=[i == k for i in range(model.k)], coarse=cfg.coarse,
                        coarse_level=part_level(model, frames, k))
            with unshaded(model):
                after_frames = run.evaluate()
            after = float(after_frames.mean())
            # a part the optimisation invents has only the loss it lowers as evidence: over
            # all frames, not on the frames it picks itself (the local test is for proposals)
            gain = clearly_better(before_frames, after_frames, [])
            run.progress.log(f"{name}: {len(g)} Gaussians where the frames change and the "
                             f"model does not; as a {kind} part the image loss is {after:.5f} "
                             f"(without {before:.5f})")
            why = implausible(model, k) if gain else None
            if why:
                gain = False
                run.progress.log(f"{name}: not added as a {kind} part, {why}")
            if gain:
                break
        if not gain:
            run.drop_joint(k)
            restore(model, kept)
            tried |= members
            continue
        into = merge_target(run, k, after)
        if into is None:
            added.append(name)
            continue
        run.progress.log(f"{name}: moves with {model.names[into]}; merged into its part")
        fitted = snapshot(model)
        model.reassign(model.labels() == k + 1, into + 1)
        run.drop_joint(k)
        restore(model, tuple(part[:-1] for part in fitted))    # every joint's but the last
    return added

def implausible(model: ArticulatedSplat, k: int, measured: bool = False) -> str | None:
    """Why fitted joint ``k`` is no part to invent, or None: it barely moves
    (:func:`.plausible.little_motion`: a part that turns half the object by half a degree
    absorbs small registration errors), or, unless its line was ``measured`` (read off the
    robot's path, which the hand's turn confirms), its hinge passes off its part
    (:func:`hinge_off_part`: a wide circle mimics another motion). Whether it moves into the
    body is asked only of its final fit (:func:`drop_into_body`): a first fit's part holds
    more than the part, and a door found from no proposal went 98-100 % into the body there."""
    kind = model.types[k]
    values = np.array(list(model.joint_values(k).values()))
    span = float(np.ptp([0.0, *values]))
    axes, origins = model.joint_lines()
    if little_motion(kind, span, part_points(model, k, limit=model.splat.n), axes[k], origins[k]):
        unit = "rad" if kind == REVOLUTE else "m"
        return f"it barely moves ({span:.3f} {unit}): an invented part must move visibly"
    if not measured and hinge_off_part(model, k):
        return "its hinge passes off the part (a wide circle that mimics another motion)"
    return None

def hinge_off_part(model: ArticulatedSplat, k: int) -> bool:
    """Whether joint ``k`` is a hinge whose line passes off its part
    (:func:`.plausible.off_part`)."""
    if model.types[k] != REVOLUTE:
        return False
    axes, origins = model.joint_lines()
    return off_part(axes[k], origins[k], part_points(model, k, limit=model.splat.n))

@torch.no_grad()
def merge_target(run, k: int, loss: float) -> int | None:
    """The joint of the same type whose motion explains joint ``k``'s part as well as ``k`` does
    (within ``REMOVE_TOL`` of ``loss``, the image loss over all frames): a new part that is the
    rest of an existing one (Gaussians its box missed) is merged into it. None if none."""
    model = run.model
    best = None
    for j in range(model.k):
        if j == k or model.types[j] != model.types[k]:
            continue
        merged = float(moved_with(run, k, j).mean())
        if merged <= loss * (1 + REMOVE_TOL) and (best is None or merged < best[0]):
            best = (merged, j)
    return None if best is None else best[1]

def drop_into_body(run, names: list[str]) -> list[str]:
    """Of the invented joints ``names``, drop those whose final fit moves more than
    ``HIDDEN_SHARE`` of their part behind surfaces the static views measured
    (:func:`.hypotheses.hidden_share`): an opening part moves into space, and an invented part
    has no other evidence than the loss it lowers, which a piece of noise swung into the body (the
    demo cabinet's 173 Gaussians, 0.1 % of loss) also lowers. Asked after the final fits, not
    of the first (whose part holds more than the part). Returns the dropped names."""
    model = run.model
    dropped = []
    for name in names:
        k = model.names.index(name)
        share = hidden_share(run, k)
        if share > HIDDEN_SHARE:
            run.progress.log(f"{name}: dropped, its fit moves {100 * share:.0f} % of its part "
                             f"into the body (behind what the static views measured)")
            run.drop_joint(k)
            dropped.append(name)
    return dropped

# a joint explains a tool run when it carries the first grasp point along the run within this
# share of the object's size (the grasp holds the handle within ~1 cm; a hinge 10 deg off at
# half a metre strays ~5 cm over a quarter turn)
TOOL_TOL = 0.05

# ... and within this share of how far the run went: a joint at rest "carries" a short run (a
# hand reaching for a handle) within the size share, and would be pulled along it
CARRIED = 0.5

# the hand held a joint's part when a Gaussian of it lies within this share of the object's size
# of the grasp point (the start's handle holds alike: core/stages/optimise/stage.py)
HANDLE_NEAR = 0.03


# a held tool whose approach turns by at least this much (rad) over a run turns with a hinge: a
# grasp turns with its part, by the part's own angle, and not at all on a slide
TURNED = np.radians(5.0)


def tool_joint(path: np.ndarray, size: float, approach: np.ndarray | None = None
               ) -> tuple[str, np.ndarray, np.ndarray, np.ndarray]:
    """The joint of one run of tool positions ``path`` (M,3), with its value at each position
    (rad / m, 0 at the first). ``approach`` (M,3), when known, is the tool's approach direction
    at each position: one that turned by ``TURNED`` or more turned with a hinge (the approach,
    not the whole pose: a parallel gripper holds a handle alike turned half a turn about its
    approach, and IK may pick either). Hinge candidates: the circle through the positions (axis
    normal to their plane) and the approaches' turn (axis normal to it, values their angles
    about it, line by least squares, :func:`_turn_hinge`; good however short the arc, but only
    as good as the tool's orientation); the one that carries the first position along the path
    more closely is kept. Without a turn, the circle when it explains the positions clearly
    better than a line, else a slide along their principal direction."""
    if len(path) >= 3:
        vt, line, centre, circle = line_and_circle(path)
    else:
        vt = np.linalg.svd(path - path.mean(0), full_matrices=False)[2]
        line, centre, circle = 0.0, None, np.inf
    hinges = []
    if centre is not None and np.linalg.norm(centre - path.mean(0)) < 10 * size:
        xy = (path - centre) @ vt[:2].T
        angles = np.unwrap(np.arctan2(xy[:, 1], xy[:, 0]))
        values = angles - angles[0]           # about vt[0] x vt[1], right-handed
        hinges.append((np.cross(vt[0], vt[1]), centre, values))
    if approach is not None:
        approach = approach / np.linalg.norm(approach, axis=1, keepdims=True)
    turned = approach is not None and len(path) >= 2 and _turn(approach) >= TURNED
    if turned:
        hinges.append(_turn_hinge(path, approach))
    if hinges and (turned or circle < 0.5 * line):
        axis, point, values = min(hinges, key=lambda h: _carried(path, approach, *h))
        k = int(np.argmax(np.abs(values)))
        return (REVOLUTE, axis, point, values) if values[k] >= 0 else \
            (REVOLUTE, -axis, point, -values)
    axis = vt[0] if (path[-1] - path[0]) @ vt[0] >= 0 else -vt[0]
    return PRISMATIC, axis, path[0], (path - path[0]) @ axis


def _turn(approach: np.ndarray) -> float:
    """Largest angle (rad) between the first (unit) approach direction and any later one."""
    return float(np.arccos(np.clip(approach[1:] @ approach[0], -1.0, 1.0)).max())


def _turn_hinge(path: np.ndarray, approach: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(axis, point, values) of the hinge the (unit) approaches turned about: the axis normal to
    the first approach and the one most turned from it, the values the approaches' angles about
    it, the line the points c with p_i - c = R(axis, value_i) (p_0 - c) in least squares."""
    from ...model.joints import rotation_about_axis

    u = np.cross(approach[0], approach[int(np.argmin(approach @ approach[0]))])
    u /= np.linalg.norm(u)
    flat = approach - np.outer(approach @ u, u)
    values = np.arctan2(np.cross(flat[0], flat) @ u, flat @ flat[0])
    turns = [rotation_about_axis(u, v) for v in values[1:]]
    A = np.concatenate([np.eye(3) - R for R in turns])
    b = np.concatenate([p - R @ path[0] for p, R in zip(path[1:], turns)])
    return u, np.linalg.lstsq(A, b, rcond=None)[0], values


def _carried(path: np.ndarray, approach: np.ndarray | None, axis: np.ndarray,
             point: np.ndarray, values: np.ndarray) -> float:
    """RMS distance (m) between the positions and the first one carried by the hinge, plus,
    with (unit) ``approach``, the approaches' RMS difference from the first one carried alike,
    as a distance at the handle's radius (a circle through noisy positions of a short arc fits them
    closely with a wrong axis; the approaches then disagree)."""
    Ms = [joint_transform(REVOLUTE, axis, point, v) for v in values]
    moved = np.array([M[:3] @ np.append(path[0], 1.0) for M in Ms])
    cost = float(np.sqrt(np.mean(np.sum((moved - path) ** 2, 1))))
    if approach is None:
        return cost
    turned = np.array([M[:3, :3] @ approach[0] for M in Ms])
    rel = path[0] - point
    radius = float(np.linalg.norm(rel - (rel @ axis) * axis))
    return cost + radius * float(np.sqrt(np.mean(np.sum((turned - approach) ** 2, 1))))


def carry_error(model: ArticulatedSplat, k: int, times: list[int], path: np.ndarray) -> float:
    """Largest distance (m) between ``path`` (one position per time of ``times``) and its first
    point carried along by joint ``k``'s fitted motion from ``times[0]``."""
    axes, origins = model.joint_lines()
    values = model.joint_values(k)
    kind = model.types[k]
    start = np.linalg.inv(joint_transform(kind, axes[k], origins[k], values[times[0]]))
    p0 = np.append(path[0], 1.0)
    return max(float(np.linalg.norm((joint_transform(kind, axes[k], origins[k], values[t])
                                     @ start @ p0)[:3] - p)) for t, p in zip(times, path))


def carried_runs(model: ArticulatedSplat, runs: list[np.ndarray], path: np.ndarray,
                 times: list[int], kinds: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """Per joint and run of the tool ``path`` (positions at ``times``; ``runs`` index arrays,
    ``kinds`` the type of each run's :func:`tool_joint`): the :func:`carry_error` (K, runs),
    and whether the joint carries the run: a joint of the run's type (a hinge of wide radius
    carries a short slide within centimetres, and the tool term would then bend it towards
    a line) within ``TOOL_TOL`` of the object's size and ``CARRIED`` of how far the run
    went."""
    spans = np.array([np.linalg.norm(path[q] - path[q[0]], axis=1).max() for q in runs])
    errors = np.array([[carry_error(model, k, [times[i] for i in q], path[q]) for q in runs]
                       for k in range(model.k)]).reshape(model.k, len(runs))
    alike = np.array([[t == kind for kind in kinds] for t in model.types], bool)
    return errors, alike.reshape(errors.shape) & (
        errors <= np.minimum(TOOL_TOL * model.size, CARRIED * spans))


def carrier(errors: np.ndarray, held: np.ndarray, r: int) -> int | None:
    """The joint that carries run ``r`` best (least error among those that carry it, by
    :func:`carried_runs`' ``errors`` and ``held``), or None when none does."""
    if not held[:, r].any():
        return None
    return int(np.argmin(np.where(held[:, r], errors[:, r], np.inf)))


def run_states(along: np.ndarray, ts: list[int], times: list[int]) -> list[np.ndarray]:
    """Candidate states at ``times`` of a joint read off one tool run (values ``along`` at the
    run's times ``ts``, 0 before, held after): as read, and with either end continued by its
    neighbouring step, since a run's first position may be a step into the opening (the hand
    grasped between two frames) and its last one a step short of it (the hand letting go). The
    frames' depth chooses among them."""
    starts = [0.0] if len(along) < 2 else [0.0, along[1] - along[0]]
    ends = [along[-1]] if len(along) < 3 else [along[-1], 2 * along[-2] - along[-3]]
    out = []
    for shift in starts:
        for end in ends:
            v = along + shift
            v[-1] = end + shift
            values = np.zeros(len(times))
            for t, x in zip(ts, v):
                values[times.index(t)] = x
            values[[i for i, t in enumerate(times) if t > ts[-1]]] = v[-1]
            out.append(values)
    return out


def add_tool_parts(run, share: float) -> list[str]:
    """Joints the robot was seen opening that no joint explains: each run of the tool path
    (:func:`.hypotheses.tool_segments`: a hand holding one handle moves on a circle about its
    hinge or a line along its slide) is held (:meth:`.model.ArticulatedSplat.hold`, the tool
    term of every later fit) by the fitted joint that carries its first grasp point along it
    best (:func:`carried_runs`: of the run's type, within ``TOOL_TOL`` of the object's size
    and ``CARRIED`` of how far the run went). A run no joint
    carries gives a joint read off the path (:func:`tool_joint`; its states 0 before the run and
    held after it, the run's ends continued or not as the depth below finds more Gaussians:
    :func:`run_states`), held along the run, tried on two parts:
    - the part of the joint the hand grasped (:func:`held_part`), that joint's motion replaced
      (a realistic robot dishwasher's door, proposed as a slide of the right part: as a new
      part its depth-chosen Gaussians made the true hinge explain the frames worse than none);
    - a new part chosen by the frames (:func:`moved_by_tool`: the Gaussians of the base, or of
      joints that explain no run, that its motion puts where the depth contradicts them less,
      less those seen staying put); their connected group nearest the first grasp point (a
      storage unit's two doors, proposed as one slide of both; a realistic robot cabinet's
      drawer, which without the ones seen staying put took the body's sides along).
    Each is fitted alone and is kept, as :func:`add_missed` keeps a part, when it clearly
    lowers the image loss and moves plausibly; of the two the lower image loss. The robot's own
    record is the evidence of which part moved and how; the motion route and the missed-part
    search see only pixels, and lose a part the arm hides. Returns the names of the joints
    added or replaced."""
    model, frames = run.model, run.frames
    if not frames.tool:
        return []
    times, path, approaches, runs = tool_runs(frames, model.size)
    joints = [tool_joint(path[q], model.size, approaches[q]) for q in runs]
    added: list[str] = []
    for r, seg in enumerate(runs):
        ts, P = [times[i] for i in seg], path[seg]
        approach = approaches[seg]
        ti = [model.times.index(t) for t in ts]
        errors, held = carried_runs(model, runs, path, times, [j[0] for j in joints])
        k = carrier(errors, held, r)
        if k is not None:
            _hold(run, k, ts, P, approach, errors[k, r])
            continue
        joint = joints[r]
        with unshaded(model):
            before = run.evaluate()
        labels, kept = model.labels(), snapshot(model)
        draws = run.rng.bit_generator.state     # given back when nothing is kept
        share_each = share / max(len(runs), 1) / 2
        # the joint whose part the hand held, its motion read off the path instead ...
        k = held_part(model, held, P[0])
        retyped: tuple | None = None
        if k is not None:
            model.set_type(k, *joint[:3], run_states(joint[3], ts, model.times)[0])
            model.hold(model.names[k], ti, P, approach)
            after = _fit_tool_part(run, k, share_each)
            why = _kept_or_why(model, k, before, after)
            run.progress.log(f"{model.names[k]}: its part was held along {len(ts)} steps of "
                             f"the robot's path that no joint explains; moved as read off the "
                             f"path the image loss is {float(after.mean()):.5f} (without "
                             f"{float(before.mean()):.5f}){'; ' + why if why else ''}")
            if not why:
                retyped = (float(after.mean()), snapshot(model), model.held[model.names[k]][-1])
            model.held[model.names[k]].pop()
            restore(model, kept)
        # ... or a new part chosen by the frames' depth; the lower image loss is kept
        name, after, why = _new_tool_part(run, held, ts, ti, P, approach, joint, labels,
                                          before, share_each)
        if not why and (retyped is None or float(after.mean()) <= retyped[0]):
            added.append(name)
            continue
        if name in model.names:
            run.drop_joint(model.names.index(name))
            model.reassign_all(labels)
        restore(model, kept)
        run.progress.log(f"{name}: not added from the robot's path, " + (
            why or f"{model.names[k]} moved as read off it explains the frames better"))
        if retyped is not None:
            restore(model, retyped[1])
            model.held.setdefault(model.names[k], []).append(retyped[2])
            added.append(model.names[k])
        else:     # as if never tried: the later fits draw the same times
            run.rng.bit_generator.state = draws
    return added


def tool_runs(frames, size: float) -> tuple[list[int], np.ndarray, np.ndarray, list[np.ndarray]]:
    """The robot's tool path (``frames.tool``): its times, positions (M,3), approach directions
    (M,3) and runs (:func:`.hypotheses.tool_segments`, index arrays; a run ends where the path
    leaves a circle or line by 1 % of the object's ``size`` or jumps by 5 %)."""
    times = sorted(frames.tool)
    path = np.array([frames.tool[t][:3, 3] for t in times])
    approaches = np.array([frames.tool[t][:3, 2] for t in times])
    return times, path, approaches, tool_segments(path, 0.01 * size, 0.02 * size, 0.05 * size)


def _hold(run, k: int, ts: list[int], P: np.ndarray, approach: np.ndarray, error: float) -> None:
    """Joint ``k`` held along the run ``P`` at times ``ts`` (the tool term of its later fits)."""
    model = run.model
    model.hold(model.names[k], [model.times.index(t) for t in ts], P, approach)
    run.progress.log(f"{model.names[k]}: held by the robot's tool from time {ts[0]} to "
                     f"{ts[-1]} (carries the grasp within {100 * error:.1f} cm); the path joins "
                     f"its fits")


def hold_carried(run) -> list[str]:
    """Runs of the tool path that no joint holds yet, held by the joint that now carries them
    best (:func:`carried_runs`): a joint whose line was off when :func:`add_tool_parts` read
    the path (a realistic robot cabinet's door was 17 deg off after the first fit, its run
    given no part) and that the fits since have brought onto it gets the path's evidence for
    the fits after. (That door ended 12 cm from its run's line, farther than the limits, and
    was not held.) Returns the names of the joints that got a run."""
    model, frames = run.model, run.frames
    if not frames.tool or not model.k:
        return []
    times, path, approaches, runs = tool_runs(frames, model.size)
    first = {int(entry[0][0]) for entries in model.held.values() for entry in entries}
    kinds = [tool_joint(path[q], model.size, approaches[q])[0] for q in runs]
    errors, held = carried_runs(model, runs, path, times, kinds)
    got = []
    for r, seg in enumerate(runs):
        k = carrier(errors, held, r)
        if model.times.index(times[seg[0]]) in first or k is None:
            continue
        _hold(run, k, [times[i] for i in seg], path[seg], approaches[seg], errors[k, r])
        got.append(model.names[k])
    return got


def held_part(model: ArticulatedSplat, held: np.ndarray, grasp: np.ndarray) -> int | None:
    """The unlocked joint that explains no run of the tool path (``held`` (K, runs)) whose part
    the hand grasped: a Gaussian of it within ``HANDLE_NEAR`` of the object's size of the
    ``grasp`` point (the nearest such part), or None."""
    means = model.splat.means.cpu().numpy().astype(float)
    labels = model.labels()
    best, near = None, HANDLE_NEAR * model.size
    for k in range(model.k):
        pts = means[labels == k + 1]
        if held[k].any() or bool(model.locked[k]) or not len(pts):
            continue
        d = float(np.linalg.norm(pts - grasp, axis=1).min())
        if d <= near:
            best, near = k, d
    return best


def _fit_tool_part(run, k: int, share: float) -> np.ndarray:
    """Joint ``k`` fitted alone (coarse-to-fine, half the main fit's steps); the per-frame
    image losses after (unshaded)."""
    model = run.model
    steps = max(run.options.iterations // 2, 1)
    run.run_fit(steps, f"{model.names[k]} from the robot's path", share,
                free=[i == k for i in range(model.k)],
                coarse=run.cfg.coarse, coarse_level=part_level(model, run.frames, k))
    with unshaded(model):
        return run.evaluate()


def _kept_or_why(model: ArticulatedSplat, k: int, before: np.ndarray, after: np.ndarray) -> str:
    """Why a tool part's fit is not kept ('' when it is): it does not clearly lower the image
    loss, or it moves implausibly."""
    if not clearly_better(before, after, []):
        return (f"it does not lower the image loss clearly ({float(after.mean()):.5f} against "
                f"{float(before.mean()):.5f})")
    return implausible(model, k, measured=True) or ""


def moved_by_tool(model: ArticulatedSplat, frames, cfg, k: int, candidates: list[np.ndarray],
                  labels: np.ndarray, free: np.ndarray) -> np.ndarray:
    """Indices of the Gaussians joint ``k`` (a tool part's) moves: of the ``free`` ones (their
    ``labels`` the parts before it), those the frames' depth contradicts at least ``MARGIN``
    frames less when the joint moves them, or whose support less contradiction rises by
    ``MARGIN`` (:func:`.assign.depth_votes`; a slide that moves a door into the body hides
    it, and hidden is never contradicted), with the state ``candidates`` (:func:`run_states`)
    that gives the most (the joint is left at them); less those the frames then show staying
    put (:func:`.seen.seen_static`): a surface that slides within its own plane (the body's
    side beside a drawer) lands on itself, supported and never contradicted, but its pixels do
    not change."""
    from .assign import MARGIN, depth_votes

    kind, axis, point = model.types[k], *(x[k] for x in model.joint_lines())
    moves, best = np.zeros(0, int), candidates[0]
    for values in candidates:
        model.set_type(k, kind, axis, point, values)
        support, against = (x.cpu().numpy() for x in depth_votes(model, frames, cfg))
        at = np.arange(model.splat.n), labels
        here, net = against[at], support[at] - against[at]
        these = np.flatnonzero(free & (support[:, k + 1] > 0) & (
            (against[:, k + 1] <= here - MARGIN)
            | (support[:, k + 1] - against[:, k + 1] >= net + MARGIN)))
        if len(these) > len(moves):
            moves, best = these, values
    model.set_type(k, kind, axis, point, best)
    part = labels.copy()
    part[moves] = k + 1
    model.reassign_all(part)
    return moves[~seen_static(model, frames, cfg, k)[moves]]


def _new_tool_part(run, held: np.ndarray, ts: list[int], ti: list[int], P: np.ndarray,
                   approach: np.ndarray, joint: tuple, labels: np.ndarray, before: np.ndarray,
                   share: float) -> tuple[str, np.ndarray, str]:
    """A new joint ``joint`` (:func:`tool_joint`) held along the run ``P`` (at times ``ts``,
    time indices ``ti``), its part the connected group nearest the first grasp of the
    Gaussians :func:`moved_by_tool` gives it, fitted: (its name, the per-frame image losses
    after, why it is not kept against the losses ``before`` or ''). The model keeps the new
    joint whatever the outcome."""
    model, frames, cfg = run.model, run.frames, run.cfg
    kind, axis, point, along = joint
    means = model.splat.means.cpu().numpy().astype(float)
    free = np.isin(labels, [0] + [k + 1 for k in range(model.k) if not held[k].any()])
    seed = np.zeros(model.splat.n, bool)
    seed[int(np.argmin(np.linalg.norm(means - P[0], axis=1)))] = True
    k = run.add_joint(kind, axis, point, seed)
    name = model.names[k]
    model.hold(name, ti, P, approach)
    moves = moved_by_tool(model, frames, cfg, k, run_states(along, ts, model.times),
                          labels, free)
    groups = clusters(means[moves], max(10, model.splat.n // 100))
    if not groups:
        return name, np.zeros(0), "the frames' depth gives it no part"
    near = min(groups, key=lambda g: float(np.linalg.norm(means[moves[g]] - P[0], axis=1).min()))
    part = labels.copy()
    part[moves[near]] = k + 1
    model.reassign_all(part)
    after = _fit_tool_part(run, k, share)
    run.progress.log(f"{name}: the robot's tool moved over {len(ts)} steps that no joint "
                     f"explains; as a {kind} part of {len(near)} Gaussians the image loss is "
                     f"{float(after.mean()):.5f} (without {float(before.mean()):.5f})")
    return name, after, _kept_or_why(model, k, before, after)
