"""``artgs synth --robot``: a robot arm that opens the parts in the interaction frames.

The robot (URDF from ``pybullet_data``, core/model/robots.py) stands in front of the object on an
invisible stand, facing it. At every interaction time it holds the handle of the part that moves
at that time (time 0: the first part to move; in a segment moving two parts at once, the first
of them) with the fingers closed across the handle bar and the approach along the part's front
normal, following the true joint as the part moves. The arm's joints come from damped least-squares IK on
the URDF chain (kinematic only: no dynamics, no contacts). The base is placed by scoring positions
in front of the object (every grasp point within comfortable reach of the shoulder, the base clear
of the object in every state), trying the best few with IK and keeping the first whose grasps are
all reached within 1 cm, else the one with the smallest worst error.

The robot appears in RGB and depth of every interaction frame, never in the masks (they hold the
object only), and not in the static views. transforms.json gets ``robot``, ``robot_base_pose``
(world <- robot base) and per interaction frame ``robot_joint_positions`` (the model's actuated
joints, arm then gripper).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pybullet as p
from scipy.linalg import solve
from scipy.spatial.transform import Rotation

from ..geometry.kinematics import joint_motion
from ..model.joints import joint_transform
from ..model.errors import InputError
from ..model.robots import ROBOTS, RobotModel, robot_model
from ..sim.robot_assets import load_chain, robot_urdf
from .objects import ObjectSpec, box_distance

_REACH = (0.3, 0.7)   # comfortable distance of a grasp point from the shoulder (m)
_CLEARANCE = 0.15     # the base column keeps this far from the object's boxes in every state (m)
_TRIES = 4            # base placements tried with IK, best-scored first ...
_GOOD = 0.01          # ... until one reaches every grasp point within this (m)


@dataclass
class RobotPlan:
    """Where the robot stands and its joint positions (actuated joints) per interaction time."""

    model: RobotModel
    base_pose: np.ndarray
    positions: list[np.ndarray]
    error: float                     # worst grasp-point error over the times (m)


def check_robot(name: str | None) -> None:
    """Refuse an unknown robot name (before any work)."""
    if name is not None and name not in ROBOTS:
        raise InputError("command line", f"unknown robot {name!r}; expected one of "
                         f"{', '.join(ROBOTS)}", field="robot")


def robot_keys(plan: RobotPlan) -> dict:
    """Top-level transforms.json keys of a capture with the robot (joint positions are per frame);
    ``robot_grasp_error_mm``: the planned grasps' worst distance from the handle (information)."""
    return {"robot": plan.model.name,
            "robot_base_pose": [[float(v) for v in row] for row in plan.base_pose],
            "robot_grasp_error_mm": round(1000 * plan.error, 2)}


def grasps(spec: ObjectSpec, schedule: list[dict[str, float]]) -> list[np.ndarray]:
    """Per time, the 4x4 grasp frame (world): origin at the held part's grasp point (its
    ``handle``, as gt.json's; else its last box's centre), z = approach (into the part), y =
    across the handle bar (the fingers close along it)."""
    R, t = spec.base_pose[:3, :3], spec.base_pose[:3, 3]
    joints = {q.name: j for q, j in zip(spec.parts, spec.joints())}
    held = _held_parts(spec, schedule)
    out = []
    for state, name in zip(schedule, held):
        q = next(q for q in spec.parts if q.name == name)
        j = joints[name]
        handle = q.boxes[-1]
        centre = np.array(handle.center) if q.handle is None else np.asarray(q.handle, float)
        M = joint_transform(j.type, j.axis, j.origin, state[name])
        point = M[:3, :3] @ (R @ (centre + q.origin) + t) + M[:3, 3]
        approach = M[:3, :3] @ -R[:, 0]
        # the bar: the handle's longest side across the approach (a knob deeper than it is
        # wide has its longest side along the approach, which would leave no grasp frame)
        bar = M[:3, :3] @ R[:, 1 + int(np.argmax(np.asarray(handle.half)[1:]))]
        y = np.cross(approach, bar)
        y /= np.linalg.norm(y)
        G = np.eye(4)
        G[:3, :3] = np.stack([np.cross(y, approach), y, approach], axis=1)
        G[:3, 3] = point
        out.append(G)
    return out


def _held_parts(spec: ObjectSpec, schedule: list[dict[str, float]]) -> list[str]:
    """The part the robot holds at each time: the first that moves from the time before."""
    held: list[str | None] = [None] * len(schedule)
    for k in range(1, len(schedule)):
        moving = [q.name for q in spec.parts if schedule[k][q.name] != schedule[k - 1][q.name]]
        held[k] = moving[0] if moving else held[k - 1]
    first = next((h for h in held if h is not None), spec.parts[0].name)
    held[0] = first
    for k in range(1, len(held)):
        held[k] = held[k] or held[k - 1]
    return held   # type: ignore[return-value]


def plan_robot(spec: ObjectSpec, schedule: list[dict[str, float]], name: str) -> RobotPlan:
    """Base placement and joint positions of robot ``name`` grasping along the schedule."""
    model = robot_model(name)
    if model is None:
        raise KeyError(name)
    targets = grasps(spec, schedule)
    arm = _Arm(model)
    best: RobotPlan | None = None
    for base in _placements(spec, schedule, targets, model)[:_TRIES]:
        plan = arm.follow(base, targets)
        if best is None or plan.error < best.error:
            best = plan
        if best.error < _GOOD:
            break
    assert best is not None
    return best


def _placements(spec: ObjectSpec, schedule: list[dict[str, float]], targets: list[np.ndarray],
                model: RobotModel) -> list[np.ndarray]:
    """Base poses facing the object, best first: every grasp point within the arm's comfortable
    reach of its shoulder, and the base clear of the object's boxes in every state."""
    front, side = spec.base_pose[:3, 0], spec.base_pose[:3, 1]
    facing = np.eye(4)
    facing[:3, :3] = np.stack([-front, -side, [0.0, 0.0, 1.0]], axis=1)   # base x at the object
    points = np.array([G[:3, 3] for G in targets])
    shoulder = model.mdh[0][2]
    grid = np.array([(d, s, h) for d in np.arange(0.2, 1.01, 0.05)
                     for s in np.arange(-0.6, 0.61, 0.1) for h in np.arange(0.0, 0.71, 0.1)])
    origins = points[0] + np.outer(grid[:, 0], front) + np.outer(grid[:, 1], side)
    origins[:, 2] = np.maximum(0.0, points[:, 2].mean() - shoulder - grid[:, 2])
    r = np.linalg.norm(points[None] - (origins + [0.0, 0.0, shoulder])[:, None], axis=2)
    reach = np.max(np.maximum(r - _REACH[1], 0) + np.maximum(_REACH[0] - r, 0), axis=1)
    heights = np.linspace(0.0, shoulder, 4)
    column = (origins[:, None] + heights[None, :, None] * [0.0, 0.0, 1.0]).reshape(-1, 3)
    boxes = [b for state in schedule[::max(1, len(schedule) // 8)] + schedule[-1:]
             for b in spec.boxes_at(state)]
    clear = box_distance(column, boxes).reshape(len(grid), len(heights)).min(axis=1)
    score = np.round(reach + 2 * np.maximum(0.0, _CLEARANCE - clear), 3)
    order = np.lexsort((r.mean(axis=1), score))
    out = []
    for k in order:
        base = facing.copy()
        base[:3, 3] = origins[k]
        out.append(base)
    return out


class _Arm:
    """Inverse kinematics of the arm by damped least squares with the analytic Jacobian of the
    URDF's serial chain to the end effector: the grasp point exactly, the approach direction
    weighted, the fingers across the bar weakly (the gripper is symmetric, so only the line of
    the fingers matters); joint limits by clipping; several seeds (the last solution, the rest
    posture, random postures), the best kept."""

    W_APPROACH = 0.3
    W_FINGERS = 0.05

    def __init__(self, model: RobotModel) -> None:
        self.model = model
        self.chain = load_chain(robot_urdf(model))
        by_child = {j.child: j for j in self.chain.joints}
        path, link = [], model.end_effector
        while link in by_child:
            path.append(by_child[link])
            link = by_child[link].parent
        self.path = path[::-1]
        self.names = list(model.joints[:model.arm_joints])
        joints = {j.name: j for j in self.chain.joints}
        self.lower = np.array([max(joints[n].limit[0], -2 * math.pi) for n in self.names])
        self.upper = np.array([min(joints[n].limit[1], 2 * math.pi) for n in self.names])
        self.tcp = np.eye(4)
        self.tcp[2, 3] = model.tcp_offset
        self.rng = np.random.default_rng(0)

    def full(self, arm: np.ndarray) -> np.ndarray:
        extra = len(self.model.joints) - self.model.arm_joints
        return np.concatenate([arm, [self.model.gripper_grasp] * extra])

    def tcp_pose(self, base: np.ndarray, arm: np.ndarray) -> np.ndarray:
        return self._fk(base, arm)[0]

    def _fk(self, base: np.ndarray, arm: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """TCP pose, and each arm joint's world axis and a point on it."""
        values = dict(zip(self.names, arm))
        T = np.asarray(base, float)
        axes, points = np.zeros((len(arm), 3)), np.zeros((len(arm), 3))
        for j in self.path:
            T = T @ j.origin
            if j.name in values:
                k = self.names.index(j.name)
                axes[k], points[k] = T[:3, :3] @ j.axis, T[:3, 3]
                T = T @ joint_motion(j.type, j.axis, values[j.name])
        return T @ self.tcp, axes, points

    def _error(self, T: np.ndarray, G: np.ndarray) -> np.ndarray:
        fingers = np.cross(G[:3, 1], G[:3, 2])   # the bar's direction
        return np.concatenate([G[:3, 3] - T[:3, 3], self.W_APPROACH * (G[:3, 2] - T[:3, 2]),
                               [-self.W_FINGERS * float(T[:3, 1] @ fingers)]])

    def _descend(self, base: np.ndarray, G: np.ndarray, q: np.ndarray, iterations: int = 40
                 ) -> tuple[np.ndarray, float]:
        """Levenberg-Marquardt steps (damping halves on success, triples on failure)."""
        fingers = np.cross(G[:3, 1], G[:3, 2])
        lam2 = 0.05 ** 2
        T, z, o = self._fk(base, q)
        e = self._error(T, G)
        for _ in range(iterations):
            J = np.concatenate([np.cross(z, T[:3, 3] - o).T,
                                self.W_APPROACH * np.cross(z, T[:3, 2]).T,
                                -self.W_FINGERS * (np.cross(z, T[:3, 1]) @ fingers)[None]])
            # scipy, not numpy: numpy's small dense solve is slow once torch is loaded
            dq = J.T @ solve(J @ J.T + lam2 * np.eye(len(e)), e, assume_a="pos")
            q_new = np.clip(q + dq, self.lower, self.upper)
            T_new, z_new, o_new = self._fk(base, q_new)
            e_new = self._error(T_new, G)
            if e_new @ e_new < e @ e:
                q, T, z, o, e = q_new, T_new, z_new, o_new, e_new
                lam2 = max(lam2 * 0.25, 1e-6)   # J J^T has rank <= joints
            else:
                lam2 *= 9.0
            if e @ e < 1e-10 or lam2 > 1e4:
                break
        return q, float(np.linalg.norm(T[:3, 3] - G[:3, 3])
                        + 0.05 * np.linalg.norm(T[:3, 2] - G[:3, 2]))

    def solve(self, base: np.ndarray, G: np.ndarray, seed: np.ndarray) -> np.ndarray:
        rest = np.clip(np.array(self.model.rest, float), self.lower, self.upper)
        best = None
        for k in range(8):
            s = seed if k == 0 else rest if k == 1 else self.rng.uniform(self.lower, self.upper)
            q, cost = self._descend(base, G, np.clip(s, self.lower, self.upper))
            # prefer continuity: another seed wins only by a clear margin
            if best is None or cost < best[1] - 0.002:
                best = (q, cost)
            if best[1] < 3e-3:
                break
        return best[0]

    def follow(self, base: np.ndarray, targets: list[np.ndarray]) -> RobotPlan:
        """Joint positions reaching every grasp frame in turn (each solve seeded by the last)."""
        arm = np.clip(np.array(self.model.rest, float), self.lower, self.upper)
        out, worst = [], 0.0
        for G in targets:
            arm = self.solve(base, G, arm)
            worst = max(worst, float(np.linalg.norm(self.tcp_pose(base, arm)[:3, 3] - G[:3, 3])))
            out.append(self.full(arm))
        return RobotPlan(self.model, base, out, worst)


class RobotInScene:
    """The planned robot in a render client (core/sim/client.py's Scene), loaded at its first
    :meth:`show` (the static views come first and must not see it). Loaded at the base pose
    rather than moved there: PyBullet's base reset places the base's centre of mass, not its
    link frame."""

    def __init__(self, client: int, plan: RobotPlan) -> None:
        self.client, self.plan = client, plan
        self.chain = load_chain(robot_urdf(plan.model))
        self.body: int | None = None
        self.index: dict[str, int] = {}

    def show(self, time: int) -> list[float]:
        """Pose the robot for interaction ``time``; returns its joint positions for the frame."""
        if self.body is None:
            base = self.plan.base_pose
            self.body = p.loadURDF(str(robot_urdf(self.plan.model)), base[:3, 3].tolist(),
                                   Rotation.from_matrix(base[:3, :3]).as_quat().tolist(),
                                   useFixedBase=True, physicsClientId=self.client)
            self.index = {p.getJointInfo(self.body, k, physicsClientId=self.client)[1].decode(): k
                          for k in range(p.getNumJoints(self.body, physicsClientId=self.client))}
        q = self.plan.positions[time]
        values = dict(zip(self.chain.actuated, q))
        for j in self.chain.joints:
            if j.mimic is not None:
                values[j.name] = j.mimic[1] * values[j.mimic[0]] + j.mimic[2]
        for name, v in values.items():
            p.resetJointState(self.body, self.index[name], float(v), physicsClientId=self.client)
        return [float(x) for x in q]
