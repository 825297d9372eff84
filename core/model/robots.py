"""Robot models the project knows (numpy-only: the capture reader checks joint vectors with it).

A capture's ``robot`` names one of :data:`ROBOTS`; each interaction frame's
``robot_joint_positions`` then lists the values of the robot URDF's *actuated* joints (not fixed,
not mimic) in the URDF's order: the arm joints, then the gripper's one driving joint. An arm-only
vector (the gripper joint left out, taken as 0) is accepted too, since real
arm drivers often report the gripper separately. ``robot_base_pose`` (top level, 4x4 world <- robot
base, default identity: the world frame is the robot's base frame, as with cameras calibrated to
the robot) places it. Unknown robot names are allowed: the stages then have no twin and ignore
what they cannot explain.

``mdh`` rows are the modified (Craig) Denavit-Hartenberg parameters
``(alpha_{i-1}, a_{i-1}, d_i, theta_offset_i)`` of the arm joints (the ArtGS paper poses the twin
with them); ``mdh_links`` names the URDF link each MDH frame rides on (the frames coincide up to a
constant rotation about z where the manufacturer's table has a joint-angle offset; tested).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import numpy as np


@dataclass(frozen=True)
class RobotModel:
    """A robot from ``pybullet_data``: its URDF (path inside the package) and joint layout."""

    name: str
    urdf: str
    joints: tuple[str, ...]          # actuated joints, in URDF order (arm joints then gripper)
    arm_joints: int                  # how many of them belong to the arm
    end_effector: str                # the link that carries the grasp point ...
    tcp_offset: float                # ... this far along its z axis (m; between the fingertips)
    gripper_grasp: float             # gripper joint value of a hand closed around a handle
    mdh: tuple[tuple[float, float, float, float], ...]
    mdh_links: tuple[str, ...]
    rest: tuple[float, ...]          # a comfortable arm posture (IK seed)

    def full_positions(self, q) -> np.ndarray:
        """``q`` (arm-only or full) as a full actuated-joint vector (gripper joint 0 if missing)."""
        import numpy as np  # here: the CLI imports this module, and check-env runs without numpy

        q = np.asarray(q, float)
        if len(q) == self.arm_joints:
            q = np.concatenate([q, np.zeros(len(self.joints) - self.arm_joints)])
        return q

    def accepted_lengths(self) -> tuple[int, ...]:
        return (len(self.joints), self.arm_joints)


_X6_OFFSET = math.atan2(284.5, 53.5)   # xArm6: link 2 -> 3 is (53.5, -284.5) mm, not along x

ROBOTS: dict[str, RobotModel] = {
    "franka_panda": RobotModel(
        name="franka_panda", urdf="franka_panda/panda.urdf",
        joints=tuple(f"panda_joint{k}" for k in range(1, 8)) + ("panda_finger_joint1",),
        arm_joints=7, end_effector="panda_grasptarget", tcp_offset=0.0, gripper_grasp=0.015,
        # Franka Emika's published (Craig) parameters; the last row is the flange (link 8)
        mdh=((0.0, 0.0, 0.333, 0.0), (-math.pi / 2, 0.0, 0.0, 0.0), (math.pi / 2, 0.0, 0.316, 0.0),
             (math.pi / 2, 0.0825, 0.0, 0.0), (-math.pi / 2, -0.0825, 0.384, 0.0),
             (math.pi / 2, 0.0, 0.0, 0.0), (math.pi / 2, 0.088, 0.0, 0.0)),
        mdh_links=tuple(f"panda_link{k}" for k in range(1, 8)),
        rest=(0.0, -0.3, 0.0, -2.2, 0.0, 2.0, 0.785)),
    "xarm6": RobotModel(
        name="xarm6", urdf="xarm/xarm6_with_gripper.urdf",
        joints=tuple(f"joint{k}" for k in range(1, 7)) + ("drive_joint",),
        arm_joints=6, end_effector="link6", tcp_offset=0.172, gripper_grasp=0.5,
        # UFACTORY's xArm6 kinematic parameters (modified DH)
        mdh=((0.0, 0.0, 0.267, 0.0), (-math.pi / 2, 0.0, 0.0, -_X6_OFFSET),
             (0.0, math.hypot(53.5, 284.5) / 1000, 0.0, _X6_OFFSET),
             (-math.pi / 2, 0.0775, 0.3425, 0.0), (math.pi / 2, 0.0, 0.0, 0.0),
             (-math.pi / 2, 0.076, 0.097, 0.0)),
        mdh_links=tuple(f"link{k}" for k in range(1, 7)),
        rest=(0.0, -0.5, -1.0, 0.0, 1.5, 0.0)),
}


def robot_model(name: str | None) -> RobotModel | None:
    """The known model called ``name`` (None for an unknown or missing name)."""
    return ROBOTS.get(name) if name else None
