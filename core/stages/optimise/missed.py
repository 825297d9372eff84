"""Missed parts: where the frames change and the model does not, a new part is fitted and kept only
when it clearly lowers the image loss; a new part that moves with an existing one is merged."""

from __future__ import annotations

import numpy as np
import torch

from .fit import part_level, search_states
from .hypotheses import (REMOVE_TOL, clearly_better, hidden_share, hinge_lines, key_time,
                         moved_with, part_normal, part_points, score_at, state_candidates)
from .kinematics import PRISMATIC, REVOLUTE
from .model import ArticulatedSplat, restore, snapshot, unshaded
from .plausible import HIDDEN_SHARE, little_motion, off_part
from .seen import unexplained


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
        name = f"part_{len(model.names) + 1}"
        while name in model.names:
            name += "_"
        k = model.add(name, REVOLUTE, np.array([0.0, 0.0, 1.0]), means[members].mean(0), members)
        run.trust = torch.cat([run.trust, torch.zeros(1, device=run.trust.device)])
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
            model.drop(k)
            run.trust = run.trust[:-1]
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
        model.drop(k)
        run.trust = run.trust[:-1]
        restore(model, tuple(part[:-1] for part in fitted))    # every joint's but the last
    return added

def implausible(model: ArticulatedSplat, k: int) -> str | None:
    """Why fitted joint ``k`` is no part to invent, or None: it barely moves
    (:func:`.plausible.little_motion`: a part that turns half the object by half a degree
    absorbs small registration errors), or its hinge passes off its part
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
    if hinge_off_part(model, k):
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
            model.drop(k)
            run.trust = torch.cat([run.trust[:k], run.trust[k + 1:]])
            dropped.append(name)
    return dropped
