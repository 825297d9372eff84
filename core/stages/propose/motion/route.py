"""The motion route: joints of the parts that move in the interaction frames (see the package
docstring for the steps)."""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from ....model.capture import Capture
from ....model.joints import Joint
from ....model.progress import QUIET, Progress
from ....geometry.consistency import unsupported
from ....geometry.rigid import StepData, by_motion, fit_both
from .assemble import choose_type, finite, make_joint, snap_to_front, view_meta
from .cameras import InteractionView, make_views, pooled_views, step_cloud
from .change import mark_changed, moving_at, vanish_times
from .config import MotionConfig
from .parts import group_parts
from .track import track_part, visible_filter


def propose_motion(capture: Capture, splat_means: np.ndarray, splat_opacity: np.ndarray,
                   render_depth, progress: Progress = QUIET,
                   config: MotionConfig | None = None, robot_depth=None
                   ) -> tuple[list[Joint], dict[str, Any]]:
    """Joints of the parts that move in ``capture``'s interaction frames.

    ``splat_means`` (N,3) and ``splat_opacity`` (N,) (0..1) are the static splat's Gaussians;
    ``render_depth(camera) -> (H,W)`` renders the splat's depth (used only for cameras without a
    time-0 frame); ``robot_depth(frame) -> (H,W) | None`` the robot twin's depth in a frame
    (core/stages/robot_twin.py; None: no twin). Returns the joints (source ``motion``) and meta
    with per-part diagnostics.
    """
    cfg = config or MotionConfig()
    times = capture.times
    progress.update("propose", 0.02, "closed state per interaction camera")
    pts = np.asarray(splat_means, float)[np.asarray(splat_opacity) >= cfg.min_opacity]
    spacing = float(np.median(cKDTree(pts).query(pts, k=2)[0][:, 1])) if len(pts) > 1 else 0.01
    pts = pts[~unsupported(pts, capture.static, max(cfg.min_threshold, 1.5 * spacing),
                           cfg.noise_sigmas)]
    min_points = max(cfg.min_part_points, int(cfg.min_part_fraction * len(pts)))

    def moving_parts(views: list[InteractionView]):
        mark_changed(views, pts, spacing)
        first, count, earliest = vanish_times(pts, views, times, spacing)
        first[count < 2] = -1
        return first, group_parts(pts, first, moving_at(pts, views, times), times,
                                  cfg.link_pixels * spacing, min_points, earliest=earliest)

    views = make_views(capture, render_depth, cfg, robot_depth)
    if cfg.pool > 1:
        views = pooled_views(views, cfg, cfg.pool)
    first, parts = moving_parts(views)
    if not parts and cfg.pool == 0:   # single pixels too noisy (a far camera): pool depth
        progress.update("propose", 0.05, "no part seen in single pixels; pooling depth")
        views = pooled_views(views, cfg)
        first, parts = moving_parts(views)
    progress.update("propose", 0.1, f"{len(parts)} moving part(s)", parts=len(parts))

    clouds = {}
    for t in times:
        P, N, moved = step_cloud(views, t)
        clouds[t] = (P, N, cKDTree(P), moved)
    rng = np.random.default_rng(0)
    joints: list[Joint] = []
    diagnostics = []
    for k, idx in enumerate(parts):
        S = pts[idx]
        St = S[rng.choice(len(S), cfg.track_points, replace=False)] \
            if len(S) > cfg.track_points else S
        start = int(np.min(first[idx]))
        track = track_part(St, views, times, start, clouds, cfg)
        moving = [t for t in times if t >= start]
        weights = np.array([max(track.score[t], 0.05) for t in moving])
        both = fit_both(St, [track.transforms[t] for t in moving], weights)
        rule = by_motion(*both, cfg.min_angle_deg, cfg.min_rms_ratio)
        steps = [StepData(*clouds[t][:3], visible_filter(views, t)) for t in moving]
        thr = float(np.median([v.threshold for v in views]))
        fit, other, scores = choose_type(rule, both, St, steps, views, moving, thr, cfg)
        snapped = None
        if fit.type == "prismatic":
            fit, snapped = snap_to_front(fit, S, cfg.front_snap_deg)
        else:
            other = snap_to_front(other, S, cfg.front_snap_deg)[0]
        def states(f) -> dict[int, float]:
            """The fit's value at every time (closed before the part starts moving)."""
            return {**{t: 0.0 for t in times if t < start},
                    **{t: float(v) for t, v in zip(moving, f.values)}}

        joint = make_joint(k, fit, states(fit), moving, S, track, views, clouds)
        joint.extra["alternative"] = {
            "type": other.type, "axis": [float(x) for x in other.axis],
            "origin": [float(x) for x in other.origin],
            "states": {str(t): v for t, v in states(other).items()}}
        joints.append(joint)
        diagnostics.append({"name": joint.name, "points": int(len(S)), "first_step": start,
                            "rms_revolute_mm": finite(1000 * fit.rms_revolute),
                            "rms_prismatic_mm": finite(1000 * fit.rms_prismatic),
                            "max_angle_deg": finite(fit.max_angle_deg),
                            "score_revolute": finite(scores["revolute"]),
                            "score_prismatic": finite(scores["prismatic"]),
                            "type_by": "motion" if fit.type == rule.type else "depth",
                            "snapped_to_front_deg": snapped,
                            "score_min": finite(min(track.score[t] for t in moving)),
                            "icp_rms_mm": finite(1000 * np.median([track.rms[t]
                                                                    for t in moving]))})
        progress.update("propose", 0.1 + 0.9 * (k + 1) / len(parts), f"part {k + 1}: {joint.type}")
    meta = {"method": "motion",
            "view": view_meta(views[0]) if views else None,
            "cameras": [{"name": v.name, "closed_state": v.ref_source, "pool": v.pool,
                         "threshold_mm": 1000 * v.threshold,
                         "closed_state_threshold_mm": 1000 * v.ref_threshold} for v in views],
            "motion": diagnostics}
    if not joints:
        meta["nothing_seen"] = nothing_seen(views, min_points, cfg)
    return joints, meta


def nothing_seen(views: list[InteractionView], min_points: int, cfg: MotionConfig) -> str:
    """Why the route saw no part, for the user: the change thresholds the depth noise set per
    camera (far cameras measure with centimetres of noise, and a part that moves less than
    the threshold in depth is not seen; a realistic cabinet at 6 m gave 54 and 67 cm in single
    pixels)."""
    def where(v: InteractionView) -> str:
        d = v.ref[v.ref > 0]
        span = f", object at {np.percentile(d, 2):.1f}-{np.percentile(d, 98):.1f} m" \
            if d.size else ""
        pool = f", median of {v.pool}x{v.pool} pixels" if v.pool > 1 else ""
        return f"{1000 * v.threshold:.0f} mm ({v.name}{span}{pool})"
    return (f"no group of {min_points} or more splat points vanished in two steps or views; the "
            f"change thresholds ({cfg.noise_sigmas:g} noise sigmas of a camera's depth "
            f"difference, at least {1000 * cfg.min_threshold:.0f} mm) were "
            + ", ".join(map(where, views))
            + ": a part that moves less than that in depth is not seen by this route")
