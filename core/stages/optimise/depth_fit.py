"""The joints' last refinement on the interaction frames' depth, beyond the paper.

Near the true joint the image loss is flat: on 160x120 frames a joint 0.5 degrees off changes the
mean loss by 1e-6 to 1e-3 relative, so the rendering fit wanders along a valley (README,
"Optimisation"). The depth maps resolve it: every measured pixel of the part is a point the part's
surface must pass through. Each joint is refined by point-to-plane least squares of its part's
canonical Gaussians, placed by the joint at every time it moves, against the measured points of
those times (:func:`core.geometry.rigid.refine_joint`, the motion route's refinement, with its
clouds, thresholds and visibility filter: core/stages/propose/motion), from the fitted axis, line,
states and parts. The refined joint is kept unless it explains the frames where the part moves
worse by more than the evaluation's resolution (``REMOVE_TOL``): the image loss keeps the
decisions (type, part, which line), the depth sets the last decimals.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ...geometry.rigid import JointFit, StepData
from ...model.capture import Capture
from ..propose.motion.assemble import refine_on_steps
from ..propose.motion.cameras import make_views, step_cloud
from ..propose.motion.config import MotionConfig
from ..propose.motion.track import visible_filter
from ..propose.stage import splat_depth, twin_depth
from .fit import evaluate
from .hypotheses import REMOVE_TOL, moving_frames, part_points
from .kinematics import REVOLUTE
from .model import restore, snapshot

#: A refinement that turns the axis further (degrees) or moves a hinge line further (x object
#: size) is another joint, not the last decimals: it must lower the image loss to be kept.
MAX_TURN = 2.0
MAX_SHIFT = 0.02


def refine_on_depth(run, capture: Capture, arrays, config: MotionConfig | None = None
                    ) -> dict[str, dict[str, float]]:
    """Refine every unlocked joint on the depth (module doc); returns per joint the image loss
    over its moving frames before and after and whether the refinement was kept."""
    model, frames, cfg, options = run.model, run.frames, run.cfg, run.options
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
        axis = model.joint_axes()[k].detach().cpu().numpy().astype(float)
        origin = model.joint_origins()[k].detach().cpu().numpy().astype(float)
        start = JointFit(model.types[k], axis, origin, np.array([values[t] for t in moving]),
                         np.nan, np.nan, 0.0)
        new = refine_on_steps(start, pts, steps, thr, mc, mc.refine_rounds)
        here = float(evaluate(model, frames, cfg, 0, ids).mean())
        kept = snapshot(model)
        sign = 1.0 if new.axis @ axis >= 0 else -1.0    # refine_joint may flip axis and values
        refined = {t: sign * v for t, v in values.items()}
        refined.update(zip(moving, map(float, new.values)))
        model.set_type(k, model.types[k], new.axis, new.origin, refined)
        there = float(evaluate(model, frames, cfg, 0, ids).mean())
        turn = float(np.degrees(np.arccos(np.clip(abs(new.axis @ axis), -1, 1))))
        shift = float(np.linalg.norm(np.cross(new.origin - origin, axis))) \
            if model.types[k] == REVOLUTE else 0.0
        small = turn <= MAX_TURN and shift <= MAX_SHIFT * model.size
        keep = there <= here * (1 + REMOVE_TOL) if small else there < here * (1 - REMOVE_TOL)
        if not keep:
            restore(model, kept)
        report[model.names[k]] = {"loss_before": round(here, 6), "loss_after": round(there, 6),
                                  "kept": keep, "turned_deg": round(turn, 4)}
        run.progress.log(f"{model.names[k]}: refined on the depth (axis turned {turn:.3f} deg, "
                         f"image loss {here:.5f} -> {there:.5f}); "
                         f"{'kept' if keep else 'dropped'}")
    return report
