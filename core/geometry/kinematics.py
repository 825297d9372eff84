"""Forward kinematics of URDF joint trees and modified Denavit-Hartenberg chains (numpy only).

A :class:`Chain` is a URDF's joint tree reduced to what poses its links (built from the URDF by
``core.sim.robot_assets.load_chain``): every joint's parent/child link, origin (parent link <-
joint frame, 4x4), unit axis, type, and mimic relation. :func:`link_poses` gives every link's
frame (world <- link) for the actuated joint values. :func:`mdh_frames` is the manufacturer's
view of the same arm (the ArtGS paper poses its twin that way).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..model.joints import rotation_about_axis


@dataclass(frozen=True)
class ChainJoint:
    """One URDF joint: ``type`` fixed/revolute/continuous/prismatic; ``mimic`` = (joint, multiplier,
    offset) or None; ``limit`` = (lower, upper), infinite where the URDF gives none."""

    name: str
    type: str
    parent: str
    child: str
    origin: np.ndarray
    axis: np.ndarray
    mimic: tuple[str, float, float] | None = None
    limit: tuple[float, float] = (-math.inf, math.inf)


@dataclass(frozen=True)
class Chain:
    """A URDF joint tree: joints ordered parents first, the root link, the actuated joints' names
    (not fixed, not mimic) in URDF order."""

    root: str
    joints: tuple[ChainJoint, ...]
    actuated: tuple[str, ...]

    @property
    def links(self) -> tuple[str, ...]:
        return (self.root,) + tuple(j.child for j in self.joints)


def joint_motion(kind: str, axis: np.ndarray, value: float) -> np.ndarray:
    """The 4x4 motion of a joint frame at ``value`` (radians / metres)."""
    T = np.eye(4)
    if kind in ("revolute", "continuous"):
        T[:3, :3] = rotation_about_axis(axis, value)
    elif kind == "prismatic":
        T[:3, 3] = value * np.asarray(axis, float)
    return T


def link_poses(chain: Chain, q, base: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """World <- link 4x4 of every link for actuated joint values ``q`` (sequence in
    ``chain.actuated`` order, or a name -> value mapping); ``base`` = world <- root link."""
    values = dict(q) if isinstance(q, dict) else dict(zip(chain.actuated, map(float, q)))
    poses = {chain.root: np.eye(4) if base is None else np.asarray(base, float)}
    for j in chain.joints:
        if j.type == "fixed":
            value = 0.0
        elif j.mimic is not None:
            src, mult, off = j.mimic
            value = mult * values.get(src, 0.0) + off
        else:
            value = values.get(j.name, 0.0)
        poses[j.child] = poses[j.parent] @ j.origin @ joint_motion(j.type, j.axis, value)
    return poses


def mdh_transform(alpha: float, a: float, d: float, theta: float) -> np.ndarray:
    """Modified (Craig) DH: Rot_x(alpha_{i-1}) Trans_x(a_{i-1}) Rot_z(theta_i) Trans_z(d_i)."""
    ca, sa, ct, st = math.cos(alpha), math.sin(alpha), math.cos(theta), math.sin(theta)
    return np.array([[ct, -st, 0.0, a],
                     [st * ca, ct * ca, -sa, -sa * d],
                     [st * sa, ct * sa, ca, ca * d],
                     [0.0, 0.0, 0.0, 1.0]])


def mdh_frames(table, q, base: np.ndarray | None = None) -> list[np.ndarray]:
    """World <- frame i of an arm given by MDH rows ``(alpha_{i-1}, a_{i-1}, d_i, theta_offset_i)``
    at joint angles ``q`` (one per row)."""
    T = np.eye(4) if base is None else np.asarray(base, float)
    frames = []
    for (alpha, a, d, offset), angle in zip(table, q):
        T = T @ mdh_transform(alpha, a, d, float(angle) + offset)
        frames.append(T)
    return frames
