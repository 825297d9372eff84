"""Hinges moved onto their part's edges, late, beyond the paper: a fitted hinge's point tried
on the part's box edges once the parts are settled, kept only when the frames say it is better.

A door opened a little moves almost as if it slid, so the hinge's point trades off against the
states: a realistic oven's door opened 10 degrees was fitted on the right axis but 20 cm in
front of its true hinge, and a realistic chest's lid on the right axis 18 cm inside the chest.
The types are chosen early (:func:`.hypotheses.select_types`), when a part is still its
proposal's box; the restarts from its edges then land on other basins. With the true line
locked and only states and parts fitted, both explained the frames better (image loss 0.4848
against the fit's 0.4883; 0.3551 against 0.3649), so the evidence is there and the search
missed it. Here each unlocked revolute joint keeps its axis, its point is moved to each edge of
its final part's box that runs along the axis (:func:`.hypotheses.hinge_lines`), the edges are
scored at the time the part moves most (:func:`.hypotheses.score_all`), and the best is fitted
against the fit refitted alike (states searched again, then the same steps on the same draws
of times, the part's brightness held); the edge is kept only when it explains the frames
clearly better (:func:`.hypotheses.clearly_better`) and better in every camera's frames where
the part moves (:func:`.hypotheses.every_camera_lower`: on a 64x48 test cabinet the true
hinge lost to one 26 cm away by 1 %, won in one camera and lost in the other), does not open
the part into the body where the fit did not, and carries the robot's tool positions no worse.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .hypotheses import (clearly_better, every_camera_lower, hidden_share, hinge_lines,
                         key_time, moving_frames, off_line, paired_t, part_points, refits_alike,
                         score_all)
from .kinematics import REVOLUTE
from .model import farther, restore, snapshot
from .plausible import HIDDEN_SHARE

#: Edges further than this (degrees) from the fitted axis are no hinge of it.
MAX_TURN = 20.0
#: Lines nearer than this share of the object's size to the fit (or to each other) are one.
NEAR = 0.03


def edge_points(model, k: int) -> list[np.ndarray]:
    """Points of joint ``k``'s part's box edges that run along its fitted axis (within
    ``MAX_TURN``), each line off the fit's and the others' by more than ``NEAR`` of the size."""
    axis, origin = (line[k] for line in model.joint_lines())
    cos = np.cos(np.radians(MAX_TURN))
    points: list[np.ndarray] = [origin]
    for direction, point in hinge_lines(model, part_points(model, k)):
        if abs(direction @ axis) < cos:
            continue
        if all(off_line(point - p, axis) > NEAR * model.size for p in points):
            points.append(point)
    return points[1:]


def edge_hinges(run, fixed: list[bool], steps: int) -> dict[str, dict[str, Any]]:
    """Try every revolute joint not ``fixed`` on its part's edges (module doc), fitting point
    and states for ``steps`` steps; returns per tried joint the image loss over its moving
    frames of the fit refitted and of the best edge, the edge's distance from the fit (m), and
    whether the edge was kept."""
    model, frames = run.model, run.frames
    report: dict[str, dict[str, Any]] = {}
    for k in range(model.k):
        run.progress.check_cancel()
        ids = moving_frames(model, frames, k)
        if fixed[k] or not ids or model.types[k] != REVOLUTE:
            continue
        points = edge_points(model, k)
        if not points:
            continue
        axis, origin = (line[k] for line in model.joint_lines())
        scores = score_all(run, k, key_time(run, k), [(REVOLUTE, axis, p, None) for p in points])
        edge = points[int(np.argmin(scores))]
        fitted = snapshot(model)
        draws = run.rng.bit_generator.state
        times = sorted({frames.time_index[i] for i in ids})
        losses, states, paths = zip(*refits_alike(
            run, k, [(axis, origin), (axis, edge)], steps, f"{model.names[k]} on its part's edge",
            search=True, times=times, hold=("gains",)))
        inward = []
        for state in states:
            restore(model, state)
            inward.append(hidden_share(run, k) > HIDDEN_SHARE)
        cameras = np.array([frames.camera[i] for i in ids])
        kept = clearly_better(losses[0], losses[1], ids) and not (inward[1] and not inward[0]) \
            and every_camera_lower(losses[0][ids], losses[1][ids], cameras) \
            and not farther(paths[1], paths[0], model.size)
        moved = off_line(model.joint_lines()[1][k] - origin, axis)
        restore(model, states[1] if kept else fitted)
        if not kept:        # a refused edge leaves the run as it found it
            run.rng.bit_generator.state = draws
        fit, there = (float(x[ids].mean()) for x in losses)
        t = paired_t(losses[0][ids] - losses[1][ids])
        report[model.names[k]] = {"loss_fit": round(fit, 6), "loss_edge": round(there, 6),
                                  "t": round(t, 3), "moved_m": round(moved, 4),
                                  "into_body": inward[1], "kept": kept}
        run.progress.log(f"{model.names[k]}: hinged on its part's edge, {100 * moved:.1f} cm "
                         f"from the fit, the image loss where it moves is {there:.5f} (the fit, "
                         f"refitted alike: {fit:.5f}; paired t {t:.2f}"
                         f"{'; opens into the body' if inward[1] else ''}); "
                         f"{'kept' if kept else 'the fit stays'}")
    return report
