"""Joints square to the body, beyond the paper: a hinge or slide along the body's box when the
frames cannot tell the two apart.

Near the true joint the image loss is flat (README, "Optimisation"): on 160x120 frames of a part
opened 10 degrees, a hinge 7 degrees off explains the frames to within 0.1 % of the true one
(PartNet dishwasher 12428), so the fit ends anywhere along that valley. The parts of furniture
and appliances move along their body's box: a door turns about a vertical or horizontal edge, a
drawer slides out square to the front. So each unlocked joint is tried along the nearest
direction of the body's box (:func:`core.geometry.rectangle.upright_axes`: the cameras' up and
the sides of the body's smallest footprint), within ``MAX_TURN`` degrees of the fit. The fit and
the squared joint get the same treatment: point and states fitted again for the same steps on
the same draws of times, axis and part brightness held (a converged fit refitted with its
brightness free rose 2.5 % in image loss on a PartNet box: Adam's first steps are about the
learning rate whatever the gradient). The squared joint is kept unless the frames where the
part moves say it is worse: its image loss there higher by more than ``REMOVE_TOL`` (the
resolution of the evaluation) and consistently so (paired t over those frames above
``SIGNIFICANT``, as :func:`.hypotheses.clearly_better` judges a part's gain), or higher by
``CLEARLY_WORSE`` whatever the spread. The image loss still decides; the body's box only breaks
its ties. A joint the frames place off the body's box (a lid hinged on a slant) keeps its fit
as soon as the frames tell the two apart.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ...geometry.rectangle import upright_axes
from ...geometry.separate import camera_up
from ...model.capture import Capture
from .hypotheses import (REMOVE_TOL, SIGNIFICANT, moving_frames, paired_t, part_points,
                         refits_alike)
from .kinematics import REVOLUTE
from .model import farther, restore, snapshot

#: Fits further than this (degrees) from every direction of the body's box are left as they are.
MAX_TURN = 30.0
#: A squared joint whose image loss is higher by this share is worse however few frames show it
#: (over a handful of frames the paired t statistic has little power: a door turned 12 degrees
#: off, +5.5 % over 6 frames of a 64x48 capture, gives t = 2.1).
CLEARLY_WORSE = 0.01


def body_axes(run, capture: Capture) -> np.ndarray:
    """The directions of the body's box (rows): :func:`upright_axes` of the base's Gaussians,
    up from the capture's cameras (:func:`core.geometry.separate.camera_up`)."""
    cameras = np.array([f.camera.c2w for f in capture.frames])
    base = run.model.splat.means.cpu().numpy()[run.model.labels() == 0]
    return upright_axes(base, camera_up(cameras))


def nearest_axis(axis: np.ndarray, axes: np.ndarray) -> tuple[np.ndarray, float]:
    """Of ``axes`` (rows), the one nearest to ``axis`` in direction, signed like it, and the
    angle between them (degrees)."""
    cos = axes @ axis
    i = int(np.argmax(np.abs(cos)))
    return axes[i] * np.sign(cos[i] or 1.0), float(np.degrees(np.arccos(min(abs(cos[i]), 1.0))))


def square_to_body(run, capture: Capture, fixed: list[bool], steps: int
                   ) -> dict[str, dict[str, Any]]:
    """Try every joint not ``fixed`` along the body's box (module doc), refitting its point and
    states for ``steps`` steps; returns per tried joint the turn (degrees), the image loss over
    its moving frames of the refitted fit and of the squared joint, and whether the squared
    joint was kept."""
    model, frames = run.model, run.frames
    axes = body_axes(run, capture)
    report: dict[str, dict[str, Any]] = {}
    for k in range(model.k):
        run.progress.check_cancel()
        ids = moving_frames(model, frames, k)
        if fixed[k] or not ids:
            continue
        axis, origin = (line[k] for line in model.joint_lines())
        target, turn = nearest_axis(axis, axes)
        if turn > MAX_TURN or turn < 1e-3:
            continue
        fitted = snapshot(model)
        times = sorted({frames.time_index[i] for i in ids})
        centre = part_points(model, k).mean(0)    # the line turns about its point nearest the part
        point = origin + ((centre - origin) @ axis) * axis if model.types[k] == REVOLUTE else origin
        losses, states, paths = zip(*refits_alike(
            run, k, [(axis, point), (target, point)], steps,
            f"{model.names[k]} along the body's box", subset=ids, times=times, lr_scale=0.3,
            hold=("axes", "gains")))
        t = paired_t(losses[1] - losses[0])
        rise = float(losses[1].mean() / losses[0].mean()) - 1.0
        worse = rise > CLEARLY_WORSE or (rise > REMOVE_TOL and t > SIGNIFICANT) \
            or farther(paths[1], paths[0], model.size)
        restore(model, fitted if worse else states[1])
        fit, squared = float(losses[0].mean()), float(losses[1].mean())
        report[model.names[k]] = {"turned_deg": round(turn, 3), "loss_fit": round(fit, 6),
                                  "loss_squared": round(squared, 6), "t": round(t, 3),
                                  "kept": not worse, "fit_axis": [round(float(x), 6) for x in axis]}
        run.progress.log(f"{model.names[k]}: along the body's box (turned {turn:.2f} deg) the "
                         f"image loss is {squared:.5f} (the fit, refitted alike: {fit:.5f}; "
                         f"paired t {t:.2f}); {'the fit stays' if worse else 'kept'}")
    return report
