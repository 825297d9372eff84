"""core/sim/urdf.py: rotations survive the rpy text round trip, and world-frame joints written with
joint_in_parent are where PyBullet and yourdfpy put them."""

from __future__ import annotations

import numpy as np
import pytest
import yourdfpy
from scipy.spatial.transform import Rotation

from artgs.core.sim import urdf
from artgs.core.sim.client import Scene


def test_rpy_round_trip_including_gimbal_lock():
    rng = np.random.default_rng(0)
    mats = list(Rotation.random(50, random_state=1).as_matrix())
    mats += [Rotation.from_euler("xyz", [a, s * np.pi / 2, b]).as_matrix()
             for a, b in rng.uniform(-3, 3, (5, 2)) for s in (1, -1)]
    for R in mats:
        np.testing.assert_allclose(urdf.rpy_to_matrix(urdf.matrix_to_rpy(R)), R, atol=1e-12)


def test_sanitize_and_duplicate_names():
    assert urdf.sanitize_name("door left/1") == "door_left_1"
    assert urdf.sanitize_name("") == "_"
    with pytest.raises(ValueError, match="duplicate"):
        urdf.write_urdf("r", [urdf.Link("a b"), urdf.Link("a_b")], [])
    with pytest.raises(ValueError, match="unknown link"):
        urdf.write_urdf("r", [urdf.Link("a")], [urdf.UrdfJoint("j", "fixed", "a", "b")])


def test_world_joints_reproduced_by_pybullet_and_yourdfpy(tmp_path):
    """A chain base -> door -> flap with rotated frames: each world axis/point comes back exactly."""
    rng = np.random.default_rng(3)
    base = np.eye(4)
    base[:3, :3] = Rotation.random(random_state=4).as_matrix()
    base[:3, 3] = rng.uniform(-1, 1, 3)
    box = urdf.Geometry(urdf.Box((0.1, 0.2, 0.3)), urdf.translation((0.05, 0, 0)), (1, 0, 0, 1))
    links = [urdf.Link("world"), urdf.Link("base", [box], [box], urdf.box_inertial(1, (0.1, 0.2, 0.3)))]
    joints = [urdf.UrdfJoint("base_pose", "fixed", "world", "base", origin=base)]
    world_joints = {"door": ("revolute", rng.normal(size=3), rng.uniform(-1, 1, 3), "base"),
                    "flap": ("prismatic", rng.normal(size=3), rng.uniform(-1, 1, 3), "door_link")}
    frames = {"base": base}
    for name, (kind, axis, point, parent) in world_joints.items():
        axis = axis / np.linalg.norm(axis)
        origin, local_axis = urdf.joint_in_parent(frames[parent], axis, point)
        frames[f"{name}_link"] = frames[parent] @ origin
        links.append(urdf.Link(f"{name}_link", [box], [box], urdf.Inertial(0.5)))
        joints.append(urdf.UrdfJoint(name, kind, parent, f"{name}_link", origin=origin,
                                     axis=local_axis, limit=(-1.0, 1.0)))
        world_joints[name] = (kind, axis, point, parent)
    path = tmp_path / "chain.urdf"
    path.write_text(urdf.write_urdf("chain", links, joints))

    with Scene() as scene:
        body = scene.load(path)
        assert set(body.joints) == {"door", "flap"}
        for name, (kind, axis, point, _) in world_joints.items():
            T = scene.link_frame(body, body.joints[name])
            info = scene.joint_info(body, body.joints[name])
            np.testing.assert_allclose(T[:3, :3] @ np.array(info[13]), axis, atol=1e-6)
            off = point - T[:3, 3]
            assert np.linalg.norm(off - (off @ axis) * axis) < 1e-6
    robot = yourdfpy.URDF.load(str(path))
    for name, (_, axis, point, _) in world_joints.items():
        T = robot.get_transform(f"{name}_link", "world")
        np.testing.assert_allclose(T[:3, 3], point, atol=1e-9)
        np.testing.assert_allclose(T[:3, :3] @ robot.joint_map[name].axis, axis, atol=1e-9)
