"""Captures with the robot in view: ``artgs synth --robot``, and the motion route through them."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from artgs.core.geometry.metrics import match_joints
from artgs.core.model.capture import load_capture
from artgs.core.model.joints import joint_transform, read_articulation
from artgs.core.stages.propose.motion.route import propose_motion
from artgs.core.stages.reconstruct import initial_splats
from artgs.core.stages.robot_twin import robot_twin, twin_depth_for_capture
from artgs.core.synth.builder import HANDLES
from artgs.core.synth.generate import generate_object
from artgs.core.synth.layouts import random_spec
from artgs.core.synth.robot import grasps

SIZE = {"width": 96, "height": 72, "static_views": 12, "steps": 6}


@pytest.fixture(scope="module")
def capture_dir(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("robot")
    os.environ.setdefault("ARTGS_CACHE", str(root / "cache"))
    return generate_object(root / "microwave", "microwave", 1, robot="franka_panda", **SIZE)


def test_synth_writes_the_robot(capture_dir):
    """transforms.json names the robot, its base pose, joint positions on interaction frames only;
    the robot is in the depth (where the mask is not) of interaction frames, and where the twin
    says it is; the gripper is at the handle; static views have no robot."""
    meta = json.loads((capture_dir / "transforms.json").read_text())
    assert meta["robot"] == "franka_panda" and np.asarray(meta["robot_base_pose"]).shape == (4, 4)
    assert meta["robot_grasp_error_mm"] < 10
    capture = load_capture(capture_dir)
    assert all(f.robot_joint_positions is None for f in capture.static)
    assert all(len(f.robot_joint_positions) == 8 for f in capture.interaction)
    for f in capture.static:
        assert not np.any((f.depth > 0) & ~f.mask)
    depth = twin_depth_for_capture(capture)
    gt = read_articulation(capture_dir / "gt.json").joints[0]
    twin = robot_twin("franka_panda")
    occluded_handle = 0
    for f in capture.interaction:
        arm = (f.depth > 0) & ~f.mask
        assert arm.sum() > 20
        tw = depth(f)
        # the twin covers the arm's pixels and its depth matches there
        both = arm & (tw > 0)
        assert both.sum() > 0.8 * arm.sum()
        assert np.median(np.abs(tw[both] - f.depth[both])) < 0.004
        assert np.sum((tw > 0) & ~arm & ~f.mask) < 0.2 * arm.sum() + 20
        # the grasp point (between the fingertips) is at the handle, which moved with the joint
        M = joint_transform(gt.type, gt.axis, gt.origin, gt.states[f.time])
        handle = M[:3, :3] @ np.asarray(gt.handle["point"]) + M[:3, 3]
        tcp = twin.link_transforms(f.robot_joint_positions, capture.robot_base_pose)[
            twin.links.index("panda_hand")]
        grasp = tcp[:3, :3] @ [0, 0, 0.105] + tcp[:3, 3]
        assert np.linalg.norm(grasp - handle) < 0.015
        uv, z = f.camera.project(handle[None])
        j, i = np.floor(uv[0]).astype(int)
        if 0 <= i < f.camera.height and 0 <= j < f.camera.width and arm[i, j] \
                and f.depth[i, j] < z[0] - 0.01:
            occluded_handle += 1
    assert occluded_handle >= 4   # the arm hides the handle in several frames


def _propose(capture, **kw):
    splat, _ = initial_splats(capture.static)
    opacity = 1 / (1 + np.exp(-splat.opacity_logits.astype(float)))
    return propose_motion(capture, splat.means, opacity, render_depth=None, **kw)[0]


def _assert_true_joint(joints, capture_dir, max_ae=3.0, max_oe=3.0):
    gt = read_articulation(capture_dir / "gt.json").joints
    assert len(joints) == len(gt)
    for s in match_joints(joints, gt):
        assert s.type_correct and s.axis_error_deg < max_ae and s.origin_error_cm < max_oe, s


def test_motion_route_through_the_arm(capture_dir):
    """The arm hides the handle and part of the door: masks exclude it, so what lies behind it is
    unknown (not free space) and the true joint is still found."""
    _assert_true_joint(_propose(load_capture(capture_dir)), capture_dir)


def test_twin_explains_the_arm_without_masks(capture_dir):
    """Without masks the arm is depth like the object's; the twin's render marks its pixels."""
    capture = load_capture(capture_dir)
    for f in capture.interaction:
        f.mask = None
    joints = _propose(capture, robot_depth=twin_depth_for_capture(capture))
    _assert_true_joint(joints, capture_dir)


def _optimise_from_perturbed(capture_dir: Path, tmp_path: Path, robot_twin: bool):
    import copy

    from artgs.core.model import layout
    from artgs.core.model.joints import Articulation, rotation_about_axis, write_articulation
    from artgs.core.model.ply import write_ply
    from artgs.core.model.progress import QUIET
    from artgs.core.model.registry import OptimiseOptions
    from artgs.core.stages.optimise.stage import optimise

    gt = read_articulation(capture_dir / "gt.json")
    start = []
    for j in gt.joints:   # 10 degrees and 4 cm off
        j = copy.deepcopy(j)
        p = np.cross(j.axis, [0.3, 0.5, 0.8])
        j.axis = rotation_about_axis(p / np.linalg.norm(p), np.radians(10.0)) @ j.axis
        j.origin = j.origin + 0.04 * np.cross(j.axis, p / np.linalg.norm(p))
        start.append(j)
    out = tmp_path / "out"
    out.mkdir()
    capture = load_capture(capture_dir)
    write_ply(out / layout.SPLAT, initial_splats(capture.static)[0])
    write_articulation(out / layout.PROPOSALS, Articulation(start, {"source": "test"}))
    optimise(out, capture, QUIET, OptimiseOptions(iterations=120, types=False, parts=False,
                                                  robot_twin=robot_twin))
    return read_articulation(out / layout.ARTICULATION).joints


def test_optimisation_with_the_arm_in_view(capture_dir, tmp_path):
    """From a start 10 degrees / 4 cm off, the optimisation renders the twin with the object and
    recovers the true joint although the arm hides the handle."""
    _assert_true_joint(_optimise_from_perturbed(capture_dir, tmp_path, True), capture_dir,
                       max_ae=3.0, max_oe=2.0)


def test_tool_path_gives_the_hinge(capture_dir):
    """The tool is at the handle at every interaction time, and its path is one run
    (one part held) that yields a hinge within 3 degrees and 2 cm of the true one, and a slide
    hypothesis; the path of two parts held one after the other splits into two runs at the
    jump. Without a path there are no such hypotheses."""
    import torch

    from artgs.core.geometry.metrics import score_pair
    from artgs.core.geometry.parts import assign_parts
    from artgs.core.model.joints import Joint
    from artgs.core.stages.optimise.frames import interaction_frames
    from artgs.core.stages.optimise.hypotheses import tool_hypotheses, tool_segments
    from artgs.core.stages.optimise.model import ArticulatedSplat, Splat
    from artgs.core.stages.robot_twin import tool_path

    capture = load_capture(capture_dir)
    gt = read_articulation(capture_dir / "gt.json").joints[0]
    path = tool_path(capture)
    assert sorted(path) == sorted({f.time for f in capture.interaction})
    for t, P in path.items():
        M = joint_transform(gt.type, gt.axis, gt.origin, gt.states[t])
        handle = M[:3, :3] @ np.asarray(gt.handle["point"]) + M[:3, 3]
        assert np.linalg.norm(P[:3, 3] - handle) < 0.015
    frames = interaction_frames(capture, torch.device("cpu"))
    splat, _ = initial_splats(capture.static)
    model = ArticulatedSplat(Splat.from_arrays(splat, torch.device("cpu")), [gt], frames.times,
                             assign_parts(splat.means, [gt]), 1.0, [False])
    assert tool_hypotheses(model, frames, 0) == []
    frames.tool = path
    hyps = tool_hypotheses(model, frames, 0)
    assert [h[0] for h in hyps] == ["revolute", "prismatic"]
    s = score_pair(Joint(name="h", type="revolute", axis=hyps[0][1], origin=hyps[0][2]), gt)
    assert s.axis_error_deg < 3.0 and s.origin_error_cm < 2.0, s
    # a second part held after a jump: the door's path, then a slide 40 cm away
    door = np.array([path[t][:3, 3] for t in sorted(path)])
    slide = door[-1] + np.array([0.4, 0.0, 0.0]) + np.outer(np.arange(5) * 0.05, [0.0, 1.0, 0.0])
    runs = tool_segments(np.concatenate([door, slide]), 0.01, 0.02, 0.05)
    assert [r.tolist() for r in runs] == [list(range(len(door))),
                                          list(range(len(door), len(door) + 5))]


@pytest.mark.parametrize("kind", HANDLES)
def test_grasp_frames_for_every_handle(kind, monkeypatch):
    """Every handle kind (a knob is deeper than it is wide; a grip recess has no box) gives
    orthonormal grasp frames at the point gt.json names as the handle."""
    import artgs.core.synth.builder as builder
    real_init = builder.Builder.__init__

    def init(self, *a, **k):
        real_init(self, *a, **k)
        self.handle_kind = kind
    monkeypatch.setattr(builder.Builder, "__init__", init)
    for category in ("cabinet", "washing_machine", "drawer"):
        spec = random_spec(category, 11, variety=True)
        joints = spec.joints()
        spec.annotate(joints)
        schedule = [{q.name: 0.0 for q in spec.parts}] + \
            [{q.name: (0.5 if i == 0 else 0.0) * q.limit[1] for i, q in enumerate(spec.parts)}]
        for G, state in zip(grasps(spec, schedule), schedule):
            assert np.allclose(G[:3, :3].T @ G[:3, :3], np.eye(3), atol=1e-9)
            j = joints[0]
            M = joint_transform(j.type, j.axis, j.origin, state[spec.parts[0].name])
            handle = M[:3, :3] @ np.asarray(j.handle["point"]) + M[:3, 3]
            assert np.linalg.norm(G[:3, 3] - handle) < 1e-9


def test_a_part_the_robot_opened_is_added_from_its_path(capture_dir, tmp_path):
    """Proposed as a slide and its type not searched: the robot's record of what it opened (a
    run of the tool path that the slide does not explain) gives the door's part and hinge,
    within the optimisation's targets on this small capture."""
    import copy

    from artgs.core.model import layout
    from artgs.core.model.joints import Articulation, write_articulation
    from artgs.core.model.ply import write_ply
    from artgs.core.model.progress import QUIET
    from artgs.core.model.registry import OptimiseOptions
    from artgs.core.stages.optimise.stage import optimise

    gt = read_articulation(capture_dir / "gt.json").joints
    slide = copy.deepcopy(gt[0])
    slide.type, slide.states = "prismatic", {}
    slide.axis = -np.asarray(gt[0].handle["approach"], float)     # pulled towards the robot
    out = tmp_path / "out"
    out.mkdir()
    capture = load_capture(capture_dir)
    write_ply(out / layout.SPLAT, initial_splats(capture.static)[0])
    write_articulation(out / layout.PROPOSALS, Articulation([slide], {"source": "test"}))
    optimise(out, capture, QUIET, OptimiseOptions(iterations=120, types=False, robot_twin=True))
    joints = read_articulation(out / layout.ARTICULATION).joints
    s = match_joints(joints, gt)[0]
    assert s.type_correct and s.axis_error_deg < 3.0 and s.origin_error_cm < 2.0, s
