"""The joints' last refinement on the interaction frames' depth, beyond the paper.

Near the true joint the image loss is flat: on 160x120 frames a joint 0.5 degrees off changes the
mean loss by 1e-6 to 1e-3 relative, so the rendering fit wanders along a valley (README,
"Optimisation"). The depth maps resolve it: every measured pixel of the part is a point the part's
surface must pass through. Each joint is refined by point-to-plane least squares of its part's
canonical Gaussians, placed by the joint at every time it moves, against the measured points of
those times (:func:`core.geometry.rigid.refine_joint`, the motion route's refinement, with its
clouds, thresholds and visibility filter: core/stages/propose/motion), from the fitted axis, line,
states and parts; a slide is then taken along the normal of its part's front
(:func:`front_face`) when within the route's ``front_snap_deg`` of it, as the route does (a flat
front pins a slide only along its normal, so the points leave the slide's sideways tilt to noise
and to the part's stray Gaussians), and a hinge into its panel's plane (:func:`in_panel`).
The refined joint is kept unless it explains the frames where the part moves worse by more than
the evaluation's resolution (``REMOVE_TOL``): the image loss keeps the decisions (type, part,
which line), the depth sets the last decimals.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from scipy.spatial import cKDTree

from ...geometry.rigid import JointFit, StepData
from ...model.capture import Capture
from ..propose.motion.assemble import plane_normal, refine_on_steps, snap_to_front
from ..propose.motion.cameras import make_views, step_cloud
from ..propose.motion.config import MotionConfig
from ..propose.motion.track import visible_filter
from ..propose.stage import splat_depth, twin_depth
from .hypotheses import REMOVE_TOL, moving_frames, part_points
from .kinematics import REVOLUTE
from .model import restore, snapshot

#: A refinement that turns the axis further (degrees) or moves a hinge line further (x object
#: size) is another joint, not the last decimals: it must lower the image loss to be kept.
MAX_TURN = 2.0
MAX_SHIFT = 0.02
#: A face's thickness in the splat (x object size): Gaussians this close to a plane lie on it.
FACE_WIDTH = 0.015


def front_face(pts: np.ndarray, axis: np.ndarray, size: float, width: float = FACE_WIDTH,
               peak: float = 3.0) -> np.ndarray | None:
    """The part's face square to a slide along ``axis``: its Gaussians within ``width`` x the
    object's ``size`` of the most populated level along the axis (a drawer's front, not its
    handle or the sides the part may hold), or None when that level is no clear face: fewer
    than ``peak`` times the mean level's Gaussians (a door sliding in its own plane spreads
    evenly along its slide) or fewer than 3."""
    d = pts @ axis
    step = width * size
    counts, edges = np.histogram(d, bins=max(int(np.ptp(d) / step), 1))
    top = int(np.argmax(counts))
    if len(counts) > 1 and counts[top] < peak * len(pts) / len(counts):
        return None
    face = pts[np.abs(d - 0.5 * (edges[top] + edges[top + 1])) <= step]
    return face if len(face) >= 3 else None


def in_panel(fit: JointFit, pts: np.ndarray, size: float, max_deg: float,
             width: float = FACE_WIDTH) -> JointFit:
    """A hinge lies in the plane of its panel (a door, a lid): when at least half of the part's
    Gaussians lie within ``width`` x the object's ``size`` of their dominant plane and the axis
    is within ``max_deg`` of that plane, the axis is projected into it (the point stays). The
    points pin a hinge's tilt out of the panel only through the small motion of its far edge;
    the panel's plane, over thousands of Gaussians, is pinned far better."""
    n = plane_normal(pts)
    r = (pts - pts.mean(0)) @ n
    r -= np.median(r)
    tilt = math.degrees(math.asin(min(abs(float(fit.axis @ n)), 1.0)))
    if np.mean(np.abs(r) <= width * size) < 0.5 or tilt > max_deg:
        return fit
    axis = fit.axis - (fit.axis @ n) * n
    return replace(fit, axis=axis / np.linalg.norm(axis))


def refine_on_depth(run, capture: Capture, arrays, config: MotionConfig | None = None
                    ) -> dict[str, dict[str, float]]:
    """Refine every unlocked joint on the depth (module doc); returns per joint the image loss
    over its moving frames before and after and whether the refinement was kept."""
    model, frames, options = run.model, run.frames, run.options
    mc = config or MotionConfig()
    views = make_views(capture, lambda camera: splat_depth(arrays, camera, options.device), mc,
                       twin_depth(capture, options.robot_twin, options.device))
    if not views:
        return {}
    thr = float(np.median([v.threshold for v in views]))
    clouds: dict[int, StepData] = {}
    report: dict[str, dict[str, float]] = {}
    for k in range(model.k):
        run.progress.check_cancel()
        ids = moving_frames(model, frames, k)
        if bool(model.locked[k]) or not ids:
            continue
        values = model.joint_values(k)
        moving = sorted({model.times[frames.time_index[i]] for i in ids})
        for t in moving:
            if t not in clouds:
                P, N, _ = step_cloud(views, t)
                clouds[t] = StepData(P, N, cKDTree(P), visible_filter(views, t))
        steps = [clouds[t] for t in moving]
        if sum(len(s.points) for s in steps) < 20:
            continue
        pts = part_points(model, k, limit=mc.track_points)
        axis, origin = (line[k] for line in model.joint_lines())
        start = JointFit(model.types[k], axis, origin, np.array([values[t] for t in moving]),
                         np.nan, np.nan, 0.0)
        new = refine_on_steps(start, pts, steps, thr, mc, mc.refine_rounds)
        if model.types[k] == REVOLUTE:
            new = in_panel(new, pts, model.size, mc.front_snap_deg)
        elif (front := front_face(pts, new.axis, model.size)) is not None:
            new, _ = snap_to_front(new, front, mc.front_snap_deg)   # as the motion route
        here = float(run.evaluate(0, ids).mean())
        path = model.held_residual(k)
        kept = snapshot(model)
        sign = 1.0 if new.axis @ axis >= 0 else -1.0    # refine_joint may flip axis and values
        refined = {t: sign * v for t, v in values.items()}
        refined.update(zip(moving, map(float, new.values)))
        model.set_type(k, model.types[k], new.axis, new.origin, refined, shading=True)
        there = float(run.evaluate(0, ids).mean())
        turn = float(np.degrees(np.arccos(np.clip(abs(new.axis @ axis), -1, 1))))
        shift = float(np.linalg.norm(np.cross(new.origin - origin, axis))) \
            if model.types[k] == REVOLUTE else 0.0
        small = turn <= MAX_TURN and shift <= MAX_SHIFT * model.size
        keep = there <= here * (1 + REMOVE_TOL) if small else there < here * (1 - REMOVE_TOL)
        keep = keep and not model.leaves_path(k, path)
        if not keep:
            restore(model, kept)
        report[model.names[k]] = {"loss_before": round(here, 6), "loss_after": round(there, 6),
                                  "kept": keep, "turned_deg": round(turn, 4)}
        run.progress.log(f"{model.names[k]}: refined on the depth (axis turned {turn:.3f} deg, "
                         f"image loss {here:.5f} -> {there:.5f}); "
                         f"{'kept' if keep else 'dropped'}")
    return report
