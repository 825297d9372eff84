"""`artgs synth` beyond the tight regime: URDF assets rendered into captures (ground truth against
PyBullet), and each realism option of the realistic regime (depth noise, missing depth, flying
pixels, masks, camera distances, no masks, room, determinism). No PartNet files: the asset is a
small URDF written here."""

from __future__ import annotations

import json
import math
from pathlib import Path

import cv2
import numpy as np
import pybullet as p
import pytest
import trimesh

from artgs.core.bench.sets import category_table, Column, parse_set
from artgs.core.model.capture import load_capture
from artgs.core.model.cameras import Camera
from artgs.core.model.errors import InputError
from artgs.core.model.joints import read_articulation
from artgs.core.model.regime import regime
from artgs.core.sim.client import Scene
from artgs.core.synth import sensor
from artgs.core.synth.generate import FOCAL_FACTOR, framing, generate_asset, generate_object
from artgs.core.synth.layouts import random_spec

TINY = dict(width=64, height=48, static_views=3, steps=2)


# ----------------------------------------------------------------------------- a URDF asset

def _cube_obj(path: Path, size, centre) -> None:
    mesh = trimesh.creation.box(extents=size)
    mesh.apply_translation(centre)
    path.parent.mkdir(parents=True, exist_ok=True)
    mesh.export(path)


@pytest.fixture(scope="module")
def asset(tmp_path_factory) -> Path:
    """A PartNet-like asset: y-up meshes turned z-up by the root joint, front towards -x; a door
    whose range is negative (opens towards the lower limit), a drawer closed at its lower limit
    0.05, a small knob on the door (skipped by the rule), a continuous wheel (skipped)."""
    root = tmp_path_factory.mktemp("asset") / "cabinet" / "4711"
    objs = root / "textured_objs"
    # link frames are at the asset origin as in PartNet; meshes placed by visual origins
    _cube_obj(objs / "body.obj", (0.8, 1.0, 0.6), (0.0, 0.0, 0.0))      # y-up: 1.0 high
    _cube_obj(objs / "door.obj", (0.38, 0.9, 0.03), (0.0, 0.0, 0.0))
    _cube_obj(objs / "drawer.obj", (0.36, 0.2, 0.5), (0.0, 0.0, 0.0))
    _cube_obj(objs / "knob.obj", (0.03, 0.03, 0.03), (0.0, 0.0, 0.0))
    urdf_text = f"""<?xml version="1.0"?>
<robot name="test_asset">
  <link name="base"/>
  <link name="link_body"><visual><origin xyz="0 0 0"/><geometry><mesh filename="textured_objs/body.obj"/></geometry></visual>
    <collision><origin xyz="0 0 0"/><geometry><mesh filename="textured_objs/body.obj"/></geometry></collision></link>
  <link name="link_door"><visual><origin xyz="-0.19 0 0.015"/><geometry><mesh filename="textured_objs/door.obj"/></geometry></visual></link>
  <link name="link_drawer"><visual><origin xyz="0.2 0.3 -0.25"/><geometry><mesh filename="textured_objs/drawer.obj"/></geometry></visual></link>
  <link name="link_knob"><visual><origin xyz="0 0 0.02"/><geometry><mesh filename="textured_objs/knob.obj"/></geometry></visual></link>
  <link name="link_wheel"><visual><origin xyz="0 0 0"/><geometry><mesh filename="textured_objs/drawer.obj" scale="0.2 0.2 0.2"/></geometry></visual></link>
  <joint name="joint_root" type="fixed"><parent link="base"/><child link="link_body"/>
    <origin rpy="1.570796326794897 0 -1.570796326794897" xyz="0 0 0"/></joint>
  <joint name="joint_door" type="revolute"><parent link="link_body"/><child link="link_door"/>
    <origin xyz="0.0 -0.05 0.3" rpy="0 0.1 0"/><axis xyz="0 1 0"/><limit lower="-1.4" upper="0.0"/></joint>
  <joint name="joint_drawer" type="prismatic"><parent link="link_body"/><child link="link_drawer"/>
    <origin xyz="0 0 0.05"/><axis xyz="0 0 1"/><limit lower="0.05" upper="0.4"/></joint>
  <joint name="joint_knob" type="revolute"><parent link="link_door"/><child link="link_knob"/>
    <origin xyz="-0.33 0.1 0.03"/><axis xyz="0 0 1"/><limit lower="0" upper="3.0"/></joint>
  <joint name="joint_wheel" type="continuous"><parent link="link_body"/><child link="link_wheel"/>
    <origin xyz="0.3 -0.4 0.2"/><axis xyz="1 0 0"/></joint>
</robot>
"""
    (root / "mobility.urdf").write_text(urdf_text)
    return root / "mobility.urdf"


@pytest.fixture(scope="module")
def asset_capture(asset, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("asset_cap") / "cabinet_4711"
    return generate_asset(out, asset, 3, size=0.9, regime=regime("realistic", room=False), **TINY)


def test_asset_joint_rule_and_size(asset_capture):
    """The door and drawer open parts; the knob (small) and the wheel (continuous) do not. The
    object is scaled to the requested size and stands on z = 0."""
    gt = read_articulation(asset_capture / "gt.json")
    assert [j.name for j in gt.joints] == ["joint_door", "joint_drawer"]
    door, drawer = gt.joints
    assert door.type == "revolute" and door.limit == pytest.approx((0.0, 1.4))
    assert drawer.type == "prismatic"
    scale = gt.meta["scale"]
    assert drawer.limit == pytest.approx((0.0, 0.35 * scale))       # closed at its lower limit
    with Scene() as scene:
        body = scene.load(asset_capture / "gt.urdf")
        lo = np.full(3, np.inf)
        hi = -lo
        for link in body.links.values():
            a, b = p.getAABB(body.id, link, physicsClientId=scene.client)
            if np.isfinite(a).all() and np.ptp(np.array([a, b]), axis=0).max() > 0.01:
                lo, hi = np.minimum(lo, a), np.maximum(hi, b)
    # the body's collision AABB: 1.0 m tall in asset units -> the largest extent -> 0.9 m
    assert hi[2] - lo[2] == pytest.approx(0.9, abs=0.02)
    assert lo[2] == pytest.approx(0.0, abs=0.02)


def test_asset_gt_matches_pybullet(asset_capture):
    """gt.urdf loads in PyBullet; gt.json axes and origins are PyBullet's joint frames to 1e-6,
    also after moving every joint to its last state (the child frames move by Joint.transform)."""
    gt = read_articulation(asset_capture / "gt.json")
    with Scene() as scene:
        body = scene.load(asset_capture / "gt.urdf")
        assert set(body.joints) == {j.name for j in gt.joints}      # the others are fixed
        closed = {}
        for joint in gt.joints:
            idx = body.joints[joint.name]
            info = scene.joint_info(body, idx)
            T = scene.link_frame(body, idx)
            axis = T[:3, :3] @ np.array(info[13])
            np.testing.assert_allclose(axis, joint.axis, atol=1e-6)
            off = joint.origin - T[:3, 3]
            assert np.linalg.norm(off - (off @ axis) * axis) < 1e-6
            assert info[8] == pytest.approx(joint.limit[0], abs=1e-9)
            assert info[9] == pytest.approx(joint.limit[1], abs=1e-6)
            closed[joint.name] = T
        last = max(gt.joints[0].states)
        scene.set_states(body, {j.name: j.states[last] for j in gt.joints})
        assert any(j.states[last] > 0 for j in gt.joints)
        for joint in gt.joints:
            T = scene.link_frame(body, body.joints[joint.name])
            np.testing.assert_allclose(T, joint.transform(joint.states[last]) @ closed[joint.name],
                                       atol=1e-6)


def test_asset_rendered_depth_on_the_urdf(asset_capture):
    """Depth pixels of the (tiny) capture lie on the gt.urdf surfaces up to the sensor noise."""
    cap = load_capture(asset_capture)
    gt = read_articulation(asset_capture / "gt.json")
    with Scene() as scene:
        body = scene.load(asset_capture / "gt.urdf")
        errs = []
        for f in cap.static:
            ref = scene.render(f.camera, 0.05, 20.0)
            valid = (f.depth > 0) & (ref.body == body.id)
            errs.append(np.abs(f.depth - ref.depth)[valid])
        err = np.concatenate(errs)
        assert len(err) > 30 and np.median(err) < 0.01
    assert gt.joints[0].handle is not None and gt.joints[0].extent is not None


def test_asset_joints_override_and_errors(asset, tmp_path):
    """--joints picks the joints (even the knob); unknown names are refused before any work."""
    out = generate_asset(tmp_path / "knob", asset, 1, joints=["joint_knob"], **TINY)
    assert [j.name for j in read_articulation(out / "gt.json").joints] == ["joint_knob"]
    with pytest.raises(InputError, match="joint_nope"):
        generate_asset(tmp_path / "bad", asset, 1, joints=["joint_nope"], **TINY)
    assert not (tmp_path / "bad").exists()


# ----------------------------------------------------------------------------- realism options

def test_depth_noise_grows_with_depth_and_is_quantised():
    rng = np.random.default_rng(0)
    a, b = 0.004, 0.0015
    stds = []
    for z in (1.0, 3.0):
        plane = np.full((200, 200), z, np.float32)
        noisy = sensor.noisy_depth(plane, a, b, 0.001, rng)
        np.testing.assert_allclose(noisy * 1000, np.round(noisy * 1000), atol=1e-3)
        stds.append(float(np.std(noisy - z)))
        assert stds[-1] == pytest.approx(sensor.depth_sigma(z, a, b), rel=0.1)
    assert stds[1] > 3 * stds[0]


def test_flying_pixels_lie_between_object_and_background():
    depth = np.full((40, 40), 3.0, np.float32)
    sil = np.zeros((40, 40), bool)
    sil[10:30, 10:30] = True
    depth[sil] = 1.0
    out = sensor.flying_pixels(depth, sil, np.random.default_rng(1), p=1.0)
    changed = out != depth
    ring = cv2.dilate(sil.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool) & ~sil
    assert changed.any() and np.all(ring[changed])
    assert np.all((out[changed] > 1.0) & (out[changed] < 3.0))


@pytest.fixture(scope="module")
def realistic(tmp_path_factory) -> Path:
    """A realistic cabinet without the room, so the true silhouette can be re-rendered."""
    out = tmp_path_factory.mktemp("realistic") / "cabinet_00"
    return generate_object(out, "cabinet", 11, regime=regime("realistic", room=False), **TINY)


def _true_frames(capture_dir: Path):
    """(frame, exact render) pairs from gt.urdf at the gt states, with the capture's cameras."""
    cap = load_capture(capture_dir)
    gt = read_articulation(capture_dir / "gt.json")
    with Scene() as scene:
        body = scene.load(capture_dir / "gt.urdf")
        for f in cap.frames:
            if f.time is not None:
                scene.set_states(body, {j.name: j.states[f.time] for j in gt.joints})
            yield f, scene.render(f.camera, 0.05, 50.0), body.id


def test_masks_within_two_pixels_of_the_silhouette(realistic):
    differ = 0
    for f, ref, body in _true_frames(realistic):
        true = ref.body == body
        wrong = f.mask != true
        differ += int(wrong.any())
        if wrong.any():
            edge = cv2.morphologyEx(true.astype(np.uint8), cv2.MORPH_GRADIENT,
                                    np.ones((3, 3), np.uint8)) > 0
            dist = cv2.distanceTransform((~edge).astype(np.uint8), cv2.DIST_L2, 5)
            assert dist[wrong].max() <= 2.0 + 1e-6
    assert differ > 0                       # the masks are not the exact silhouettes


def test_missing_depth_on_edges_and_noise(realistic):
    """Depth is missing on a clear share of depth-edge pixels and rarely inside flat faces; the
    remaining depth is within a few sigma of the truth."""
    on_edge = edges = inside_missing = inside = 0
    for f, ref, body in _true_frames(realistic):
        true = np.where(ref.body == body, ref.depth, 0.0)
        e = sensor.depth_edges(true) & (true > 0)
        flat = (true > 0) & ~cv2.dilate(e.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
        flat &= ~sensor.grazing(true, f.camera) & (f.rgb.mean(axis=2) > 40)
        edges += int(e.sum())
        on_edge += int((e & (f.depth == 0)).sum())
        inside += int(flat.sum())
        inside_missing += int((flat & (f.depth == 0)).sum())
        ok = flat & (f.depth > 0)
        sigma = sensor.depth_sigma(true[ok], 0.005, 0.0015) + 0.001
        assert np.all(np.abs(f.depth[ok] - true[ok]) < 6 * sigma)
    assert on_edge > 0.3 * edges
    assert inside_missing < 0.05 * inside


def test_camera_distances_in_range(realistic):
    gt = read_articulation(realistic / "gt.json")
    spec = random_spec("cabinet", gt.meta["seed"], variety=True)
    cap = load_capture(realistic)
    w, h = cap.frames[0].camera.width, cap.frames[0].camera.height
    K = cap.frames[0].camera.K
    assert K[0, 0] == pytest.approx(FOCAL_FACTOR * w)
    centre, _, dist = framing(spec, K, w, h)
    statics = [np.linalg.norm(f.camera.center - centre) / dist for f in cap.static]
    fixed = {tuple(f.camera.center) for f in cap.interaction}
    inter = [np.linalg.norm(np.array(c) - centre) / dist for c in fixed]
    assert len(fixed) == 2
    assert all(1.0 - 1e-9 <= r <= 2.0 + 1e-9 for r in statics)
    assert all(1.2 - 1e-9 <= r <= 3.0 + 1e-9 for r in inter)
    front = spec.base_pose[:3, 0]
    for f in cap.frames:                     # every camera in the front half
        assert (f.camera.center - centre) @ front > 0


def test_no_masks_room_and_determinism(tmp_path):
    """--no-masks writes no masks; the room gives depth around the object; same seed, same bytes;
    the mixed sequence moves several joints at once."""
    reg = regime("realistic", masks=False)
    a = generate_object(tmp_path / "a", "storage", 5, regime=reg, **TINY)
    b = generate_object(tmp_path / "b", "storage", 5, regime=reg, **TINY)
    files = sorted(q.relative_to(a) for q in a.rglob("*") if q.is_file())
    assert not (a / "masks").exists()
    for rel in files:
        assert (a / rel).read_bytes() == (b / rel).read_bytes(), rel
    frames = json.loads((a / "transforms.json").read_text())["frames"]
    assert all("mask_path" not in f for f in frames)
    cap = load_capture(a)
    assert all(f.mask is None for f in cap.frames)
    # the floor and walls have depth: far more pixels than the object's
    assert np.mean([np.mean(f.depth > 0) for f in cap.static]) > 0.5
    gt = read_articulation(a / "gt.json")
    times = sorted(gt.joints[0].states)
    values = np.array([[j.states[t] for j in gt.joints] for t in times])
    if len(gt.joints) >= 2:
        moving = np.abs(np.diff(values, axis=0)) > 1e-9
        assert moving.sum(axis=1).max() >= 2


def test_extra_kinds_need_variety(tmp_path):
    with pytest.raises(InputError, match="variety"):
        generate_object(tmp_path / "x", "washing_machine", 0, **TINY)
    out = generate_object(tmp_path / "wm", "washing_machine", 0, regime=regime("realistic"),
                          **TINY)
    gt = read_articulation(out / "gt.json")
    assert gt.meta["category"] == "washing_machine" and gt.joints[0].type == "revolute"


def test_bench_sets_and_table(tmp_path):
    assert parse_set("realistic").kind == "realistic"
    assert parse_set(None, str(tmp_path)).kind == "data"
    assert parse_set(f"partnet:{tmp_path}").folder == tmp_path
    with pytest.raises(InputError):
        parse_set("nope")
    with pytest.raises(InputError):
        parse_set(f"partnet:{tmp_path / 'missing'}")
    rows = [{"category": "oven", "ae": 1.0}, {"category": "oven", "ae": 3.0},
            {"category": "door", "ae": math.nan}]
    table = category_table(rows, [Column("ae", "AE")])
    oven = next(line for line in table.splitlines() if line.startswith("oven"))
    assert oven.split()[-2:] == ["2.00", "3.00"]
    assert table.splitlines()[-1].startswith("overall")


def test_command_line_urdf_and_sets(asset, tmp_path, capsys):
    """`artgs synth --urdf` with regime flags writes <kind>_<id>/; a bad --set exits 2."""
    from artgs.core.cli import main

    out = tmp_path / "set"
    argv = ["synth", str(out), "--urdf", str(asset), "--regime", "realistic", "--no-room",
            "--mask-jitter", "1", "--width", "48", "--height", "32", "--static-views", "2",
            "--steps", "1", "--quiet"]
    assert main(argv) == 0
    gt = read_articulation(out / "cabinet_4711" / "gt.json")
    assert gt.meta["regime"]["room"] is False and gt.meta["regime"]["mask_jitter"] == 1
    assert main(["bench-propose", "--set", "nope", "--quiet"]) == 2
    assert main(["bench-reconstruct", "--set", f"partnet:{tmp_path / 'none'}", "--quiet"]) == 2
