"""The robot's digital twin: Gaussians of its links posed by forward kinematics, per frame.

Made from the robot's URDF (core/sim/robot_assets.py): each link's visual meshes sampled every
``spacing`` metres become flat discs in the surface (thin along the face normal, opacity 0.95,
colour from the mesh and the URDF material); per frame the links are placed by the URDF's forward
kinematics (core/geometry/kinematics.py) at the frame's ``robot_joint_positions`` and the
capture's ``robot_base_pose``. The stages render it together with the object's splat so the arm's
pixels are explained instead of bending the joints.

API for the stages: ``twin_for_capture(capture)`` -> ``twin(frame) -> Gaussians | None`` (None
for frames without joint positions), or None when the capture names no known robot or no frame
has joint positions.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Callable

import numpy as np
import torch
from scipy.spatial.transform import Rotation

from ..geometry.kinematics import link_poses
from ..model.capture import Capture, Frame
from ..model.robots import RobotModel, robot_model
from ..render.gaussians import Gaussians
from ..render.rasterize import render
from ..render.sh import rgb_to_sh0
from ..sim.robot_assets import load_chain, robot_urdf, sample_link_surfaces
from .reconstruct import normal_quats

#: Mean distance between the twin's Gaussians (m): a pixel at 1.5 m is ~9 mm wide at 160x120.
SPACING = 0.008
#: Disc standard deviation in spacings: discs overlap, so no back face shows through.
SCALE = 0.6
_OPACITY = 0.95
_FLAT = 0.1


class RobotTwin:
    """A robot's Gaussians in its link frames, posable by joint positions."""

    def __init__(self, model: RobotModel, spacing: float = SPACING) -> None:
        self.model = model
        self.chain = load_chain(robot_urdf(model))
        surfaces = sample_link_surfaces(model, spacing)
        self.links = [k for k in self.chain.links if k in surfaces]
        pts = [surfaces[k].points for k in self.links]
        self.link_of = np.concatenate([np.full(len(p), i) for i, p in enumerate(pts)])
        self.points = np.concatenate(pts).astype(np.float64)
        self.quats = normal_quats(np.concatenate([surfaces[k].normals for k in self.links]))
        colours = np.concatenate([surfaces[k].colors for k in self.links])
        s = np.log(SCALE * spacing)
        n = len(self.points)
        self.log_scales = np.tile([s, s, s + np.log(_FLAT)], (n, 1))
        self.opacity_logits = np.full(n, np.log(_OPACITY / (1 - _OPACITY)))
        self.sh = rgb_to_sh0(torch.as_tensor(colours, dtype=torch.float32))[:, None, :]

    def link_transforms(self, q, base: np.ndarray | None = None) -> np.ndarray:
        """(L,4,4) world <- link of the twin's links at joint positions ``q`` (full or arm-only)."""
        poses = link_poses(self.chain, self.model.full_positions(q), base)
        return np.stack([poses[k] for k in self.links])

    def tool_pose(self, q, base: np.ndarray | None = None) -> np.ndarray:
        """World <- tool (4x4): the end-effector link at ``q``, moved ``tcp_offset`` along its z
        axis to the point between the fingertips, where the hand holds a handle."""
        T = link_poses(self.chain, self.model.full_positions(q), base)[self.model.end_effector]
        tcp = np.eye(4)
        tcp[2, 3] = self.model.tcp_offset
        return T @ tcp

    def posed_points(self, q, base: np.ndarray | None = None) -> np.ndarray:
        """The Gaussians' centres in the world at ``q`` (numpy, for geometry tests)."""
        T = self.link_transforms(q, base)[self.link_of]
        return np.einsum("nij,nj->ni", T[:, :3, :3], self.points) + T[:, :3, 3]

    def gaussians(self, q, base: np.ndarray | None = None, device="cpu") -> Gaussians:
        """The twin posed at joint positions ``q`` with the robot base at ``base`` (world <- base)."""
        T = self.link_transforms(q, base)
        link_q = Rotation.from_matrix(T[:, :3, :3]).as_quat()[:, [3, 0, 1, 2]]   # w x y z
        quats = _quat_mul(link_q[self.link_of], self.quats)
        f32 = dict(dtype=torch.float32, device=device)
        return Gaussians(torch.as_tensor(self.posed_points(q, base), **f32),
                         torch.as_tensor(quats, **f32), torch.as_tensor(self.log_scales, **f32),
                         torch.as_tensor(self.opacity_logits, **f32), self.sh.to(device))


def _quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton products of (N,4) w x y z quaternions."""
    aw, ax, ay, az = a.T
    bw, bx, by, bz = b.T
    return np.stack([aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw], 1)


@lru_cache(maxsize=4)
def robot_twin(name: str, spacing: float = SPACING) -> RobotTwin:
    """The twin of the known robot ``name``, built once per process (samples cached on disk)."""
    model = robot_model(name)
    if model is None:
        raise KeyError(f"unknown robot model {name!r}")
    return RobotTwin(model, spacing)


def twin_for_capture(capture: Capture, device="cpu", spacing: float = SPACING
                     ) -> Callable[[Frame], Gaussians | None] | None:
    """``twin(frame)``: the robot's Gaussians posed for ``frame`` (None where the frame has no
    joint positions); None when the capture has no known robot with joint positions."""
    if robot_model(capture.robot) is None or not any(
            f.robot_joint_positions is not None for f in capture.frames):
        return None
    twin = robot_twin(capture.robot, spacing)
    base = capture.robot_base_pose

    def pose(frame: Frame) -> Gaussians | None:
        q = frame.robot_joint_positions
        return None if q is None else twin.gaussians(q, base, device)
    return pose


def tool_path(capture: Capture) -> dict[int, np.ndarray]:
    """Per interaction time with robot joint positions, the robot's tool pose (world <- tool,
    :meth:`RobotTwin.tool_pose`; the first such frame of the time); empty when the capture has no
    known robot or no joint positions. A hand that holds a part while it moves moves with it, so
    the path is evidence of the joint (core/stages/optimise/hypotheses.py)."""
    if robot_model(capture.robot) is None:
        return {}
    twin = robot_twin(capture.robot)
    path: dict[int, np.ndarray] = {}
    for f in capture.interaction:
        if f.time is not None and f.robot_joint_positions is not None and int(f.time) not in path:
            path[int(f.time)] = twin.tool_pose(f.robot_joint_positions, capture.robot_base_pose)
    return path


def twin_depth_for_capture(capture: Capture, device="cpu", spacing: float = SPACING
                           ) -> Callable[[Frame], np.ndarray | None] | None:
    """``depth(frame)``: the twin's rendered depth (H,W) in the frame (0 where its alpha is below
    0.5; None for frames without joint positions); None without a twin (see
    :func:`twin_for_capture`). What the motion route's change detection takes."""
    twin = twin_for_capture(capture, device, spacing)
    if twin is None:
        return None

    def depth(frame: Frame) -> np.ndarray | None:
        g = twin(frame)
        if g is None:
            return None
        with torch.no_grad():
            res = render(g, frame.camera)
        return np.where(res.alpha.cpu().numpy() > 0.5, res.depth.cpu().numpy(), 0.0)
    return depth
