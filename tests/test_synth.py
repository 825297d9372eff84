"""Synthetic objects (`artgs synth`): ground truth against PyBullet, rendered depth against the
geometry, interaction states, determinism, capture loading and the command line."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pybullet as p
import pytest
import trimesh
import yourdfpy

from artgs.core.model.capture import load_capture
from artgs.core.cli import main
from artgs.core.model.categories import CATEGORIES
from artgs.core.model.joints import read_articulation
from artgs.core.synth.generate import generate_object, generate_set
from artgs.core.synth.layouts import random_spec
from artgs.core.synth.objects import box_distance

SMALL = dict(width=64, height=48, static_views=4, steps=3, simultaneous=True)


@pytest.fixture(scope="module")
def objects(tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("synth")
    return {c: generate_object(root / c, c, seed=3, **SMALL) for c in CATEGORIES}


def _posed_boxes(capture_dir: Path, time: int | None):
    """The object's boxes posed by the joints and states of gt.json (time None = closed)."""
    gt = read_articulation(capture_dir / "gt.json")
    spec = random_spec(gt.meta["category"], gt.meta["seed"])
    by_child = {j.child: j for j in gt.joints}
    boxes = []
    for T, half, link in spec.boxes_at():
        if link != "base" and time is not None:
            T = by_child[link].transform(by_child[link].states[time]) @ T
        boxes.append((T, half, link))
    return boxes


def _all_open(gt) -> int:
    """The time at which every joint has just opened fully (before any simultaneous segment)."""
    return SMALL["steps"] * len(gt.joints)


@pytest.mark.parametrize("category", CATEGORIES)
def test_gt_joints_match_pybullet(objects, category):
    """gt.json axis, origin and limits equal PyBullet's joint frames of gt.urdf, also when moved."""
    root = objects[category]
    gt = read_articulation(root / "gt.json")
    assert gt.meta["category"] == category and gt.joints
    cid = p.connect(p.DIRECT)
    try:
        body = p.loadURDF(str(root / "gt.urdf"), useFixedBase=True, physicsClientId=cid)
        index = {p.getJointInfo(body, j, physicsClientId=cid)[1].decode(): j
                 for j in range(p.getNumJoints(body, physicsClientId=cid))}
        closed = {}
        for joint in gt.joints:
            info = p.getJointInfo(body, index[joint.name], physicsClientId=cid)
            assert info[2] == {"revolute": p.JOINT_REVOLUTE, "prismatic": p.JOINT_PRISMATIC}[joint.type]
            assert info[12].decode() == joint.child
            assert info[8] == pytest.approx(joint.limit[0], abs=1e-9)
            assert info[9] == pytest.approx(joint.limit[1], abs=1e-6)
            pos, orn = p.getLinkState(body, index[joint.name], physicsClientId=cid)[4:6]
            R = np.array(p.getMatrixFromQuaternion(orn)).reshape(3, 3)
            axis = R @ np.array(info[13])
            np.testing.assert_allclose(axis, joint.axis, atol=1e-6)
            offset = joint.origin - np.array(pos)
            assert np.linalg.norm(offset - (offset @ axis) * axis) < 1e-6
            closed[joint.name] = (np.array(pos), R)
        # with every joint open, each link frame moved exactly by Joint.transform(state)
        t_last = _all_open(gt)
        for joint in gt.joints:
            p.resetJointState(body, index[joint.name], joint.states[t_last], physicsClientId=cid)
        for joint in gt.joints:
            pos, orn = p.getLinkState(body, index[joint.name], physicsClientId=cid)[4:6]
            T = joint.transform(joint.states[t_last])
            pos0, R0 = closed[joint.name]
            np.testing.assert_allclose(np.array(pos), T[:3, :3] @ pos0 + T[:3, 3], atol=1e-6)
            R = np.array(p.getMatrixFromQuaternion(orn)).reshape(3, 3)
            np.testing.assert_allclose(R, T[:3, :3] @ R0, atol=1e-6)
    finally:
        p.disconnect(cid)


@pytest.mark.parametrize("category", CATEGORIES)
def test_depth_lies_on_geometry_at_gt_states(objects, category):
    """Every back-projected depth pixel lies within 5 mm of the boxes posed by gt.json; masks equal
    depth > 0; static views and time 0 hold the whole object; wrong states would be detected."""
    root = objects[category]
    capture = load_capture(root)
    gt = read_articulation(root / "gt.json")
    assert len(capture.static) == SMALL["static_views"]
    assert capture.times == sorted(gt.joints[0].states)
    moved = 0
    for frame in capture.frames:
        assert frame.mask.any()
        np.testing.assert_array_equal(frame.mask, frame.depth > 0)
        if frame.phase == "static" or frame.time == 0:      # the closed object is wholly in view
            m = frame.mask
            assert not (m[0].any() or m[-1].any() or m[:, 0].any() or m[:, -1].any())
        boxes = _posed_boxes(root, frame.time)
        points, _ = frame.camera.backproject(frame.depth)
        assert box_distance(points, boxes).max() < 5e-3, frame.file_path
        if frame.time == _all_open(gt):
            moved += 1
            wrong = [(T, h, l) for T, h, l in _posed_boxes(root, None)]
            assert box_distance(points, wrong).max() > 2e-2, "closed pose must not explain open frame"
    assert moved == 2


def test_urdf_geometry_matches_spec_in_yourdfpy(objects):
    """gt.urdf read by yourdfpy at the gt states gives the rendered surfaces (independent of the spec)."""
    root = objects["cabinet"]
    gt = read_articulation(root / "gt.json")
    capture = load_capture(root)
    t = _all_open(gt)
    robot = yourdfpy.URDF.load(str(root / "gt.urdf"))
    robot.update_cfg({j.name: j.states[t] for j in gt.joints})
    mesh = robot.scene.to_mesh() if hasattr(robot.scene, "to_mesh") else robot.scene.dump(concatenate=True)
    for frame in capture.interaction:
        if frame.time != t:
            continue
        points, _ = frame.camera.backproject(frame.depth)
        _, dist, _ = trimesh.proximity.closest_point(mesh, points)
        assert dist.max() < 5e-3


def test_interaction_schedule(objects):
    """Time 0 is closed, joints open one after another to their upper limit and stay open; the
    simultaneous segment moves two joints at every step; both cameras share every time."""
    for category, root in objects.items():
        gt = read_articulation(root / "gt.json")
        steps, n = SMALL["steps"], len(gt.joints)
        times = sorted(gt.joints[0].states)
        simultaneous = steps if n >= 2 else 0
        assert times == list(range(1 + steps * n + simultaneous))
        values = np.array([[j.states[t] for j in gt.joints] for t in times])
        assert np.all(values[0] == 0)
        for k, joint in enumerate(gt.joints):
            seg = values[1 + k * steps: 1 + (k + 1) * steps]
            np.testing.assert_allclose(seg[:, k], joint.limit[1] * np.arange(1, steps + 1) / steps)
            assert joint.limit[1] > 0.2
        if simultaneous:
            last = values[-steps - 1:]
            assert np.all(np.abs(np.diff(last[:, :2], axis=0)) > 1e-3)
        transforms = json.loads((root / "transforms.json").read_text())
        per_time = {}
        for f in transforms["frames"]:
            if f["phase"] == "interaction":
                per_time.setdefault(f["time"], []).append(f["transform_matrix"])
        assert sorted(per_time) == times
        cams = {json.dumps(m) for ms in per_time.values() for m in ms}
        assert all(len(ms) == 2 for ms in per_time.values()) and len(cams) == 2


def test_determinism(tmp_path):
    """Same seed -> byte-identical files; another seed -> another object."""
    opts = dict(width=48, height=32, static_views=3, steps=2, depth_noise=0.005)
    a = generate_object(tmp_path / "a", "cabinet", 7, **opts)
    b = generate_object(tmp_path / "b", "cabinet", 7, **opts)
    c = generate_object(tmp_path / "c", "cabinet", 8, **opts)
    files = sorted(q.relative_to(a) for q in a.rglob("*") if q.is_file())
    assert len(files) == 3 + 3 * (3 + 2 * (1 + 2 * 2))
    for rel in files:
        assert (a / rel).read_bytes() == (b / rel).read_bytes(), rel
    assert (a / "gt.json").read_bytes() != (c / "gt.json").read_bytes()


def test_depth_noise(tmp_path):
    """--depth-noise adds zero-mean Gaussian noise of that std-dev on object pixels only."""
    clean = load_capture(generate_object(tmp_path / "clean", "storage", 1, width=64, height=48,
                                         static_views=2, steps=1))
    noisy = load_capture(generate_object(tmp_path / "noisy", "storage", 1, width=64, height=48,
                                         static_views=2, steps=1, depth_noise=0.01))
    diffs = []
    for fc, fn in zip(clean.frames, noisy.frames):
        np.testing.assert_array_equal(fc.rgb, fn.rgb)
        np.testing.assert_array_equal(fc.depth == 0, fn.depth == 0)
        diffs.append((fn.depth - fc.depth)[fc.mask])
    d = np.concatenate(diffs)
    assert abs(d.mean()) < 1e-3 and 0.009 < d.std() < 0.011


def test_command_line(tmp_path):
    """`artgs synth` writes <category>_<kk> folders with object seeds 1000*seed+kk, refuses to
    overwrite a folder that is not a synthetic capture, and refuses bad options."""
    out = tmp_path / "set"
    argv = ["synth", str(out), "--category", "drawer", "--category", "oven", "--per-category", "2",
            "--seed", "4", "--width", "32", "--height", "24", "--static-views", "2", "--steps", "1",
            "--quiet"]
    assert main(argv) == 0
    assert sorted(q.name for q in out.iterdir()) == ["drawer_00", "drawer_01", "oven_00", "oven_01"]
    assert read_articulation(out / "oven_01" / "gt.json").meta == {"category": "oven", "seed": 4001}
    before = (out / "oven_01" / "transforms.json").read_bytes()
    assert main(argv) == 0                         # an earlier synthetic capture is replaced
    assert (out / "oven_01" / "transforms.json").read_bytes() == before
    assert not [q for q in out.iterdir() if q.name.startswith(".")]

    foreign = tmp_path / "other" / "oven_00"
    foreign.mkdir(parents=True)
    (foreign / "notes.txt").write_text("keep me")
    assert main(["synth", str(tmp_path / "other"), "--category", "oven", "--quiet"]) == 2
    assert (foreign / "notes.txt").read_text() == "keep me"
    assert main(["synth", str(tmp_path / "bad"), "--steps", "0", "--quiet"]) == 2
    assert not (tmp_path / "bad").exists()
    paths = generate_set(tmp_path / "api", ["microwave"], 1, 0, width=32, height=24,
                         static_views=1, steps=1)
    assert paths == [tmp_path / "api" / "microwave_00"]


def test_collision_shapes_and_handles(objects):
    """gt.urdf has collision boxes: a ray along each joint's handle approach hits that joint's child
    link at the handle (what a grasp in the manipulation metric relies on)."""
    for category, root in objects.items():
        gt = read_articulation(root / "gt.json")
        cid = p.connect(p.DIRECT)
        try:
            body = p.loadURDF(str(root / "gt.urdf"), useFixedBase=True, physicsClientId=cid)
            links = {p.getJointInfo(body, j, physicsClientId=cid)[12].decode(): j
                     for j in range(p.getNumJoints(body, physicsClientId=cid))}
            for joint in gt.joints:
                point, approach = np.array(joint.handle["point"]), np.array(joint.handle["approach"])
                hit = p.rayTest((point - 0.5 * approach).tolist(), (point + 0.1 * approach).tolist(),
                                physicsClientId=cid)[0]
                assert hit[0] == body and hit[1] == links[joint.child], (category, joint.name)
                assert np.linalg.norm(np.array(hit[3]) - point) < 0.02
        finally:
            p.disconnect(cid)
