"""``artgs check OUT``: a robot opens every part of a URDF along the ESTIMATED joints (PyBullet).

The URDF operated is OUT/model.urdf (does our own model hold together?) or ``--urdf`` (e.g. a
ground-truth ``gt.urdf``: the benchmark). The plan comes from OUT's joints (articulation.json, else
proposals.json), each with its ``handle`` (grasp point and approach direction). Estimated joints are
paired with the URDF's movable joints by name when all names agree, else by the metrics' one-to-one
matching (core/geometry/metrics.py). Per joint the outcome goes to report.json; ``check.png`` holds
one row of frames per joint.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ...geometry.metrics import match_joints
from ...model import atomic, layout
from ...model.capture import Capture
from ...model.errors import InputError
from ...model.joints import Joint, read_articulation
from ...model.progress import Progress
from ...model.registry import CheckOptions
from ...sim.manipulate import Task, run_episode, world_joints
from ...sim.urdf import sanitize_name


def run(out: Path, capture: Capture | None, options: CheckOptions, progress: Progress
        ) -> dict[str, Any]:
    """Run one episode per joint of the URDF; write the strip; return per-joint results."""
    urdf = Path(options.urdf) if options.urdf else out / layout.URDF
    if not urdf.is_file():
        hint = "" if options.urdf else "; run `artgs export` first"
        raise InputError(urdf, f"not found{hint}", field="urdf")
    joints_path = layout.joints_file(out)
    estimated = read_articulation(joints_path).joints
    truth = urdf_joints(urdf)
    pairs = pair_joints(estimated, truth)
    for est in estimated:
        if est.handle is None:
            raise InputError(joints_path, "needs a 'handle' (grasp point and approach) to plan "
                             "the grasp", frame=est.name, field="handle")
    results, rows = {}, []
    for k, (true_name, est) in enumerate(pairs.items()):
        progress.check_cancel()
        progress.update("check", k / max(len(pairs), 1), f"opening {true_name}")
        if est is None:
            results[true_name] = {"success": False, "reason": "no estimated joint for this part"}
            continue
        task = Task(true_name, est, np.asarray(est.handle["point"], float),
                    np.asarray(est.handle["approach"], float))
        outcome = run_episode(str(urdf), task, options.robot, options.frames)
        results[true_name] = {**outcome.to_dict(), "estimated_joint": est.name}
        rows.append(outcome.frames)
    if rows:
        write_strip(out / layout.CHECK_STRIP, rows)
    wins = sum(bool(r["success"]) for r in results.values())
    return {"urdf": str(urdf), "robot": options.robot, "joints_file": joints_path.name,
            "joints": results, "success_rate": wins / max(len(results), 1),
            "strip": layout.CHECK_STRIP if rows else None}


def urdf_joints(urdf: Path) -> dict[str, Joint]:
    """The URDF's revolute/prismatic joints in the world frame at zero state (PyBullet)."""
    import pybullet as p

    client = p.connect(p.DIRECT)
    try:
        try:
            body = p.loadURDF(str(urdf), useFixedBase=True, physicsClientId=client)
        except p.error as exc:
            raise InputError(urdf, f"PyBullet cannot load it ({exc})") from exc
        return world_joints(body, client)
    finally:
        p.disconnect(client)


def pair_joints(estimated: list[Joint], truth: dict[str, Joint]) -> dict[str, Joint | None]:
    """For every URDF joint, the estimated joint that plans its motion (None if unmatched)."""
    by_name = {sanitize_name(j.name): j for j in estimated}
    if set(truth) <= set(by_name):
        return {name: by_name[name] for name in truth}
    scores = match_joints(estimated, list(truth.values()))
    named = {j.name: j for j in estimated}
    return {s.true_name: named.get(s.pred_name) if s.pred_name else None for s in scores}


def write_strip(path: Path, rows: list[list[np.ndarray]]) -> None:
    """One row of frames per joint (blank where an episode made none), as PNG."""
    import cv2

    frames = [f for row in rows for f in row]
    if not frames:
        return
    h, w = frames[0].shape[:2]
    width = max(len(r) for r in rows)
    blank = np.full((h, w, 3), 255, np.uint8)
    image = np.concatenate([np.concatenate(list(r) + [blank] * (width - len(r)), axis=1)
                            for r in rows], axis=0)
    ok, data = cv2.imencode(".png", image[:, :, ::-1])
    if ok:
        atomic.write_bytes(path, data.tobytes())
