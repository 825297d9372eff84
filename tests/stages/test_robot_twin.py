"""The robot twin: URDF forward kinematics against PyBullet, the MDH tables, the posed Gaussians."""

from __future__ import annotations

import numpy as np
import pybullet as p
import pytest
from scipy.spatial.transform import Rotation

from artgs.core.geometry.kinematics import link_poses, mdh_frames
from artgs.core.model.robots import ROBOTS
from artgs.core.sim.robot_assets import load_chain, robot_urdf
from artgs.core.stages.robot_twin import robot_twin


def _random_pose(rng) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.random(random_state=int(rng.integers(1 << 30))).as_matrix()
    T[:3, 3] = rng.uniform(-1, 1, 3)
    return T


def _random_q(chain, rng) -> np.ndarray:
    return rng.uniform(-1.5, 1.5, len(chain.actuated)) * np.r_[np.ones(len(chain.actuated) - 1),
                                                                0.02]


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_fk_matches_pybullet(name):
    """Every link frame from the URDF chain equals PyBullet's, for random joints and base poses."""
    model = ROBOTS[name]
    chain = load_chain(robot_urdf(model))
    assert chain.actuated == model.joints
    rng = np.random.default_rng(3)
    cid = p.connect(p.DIRECT)
    try:
        for _ in range(4):
            base = _random_pose(rng)
            body = p.loadURDF(str(robot_urdf(model)), base[:3, 3].tolist(),
                              Rotation.from_matrix(base[:3, :3]).as_quat().tolist(),
                              useFixedBase=True, physicsClientId=cid)
            q = _random_q(chain, rng)
            poses = link_poses(chain, q, base)
            values = dict(zip(chain.actuated, q))
            for j in chain.joints:   # PyBullet ignores <mimic>: set those joints as FK does
                if j.mimic is not None:
                    values[j.name] = j.mimic[1] * values[j.mimic[0]] + j.mimic[2]
            index = {}
            for k in range(p.getNumJoints(body, physicsClientId=cid)):
                info = p.getJointInfo(body, k, physicsClientId=cid)
                index[info[12].decode()] = k
                if info[1].decode() in values:
                    p.resetJointState(body, k, values[info[1].decode()], physicsClientId=cid)
            assert set(index) == set(poses) - {chain.root}
            for link, k in index.items():
                s = p.getLinkState(body, k, computeForwardKinematics=True, physicsClientId=cid)
                R = Rotation.from_quat(s[5]).as_matrix()
                np.testing.assert_allclose(poses[link][:3, 3], s[4], atol=1e-5, err_msg=link)
                np.testing.assert_allclose(poses[link][:3, :3], R, atol=1e-5, err_msg=link)
            p.removeBody(body, physicsClientId=cid)
    finally:
        p.disconnect(cid)


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_mdh_agrees_with_urdf(name):
    """The manufacturer's MDH frames ride on the URDF links: same origins, and a constant rotation
    about z between them (identity except where the table has a joint-angle offset)."""
    model = ROBOTS[name]
    chain = load_chain(robot_urdf(model))
    rng = np.random.default_rng(5)
    # the xArm URDF writes pi/2 as 1.5708 (3.7e-6 rad short per twist): the frames drift apart by
    # ~1e-5 over the chain; Franka's URDF has pi/2 to 11 digits
    tol = 5e-5 if name == "xarm6" else 1e-9
    corrections = []
    for _ in range(5):
        base = _random_pose(rng)
        q = _random_q(chain, rng)
        poses = link_poses(chain, q, base)
        arm_base = next(j.parent for j in chain.joints if j.child == model.mdh_links[0])
        dh = mdh_frames(model.mdh, q[:model.arm_joints], poses[arm_base])
        C = [np.linalg.inv(poses[k]) @ F for k, F in zip(model.mdh_links, dh)]
        for c in C:
            np.testing.assert_allclose(c[:3, 3], 0, atol=tol)
            np.testing.assert_allclose(c[2, :3], [0, 0, 1], atol=tol)   # about z
        corrections.append(C)
    for C in corrections[1:]:
        np.testing.assert_allclose(np.array(C), np.array(corrections[0]), atol=tol)
    angles = [np.degrees(np.arctan2(c[1, 0], c[0, 0])) for c in corrections[0]]
    expected = [np.degrees(off) for *_, off in model.mdh]
    for k, (a, e) in enumerate(zip(angles, expected)):
        # the correction is the offset not yet undone by the next joint's opposite offset
        if k + 1 < len(expected) and abs(e + expected[k + 1]) < 1e-9:
            assert abs(a - e) < 1e-3
        else:
            assert abs(a) < 1e-3, (k, a)


def test_twin_gaussians_follow_the_links(tmp_path, monkeypatch):
    """The posed twin: its centres are the link samples moved by FK; rotations normalised; an
    arm-only joint vector poses the same arm."""
    monkeypatch.setenv("ARTGS_CACHE", str(tmp_path))
    twin = robot_twin("franka_panda", 0.02)
    chain = twin.chain
    rng = np.random.default_rng(0)
    q = _random_q(chain, rng)
    base = _random_pose(rng)
    g = twin.gaussians(q, base)
    poses = link_poses(chain, q, base)
    k = twin.links.index("panda_hand")
    sel = twin.link_of == k
    P = twin.points[sel] @ poses["panda_hand"][:3, :3].T + poses["panda_hand"][:3, 3]
    np.testing.assert_allclose(g.means.numpy()[sel], P, atol=1e-5)
    np.testing.assert_allclose(np.linalg.norm(g.quats.numpy(), axis=1), 1, atol=1e-5)
    # the disc normal (local z) of each Gaussian is its sampled face normal moved with the link
    R = Rotation.from_quat(g.quats.numpy()[sel][:, [1, 2, 3, 0]]).as_matrix()[:, :, 2]
    R0 = Rotation.from_quat(twin.quats[sel][:, [1, 2, 3, 0]]).as_matrix()[:, :, 2]
    np.testing.assert_allclose(R, R0 @ poses["panda_hand"][:3, :3].T, atol=1e-5)
    arm = twin.gaussians(q[:7], base).means.numpy()
    np.testing.assert_allclose(arm[twin.link_of == twin.links.index("panda_link5")],
                               g.means.numpy()[twin.link_of == twin.links.index("panda_link5")],
                               atol=1e-6)
    assert (tmp_path / "robots").is_dir() and any((tmp_path / "robots").iterdir())
