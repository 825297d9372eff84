"""A robot opens one part of an articulated URDF in PyBullet along a PLANNED joint (the paper's
manipulation check, shared/spec/metrics.md).

One episode per joint, in its own ``DIRECT`` client:

- the object URDF is loaded with a fixed base; the operated joint is free, the others are held
  closed; each part weighs ``PART_MASS`` so the outcome measures the joint, not the payload;
- the gripper approaches the handle along the line the plan starts to move it (``_approaches``:
  against that motion, so it pulls, or if that tracks worse, with it, so it pushes), not along
  the handle's stored ``approach`` (a part's estimated normal), which serves only a handle on
  the hinge's axis;
- the robot (``pybullet_data``) stands in front of the handle, facing along the approach
  direction; its base is the candidate place that reaches the grasp and from which inverse
  kinematics, followed along the planned handle path (each pose seeded from the last, as the arm
  moves), stays closest to the path and away from joint limits; the arm's pose halfway along that
  path is the posture the null space pulls towards;
- it starts at the grasp pose and holds the handle: a point-to-point constraint between the
  gripper's grasp point and the part, limited to ``GRASP_FORCE`` (a parallel gripper's holding
  force times friction 1); collisions between robot and object are off;
- the gripper follows the handle path of the PLANNED joint (minimum-jerk in the joint value) under
  Cartesian impedance control in operational-space form, tau = J^T Lambda (K (x_d - x) + D (xdot_d
  - xdot)) + C(q, qdot) qdot + g(q) (gravity and Coriolis from PyBullet's inverse dynamics) plus a null-space
  posture term (``_Robot.impedance_step``); the URDF's joint damping is switched off (the
  controller damps; an explicit damping of 1 N m s on xarm6's 0.1 kg wrist is unstable at 240 Hz);
- the grasp is lost when the gripper and the grasped point drift ``LOST_DISTANCE`` apart;
  success when the TRUE joint (the URDF's) reaches the target of metrics.md while the grasp
  holds (the plan goes ``OVERSHOOT`` past the target; a grasp that slips only beyond the target
  is reported, ``grasp_lost``, but the part was opened).
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass, field

import numpy as np

from ..model.joints import Joint, joint_transform, motion_direction

DT = 1.0 / 240.0
GRASP_FORCE = 70.0          # N
LOST_DISTANCE = 0.02        # m
PART_MASS = 1.0             # kg
# position stiffness in N/m: 70 N of grasp force give way at 2.3 cm (LOST_DISTANCE is 2 cm);
# damping and orientation gains per unit task mass: K = w^2, D = 2 w, w well below the step rate
# (w DT < 0.3) so the explicit control step stays stable
K_POS, D_POS = 3000.0, 2 * 60.0
K_ROT, D_ROT = 30.0 ** 2, 2 * 30.0
NULL_STIFFNESS, NULL_DAMPING = 10.0, 2 * 10.0 ** 0.5
LAMBDA_DAMPING = 1e-4       # regularises (J M^-1 J^T) near singular poses
OVERSHOOT = 1.15            # the plan goes this much past the target
REHEARSALS = 6              # at most this many robot placements rehearsed along the plan
TRACKED = 0.01              # m: a rehearsal this close to the plan ends the search (_place_robot)


@dataclass(frozen=True)
class RobotModel:
    """A robot of pybullet_data: URDF, grasp-point link, a rest pose of its arm joints."""

    urdf: str
    ee_link: str
    rest: tuple[float, ...]
    fingers: tuple[str, ...] = ()


ROBOT_MODELS = {
    "franka_panda": RobotModel("franka_panda/panda.urdf", "panda_grasptarget",
                               (0.0, -0.3, 0.0, -2.3, 0.0, 3.3, 0.785),
                               ("panda_finger_joint1", "panda_finger_joint2")),
    "xarm6": RobotModel("xarm/xarm6_robot.urdf", "link6", (0.0, -0.5, -0.5, 0.0, -0.5, 0.0)),
}


@dataclass
class Task:
    """Open the URDF joint ``true_joint`` by following the ``planned`` (estimated) joint, grasping
    at ``handle`` (world) approached along ``approach`` (unit, world, towards the part)."""

    true_joint: str
    planned: Joint
    handle: np.ndarray
    approach: np.ndarray


@dataclass
class Outcome:
    """What happened in one episode."""

    joint: str
    success: bool
    reached: float
    target: float
    grasp_lost: bool
    reason: str
    seconds: float
    max_tracking_error: float
    frames: list[np.ndarray] = field(default_factory=list)
    reached_held: float = 0.0

    def to_dict(self) -> dict:
        return {"success": self.success, "reached": round(self.reached, 5),
                "target": round(self.target, 5), "grasp_lost": self.grasp_lost,
                "reason": self.reason, "seconds": round(self.seconds, 2),
                "max_tracking_error_m": round(self.max_tracking_error, 4),
                "reached_held": round(self.reached_held, 5)}


def target_value(kind: str, limit: tuple[float, float]) -> float:
    """Signed joint value to reach (metrics.md): revolute 45 deg or 80 % of the range if smaller,
    prismatic 80 % of the range, at most 0.25 m; towards the larger end of the range from 0."""
    lo, hi = limit
    sign = 1.0 if abs(hi) >= abs(lo) else -1.0
    span = hi - lo
    amount = min(math.pi / 4, 0.8 * span) if kind == "revolute" else min(0.8 * span, 0.25)
    return sign * amount


def world_joints(body: int, client: int) -> dict[str, Joint]:
    """The movable joints of a loaded body in the world frame at its current (zero) state."""
    import pybullet as p

    out = {}
    for i in range(p.getNumJoints(body, physicsClientId=client)):
        info = p.getJointInfo(body, i, physicsClientId=client)
        if info[2] not in (p.JOINT_REVOLUTE, p.JOINT_PRISMATIC):
            continue
        state = p.getLinkState(body, i, computeForwardKinematics=1, physicsClientId=client)
        R = np.array(p.getMatrixFromQuaternion(state[5])).reshape(3, 3)
        kind = "revolute" if info[2] == p.JOINT_REVOLUTE else "prismatic"
        out[info[1].decode()] = Joint(info[1].decode(), kind, R @ np.array(info[13]),
                                      np.array(state[4]), (info[8], info[9]),
                                      child=info[12].decode())
    return out


def run_episode(object_urdf: str, task: Task, robot: str = "franka_panda", frames: int = 6,
                size: tuple[int, int] = (160, 120)) -> Outcome:
    """One episode (see the module docstring); ``frames`` images of it for the strip."""
    import pybullet as p
    import pybullet_data

    start = time.perf_counter()
    model = ROBOT_MODELS[robot]
    client = p.connect(p.DIRECT)
    try:
        p.setGravity(0, 0, -9.81, physicsClientId=client)
        p.setTimeStep(DT, physicsClientId=client)
        obj = p.loadURDF(object_urdf, useFixedBase=True, physicsClientId=client)
        truth = world_joints(obj, client)
        if task.true_joint not in truth:
            raise ValueError(f"{object_urdf} has no movable joint {task.true_joint!r}")
        true = truth[task.true_joint]
        index = {p.getJointInfo(obj, i, physicsClientId=client)[1].decode(): i
                 for i in range(p.getNumJoints(obj, physicsClientId=client))}
        link = index[task.true_joint]
        for name, i in index.items():
            if name in truth:
                held = name != task.true_joint
                p.setJointMotorControl2(obj, i, p.VELOCITY_CONTROL, targetVelocity=0,
                                        force=1e4 if held else 0.2, physicsClientId=client)
                p.changeDynamics(obj, i, mass=PART_MASS, physicsClientId=client)
        target = target_value(true.type, true.limit)

        plan_sign = math.copysign(1.0, target_value(task.planned.type, task.planned.limit)
                                  if task.planned.limit != (0.0, 0.0) else 1.0)
        plan_end = plan_sign * OVERSHOOT * abs(target)
        # inertia from the links' shapes, not the files: PyBullet rejects xarm6's inertia
        # tensors ("bad inertia tensor", set to zero), which makes its mass matrix singular
        body = p.loadURDF(os.path.join(pybullet_data.getDataPath(), model.urdf),
                          useFixedBase=True, physicsClientId=client)
        for i in range(-1, p.getNumJoints(obj, physicsClientId=client)):
            for j in range(-1, p.getNumJoints(body, physicsClientId=client)):
                p.setCollisionFilterPair(obj, body, i, j, 0, physicsClientId=client)
        duration = 3.0
        steps, hold = int(duration / DT), int(1.0 / DT)
        best = None
        for approach in _approaches(task.planned, task.handle, plan_sign, task.approach):
            grasp_pose = _grasp_pose(task.handle, approach)
            goals = [joint_transform(task.planned.type, task.planned.axis, task.planned.origin,
                                     plan_end * _min_jerk(min(k / steps, 1.0))) @ grasp_pose
                     for k in range(steps + hold)]
            facing = _facing(task.planned, task.handle, approach)
            err, base, qs = _place_robot(model, body, goals[:steps + 1], facing, client)
            if best is None or err < best[0]:
                best = (err, grasp_pose, goals, facing, base, qs)
            if err <= TRACKED:
                break
        _, grasp_pose, goals, facing, base, qs = best
        bot = _start(model, body, base, qs, client)
        reach = float(np.linalg.norm(bot.ee_pose()[:3, 3] - grasp_pose[:3, 3]))
        if reach > 0.02:
            return Outcome(task.true_joint, False, 0.0, target, False,
                           f"handle out of reach ({reach:.3f} m)", time.perf_counter() - start,
                           reach, [])
        com = p.getLinkState(obj, link, physicsClientId=client)
        local = _inverse_point(com[0], com[1], task.handle, client)
        cid = p.createConstraint(bot.body, bot.ee, obj, link, p.JOINT_POINT2POINT, [0, 0, 0],
                                 bot.ee_com_offset, local, physicsClientId=client)
        p.changeConstraint(cid, maxForce=GRASP_FORCE, physicsClientId=client)

        shots = set(np.linspace(0, steps + hold - 1, frames).round().astype(int).tolist())
        camera = _camera(task.handle, facing, goals[-1][:3, 3], size)
        images, lost, worst, reached, held = [], False, 0.0, 0.0, 0.0
        for k, (goal, speed) in enumerate(zip(goals, _velocities(goals))):
            worst = max(worst, bot.impedance_step(goal, speed))
            p.stepSimulation(physicsClientId=client)
            reached = p.getJointState(obj, link, physicsClientId=client)[0]
            if not lost:
                state = p.getLinkState(obj, link, physicsClientId=client)
                held_at = _point(state[0], state[1], local, client)
                if np.linalg.norm(held_at - bot.ee_pose()[:3, 3]) > LOST_DISTANCE:
                    lost = True
                    p.removeConstraint(cid, physicsClientId=client)
            if not lost:   # the opening reached with the part still in hand
                held = max(held, reached * math.copysign(1.0, target))
            if k in shots:
                images.append(_render(camera, size, client))
        success = held >= abs(target) - 1e-3
        reason = ("opened, the grasp slipped past the target" if lost else "opened") if success \
            else ("grasp lost" if lost else "did not reach the target")
        return Outcome(task.true_joint, success, float(reached), target, lost, reason,
                       time.perf_counter() - start, worst, images,
                       float(held * math.copysign(1.0, target)))
    finally:
        p.disconnect(client)


class _Robot:
    """The arm in a client: torque-controlled Cartesian impedance at its grasp-point link."""

    def __init__(self, model: RobotModel, body: int, base: np.ndarray, client: int) -> None:
        import pybullet as p

        self.p, self.body, self.client, self.model = p, body, client, model
        names = {}
        self.movable = []
        for i in range(p.getNumJoints(body, physicsClientId=client)):
            info = p.getJointInfo(body, i, physicsClientId=client)
            names[info[12].decode()] = i
            names[info[1].decode()] = i
            if info[2] != p.JOINT_FIXED:
                self.movable.append(i)
                p.changeDynamics(body, i, jointDamping=0.0, physicsClientId=client)
        self.ee = names[model.ee_link]
        self.arm = self.movable[:len(model.rest)]
        info = [p.getJointInfo(body, i, physicsClientId=client) for i in self.movable]
        self.lower = [i[8] for i in info]
        self.upper = [i[9] for i in info]
        self.rest = list(model.rest) + [0.0] * (len(self.movable) - len(model.rest))
        self.fingers = [names[f] for f in model.fingers]
        state = p.getLinkState(body, self.ee, physicsClientId=client)
        # the grasp point (link frame origin) in the link's centre-of-mass frame
        inv_pos, inv_orn = p.invertTransform(state[2], state[3])
        self.ee_com_offset = list(inv_pos)
        self.base = base

    def set_arm(self, q) -> None:
        for i, v in zip(self.arm, q):
            self.p.resetJointState(self.body, i, float(v), physicsClientId=self.client)
        for i in self.fingers:
            self.p.resetJointState(self.body, i, 0.0, physicsClientId=self.client)

    def ik(self, pose: np.ndarray, seed=None) -> list[float]:
        """Arm joint values reaching ``pose``, seeded from ``seed`` (default: the rest pose)."""
        p = self.p
        self.set_arm(self.model.rest if seed is None else seed)
        quat = _quat(pose[:3, :3])
        for _ in range(3):
            sol = p.calculateInverseKinematics(
                self.body, self.ee, pose[:3, 3].tolist(), quat, lowerLimits=self.lower,
                upperLimits=self.upper, jointRanges=[u - lo for lo, u in zip(self.lower, self.upper)],
                restPoses=self.rest, maxNumIterations=200, residualThreshold=1e-6,
                physicsClientId=self.client)
            sol = np.clip(sol, self.lower, self.upper)
            self.set_arm(sol[:len(self.arm)])
        return list(sol[:len(self.arm)])

    def ee_pose(self) -> np.ndarray:
        s = self.p.getLinkState(self.body, self.ee, computeForwardKinematics=1,
                                physicsClientId=self.client)
        T = np.eye(4)
        T[:3, :3] = np.array(self.p.getMatrixFromQuaternion(s[5])).reshape(3, 3)
        T[:3, 3] = s[4]
        return T

    def release_motors(self) -> None:
        p = self.p
        p.setJointMotorControlArray(self.body, self.arm, p.VELOCITY_CONTROL,
                                    forces=[0.0] * len(self.arm), physicsClientId=self.client)
        if self.fingers:
            p.setJointMotorControlArray(self.body, self.fingers, p.POSITION_CONTROL,
                                        targetPositions=[0.0] * len(self.fingers),
                                        forces=[20.0] * len(self.fingers),
                                        physicsClientId=self.client)

    def impedance_step(self, goal: np.ndarray, speed: np.ndarray) -> float:
        """Apply one step of Cartesian impedance control in the operational-space form,
        tau = J^T Lambda (K e + D (v_d - v)) + C(q, qd) qd + g(q) + null-space posture, and
        return the position error. ``speed`` is the goal's (linear, angular) velocity v_d: damping
        towards it rather than towards rest keeps the gripper on a moving goal (damping towards
        rest makes it lag by D v / K, 5 cm and more on a door's sweep).

        Lambda = (J M^-1 J^T)^-1 (PyBullet's mass matrix) scales damping and orientation gains
        to the arm's task-space inertia, so one set of gains is stable for every robot and pose
        (xarm6's last link weighs 0.1 kg; a fixed rotational damping makes it oscillate at the
        step rate); the position stiffness is physical (N/m), the same for every robot. Gravity and Coriolis come
        from PyBullet's inverse dynamics at the current velocity; the null-space term (the
        dynamically consistent projector) pulls a redundant arm towards its rest pose."""
        p, c, n = self.p, self.client, len(self.arm)
        states = p.getJointStates(self.body, self.movable, physicsClientId=c)
        q = [s[0] for s in states]
        qd = [s[1] for s in states]
        ls = p.getLinkState(self.body, self.ee, computeLinkVelocity=1, computeForwardKinematics=1,
                            physicsClientId=c)
        x = np.array(ls[4])
        R = np.array(p.getMatrixFromQuaternion(ls[5])).reshape(3, 3)
        v, w = np.array(ls[6]), np.array(ls[7])
        e_pos = goal[:3, 3] - x
        e_rot = _rotvec(goal[:3, :3] @ R.T)
        zeros = [0.0] * len(q)
        J_lin, J_ang = p.calculateJacobian(self.body, self.ee, self.ee_com_offset, q, zeros,
                                           zeros, physicsClientId=c)
        # PyBullet gives the Jacobian in the base frame: rotate it into the world
        Rb = np.array(p.getMatrixFromQuaternion(
            p.getBasePositionAndOrientation(self.body, physicsClientId=c)[1])).reshape(3, 3)
        J = np.vstack([Rb @ np.array(J_lin), Rb @ np.array(J_ang)])[:, :n]
        M = np.array(p.calculateMassMatrix(self.body, q, physicsClientId=c))[:n, :n]
        M_inv = np.linalg.inv(M)
        Lam = np.linalg.inv(J @ M_inv @ J.T + LAMBDA_DAMPING * np.eye(6))
        # stiffness in N/m (how hard the gripper insists on the plan, against the grasp's force
        # limit, is what decides a wrong plan); damping and orientation per unit task mass
        spring = np.concatenate([K_POS * e_pos, np.zeros(3)])
        accel = np.concatenate([D_POS * (speed[:3] - v), K_ROT * e_rot + D_ROT * (speed[3:] - w)])
        bias = np.array(p.calculateInverseDynamics(self.body, q, qd, zeros, physicsClientId=c))
        qd_arm = np.array(qd[:n])
        J_bar = M_inv @ J.T @ Lam
        null = np.eye(n) - J.T @ J_bar.T
        rest = np.array(self.rest[:n]) - np.array(q[:n])
        posture = M @ (NULL_STIFFNESS * rest - NULL_DAMPING * qd_arm)
        tau = J.T @ (spring + Lam @ accel) + bias[:n] + null @ posture
        p.setJointMotorControlArray(self.body, self.arm, p.TORQUE_CONTROL, forces=tau.tolist(),
                                    physicsClientId=c)
        return float(np.linalg.norm(e_pos))


def _velocities(goals: list[np.ndarray]) -> list[np.ndarray]:
    """Per goal pose, the (linear, angular) velocity towards the next one; zero at the last."""
    T = np.stack(goals)
    linear = np.diff(T[:, :3, 3], axis=0) / DT
    angular = _rotvec(T[1:, :3, :3] @ T[:-1, :3, :3].transpose(0, 2, 1)) / DT
    return list(np.hstack([linear, angular])) + [np.zeros(6)]


def _min_jerk(s: float) -> float:
    return 10 * s ** 3 - 15 * s ** 4 + 6 * s ** 5


def _place_robot(model: RobotModel, body: int, goals: list[np.ndarray], facing: np.ndarray,
                 client: int) -> tuple[float, np.ndarray, list[np.ndarray]]:
    """The candidate base that follows the planned gripper path ``goals`` (one pose per control
    step) best: (its worst tracking error in the rehearsal, the base, the arm's poses along the
    path from inverse kinematics).

    Candidates in front of the path (behind it along ``facing``, the horizontal direction the
    robot faces) are ranked by inverse kinematics along the path (seeded from
    the rest pose, and again each pose from the last), first by reaching the grasp, then by the
    worst miss and joint-limit margin; in that order, distinct bases then rehearse the whole path
    under the impedance controller without the object (collisions with it are off) until one
    tracks it within ``TRACKED`` (or ``REHEARSALS`` have), and the one that tracked best is kept.
    IK alone ranks a pose by where the arm could be, not by where the controller takes it near
    joint limits, so the rehearsal decides. Only the plan is used: the
    true joint plays no part in where the robot stands."""
    import pybullet as p

    path = goals[::max(1, len(goals) // 6)] + [goals[-1]]
    start, end = path[0][:3, 3], path[-1][:3, 3]
    side = np.cross([0.0, 0.0, 1.0], facing)
    mid = (start + end) / 2
    orn = p.getQuaternionFromEuler([0, 0, math.atan2(facing[1], facing[0])])
    ranked = []
    for d in (0.35, 0.5, 0.65, 0.8):
        for lateral in (-0.2, 0.0, 0.2):
            for dz in (-0.6, -0.4, -0.2):
                base = mid - d * facing + lateral * side
                base[2] = mid[2] + dz
                p.resetBasePositionAndOrientation(body, base.tolist(), orn,
                                                  physicsClientId=client)
                robot = _Robot(model, body, base, client)
                for sequential in (False, True):
                    ranked.append((*_ik_score(robot, path, sequential), base))
    ranked.sort(key=lambda r: r[:2])
    saved = p.saveState(physicsClientId=client)
    best, best_err, tried, speeds = None, np.inf, [], _velocities(goals)
    for _, _, qs, base in ranked:
        if best_err <= TRACKED or len(tried) == REHEARSALS:
            break
        if any(np.allclose(base, b) for b in tried):
            continue
        tried.append(base)
        p.restoreState(saved, physicsClientId=client)
        robot = _start(model, body, base, qs, client)
        err = 0.0
        for goal, speed in zip(goals, speeds):
            err = max(err, robot.impedance_step(goal, speed))
            p.stepSimulation(physicsClientId=client)
        if err < best_err:
            best, best_err = (base, qs), err
    p.restoreState(saved, physicsClientId=client)
    p.removeState(saved, physicsClientId=client)
    return best_err, best[0], best[1]


def _ik_score(robot: "_Robot", path: list[np.ndarray], sequential: bool) -> tuple:
    """(misses the grasp, worst miss + joint-limit penalty, joint values) along ``path``."""
    err, q, qs, misses_grasp = 0.0, None, [], False
    for pose in path:
        q = np.array(robot.ik(pose, q if sequential else None))
        qs.append(q)
        e = robot.ee_pose()
        miss = float(np.linalg.norm(e[:3, 3] - pose[:3, 3]))
        if len(qs) == 1:
            misses_grasp = miss > 0.01
        margin = np.minimum(q - robot.lower[:len(q)], robot.upper[:len(q)] - q).min()
        err = max(err, miss + 0.05 * float(np.linalg.norm(_rotvec(pose[:3, :3] @ e[:3, :3].T)))
                  + 0.05 * max(0.0, 0.3 - float(margin)))
    return misses_grasp, err, qs


def _start(model: RobotModel, body: int, base: np.ndarray, qs: list[np.ndarray],
           client: int) -> "_Robot":
    """The robot at ``base``, at the grasp (``qs[0]``), its null-space posture the arm's pose
    halfway along the path (away from the joint limits the ends may approach), motors off."""
    import pybullet as p

    p.resetBasePositionAndOrientation(body, base.tolist(),
                                      p.getBasePositionAndOrientation(body,
                                                                      physicsClientId=client)[1],
                                      physicsClientId=client)
    robot = _Robot(model, body, base, client)
    robot.rest[:len(robot.arm)] = qs[len(qs) // 2].tolist()
    robot.set_arm(qs[0])
    for i in robot.movable:
        p.resetJointState(body, i, p.getJointState(body, i, physicsClientId=client)[0], 0.0,
                          physicsClientId=client)
    robot.release_motors()
    return robot


def _approaches(planned: Joint, handle: np.ndarray, sign: float, given: np.ndarray
                ) -> list[np.ndarray]:
    """The gripper's approaches (unit, towards the part) to try, in order: along the line in
    which the plan starts to move the handle (a hinge's handle along axis x lever, a slide's along
    its axis), first against that motion (the gripper pulls straight back along its own axis),
    then with it (it pushes a part that opens away from where it stands), whatever the part's
    surface normal was estimated to be (a handle's stored approach, from a part's mixed normals,
    can be 90 degrees off or reversed). Only the ``given`` approach when the handle lies on the
    hinge's axis (no direction of motion)."""
    line = motion_direction(planned.type, planned.axis, planned.origin, handle)
    if line is None:
        return [np.asarray(given, float) / np.linalg.norm(given)]
    return [-sign * line, sign * line]


def _facing(planned: Joint, handle: np.ndarray, approach: np.ndarray) -> np.ndarray:
    """Horizontal unit direction the robot faces: the approach's horizontal part; for a lid
    (an approach within ~70 degrees of vertical) from beyond the handle towards the hinge."""
    flat = np.array([approach[0], approach[1], 0.0])
    if np.linalg.norm(flat) < 0.35 and planned.type == "revolute":
        lever = np.asarray(planned.origin, float) - handle
        lever[2] = 0.0
        if np.linalg.norm(lever) > 1e-6:
            flat = lever
    if np.linalg.norm(flat) < 1e-9:
        flat = np.array([1.0, 0.0, 0.0])
    return flat / np.linalg.norm(flat)


def _grasp_pose(handle: np.ndarray, approach: np.ndarray) -> np.ndarray:
    """Gripper pose at the handle: z along the approach, x up, fingers closing horizontally."""
    z = np.asarray(approach, float) / np.linalg.norm(approach)
    x = np.array([0.0, 0.0, 1.0]) - z[2] * z
    if np.linalg.norm(x) < 1e-6:
        x = np.array([1.0, 0.0, 0.0]) - z[0] * z
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, :3] = np.stack([x, y, z], axis=1)
    T[:3, 3] = handle
    return T


def _rotvec(R: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    return Rotation.from_matrix(R).as_rotvec()


def _quat(R: np.ndarray) -> list[float]:
    from scipy.spatial.transform import Rotation

    return Rotation.from_matrix(R).as_quat().tolist()      # x y z w, as PyBullet


def _inverse_point(pos, orn, point, client: int) -> list[float]:
    import pybullet as p

    inv_pos, inv_orn = p.invertTransform(pos, orn)
    return list(p.multiplyTransforms(inv_pos, inv_orn, list(map(float, point)), [0, 0, 0, 1])[0])


def _point(pos, orn, local, client: int) -> np.ndarray:
    import pybullet as p

    return np.array(p.multiplyTransforms(pos, orn, local, [0, 0, 0, 1])[0])


def _camera(handle: np.ndarray, facing: np.ndarray, end: np.ndarray, size) -> tuple:
    """View and projection matrices looking at the handle's path from the robot's side, above."""
    import pybullet as p

    centre = (np.asarray(handle) + np.asarray(end)) / 2
    side = np.cross([0.0, 0.0, 1.0], facing)
    eye = centre - 1.6 * facing + 1.0 * side + np.array([0.0, 0.0, 0.8])
    view = p.computeViewMatrix(eye.tolist(), centre.tolist(), [0, 0, 1])
    proj = p.computeProjectionMatrixFOV(60, size[0] / size[1], 0.05, 10.0)
    return view, proj


def _render(camera: tuple, size, client: int) -> np.ndarray:
    import pybullet as p

    w, h = size
    _, _, rgba, _, _ = p.getCameraImage(w, h, viewMatrix=camera[0], projectionMatrix=camera[1],
                                        renderer=p.ER_TINY_RENDERER, physicsClientId=client)
    return np.asarray(rgba, np.uint8).reshape(h, w, 4)[:, :, :3].copy()
