"""Checks of a written URDF against the world-frame joints it should reproduce.

- ``fk``: yourdfpy loads it; at every joint's lower and upper limit (one joint at a time, then all
  together) each link's pose in the base frame equals the motion composed from the world-frame
  joints (``core.model.joints``), to ``FK_TOL``. A link's closed-state frame is its joint's origin
  with the world's orientation (the convention of the export stage).
- ``collision``: PyBullet loads it; each joint is swept over its range (others closed) and the
  deepest penetration between the moving link and the base must not exceed the closed state's
  by more than ``PENETRATION_TOL`` (a part that swings or slides through the body fails).
- ``mujoco``: MuJoCo compiles it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ..model.joints import Joint
from .urdf import sanitize_name, translation

FK_TOL = 1e-6
PENETRATION_TOL = 0.01


def validate_urdf(path: str | Path, joints: list[Joint], sweep: int = 12) -> dict[str, Any]:
    """All three checks; ``ok`` when every one passed."""
    result = {"fk": fk_check(path, joints), "collision": collision_check(path, joints, sweep),
              "mujoco": mujoco_check(path)}
    result["ok"] = all(r["ok"] for r in result.values())
    return result


def expected_link_poses(joints: list[Joint], values: dict[str, float]) -> dict[str, np.ndarray]:
    """World pose of every link frame at joint ``values`` (missing joints 0)."""
    motion = {"base": np.eye(4)}
    poses = {"base": np.eye(4)}
    pending = list(joints)
    while pending:
        ready = [j for j in pending if j.parent in motion]
        if not ready:
            raise ValueError("joints do not form a tree rooted at 'base'")
        for j in ready:
            motion[j.child] = motion[j.parent] @ j.transform(values.get(j.name, 0.0))
            poses[j.child] = motion[j.child] @ translation(j.origin)
            pending.remove(j)
    return poses


def limit_configurations(joints: list[Joint]) -> list[dict[str, float]]:
    """Each joint alone at its lower and upper limit, then all at lower, all at upper."""
    cfgs = [{j.name: j.limit[k]} for j in joints for k in (0, 1)]
    if len(joints) > 1:
        cfgs += [{j.name: j.limit[k] for j in joints} for k in (0, 1)]
    return cfgs


def fk_check(path: str | Path, joints: list[Joint]) -> dict[str, Any]:
    """Largest deviation of yourdfpy's link poses from the world-frame joints at the limits."""
    import yourdfpy

    try:
        robot = yourdfpy.URDF.load(str(path), load_meshes=False, build_collision_scene_graph=False,
                                   load_collision_meshes=False)
    except Exception as exc:                              # noqa: BLE001 - report, don't crash
        return {"ok": False, "error": f"yourdfpy: {exc}"}
    worst = 0.0
    for cfg in limit_configurations(joints):
        robot.update_cfg({sanitize_name(k): v for k, v in cfg.items()})
        want = expected_link_poses(joints, cfg)
        for link, T in want.items():
            got = robot.get_transform(frame_to=sanitize_name(link), frame_from="base")
            worst = max(worst, float(np.abs(got - T).max()))
        robot.update_cfg({sanitize_name(j.name): 0.0 for j in joints})
    return {"ok": worst <= FK_TOL, "max_error": worst, "tolerance": FK_TOL}


def collision_check(path: str | Path, joints: list[Joint], sweep: int = 12) -> dict[str, Any]:
    """Per joint, the deepest moving-link/base penetration over the sweep vs the closed state."""
    import pybullet as p

    client = p.connect(p.DIRECT)
    try:
        try:     # two copies: PyBullet reports no closest points between links of one body
            body = p.loadURDF(str(path), useFixedBase=True, physicsClientId=client)
            fixed = p.loadURDF(str(path), useFixedBase=True, physicsClientId=client)
        except p.error as exc:
            return {"ok": False, "error": f"pybullet: {exc}"}
        index = {p.getJointInfo(body, i, physicsClientId=client)[1].decode(): i
                 for i in range(p.getNumJoints(body, physicsClientId=client))}
        per_joint = {}
        for j in joints:
            link = index[sanitize_name(j.name)]

            def depth(value: float) -> float:
                p.resetJointState(body, link, value, physicsClientId=client)
                pts = p.getClosestPoints(fixed, body, 0.0, linkIndexA=-1, linkIndexB=link,
                                         physicsClientId=client)
                return max([-c[8] for c in pts], default=0.0)

            closed = depth(0.0)
            worst = max(depth(v) for v in np.linspace(j.limit[0], j.limit[1], sweep))
            p.resetJointState(body, link, 0.0, physicsClientId=client)
            per_joint[j.name] = {"closed_penetration": round(closed, 5),
                                 "max_penetration": round(worst, 5),
                                 "ok": bool(worst <= closed + PENETRATION_TOL)}
        return {"ok": all(r["ok"] for r in per_joint.values()), "joints": per_joint,
                "tolerance": PENETRATION_TOL, "links": len(index) + 1}
    finally:
        p.disconnect(client)


def problems(result: dict[str, Any]) -> list[str]:
    """What a failed :func:`validate_urdf` means for the user: one line per failed check, each
    saying what to do (empty when all passed). A part that sweeps into the body is the usual one:
    a joint whose axis, point or range is wrong."""
    lines = []
    fk, collision, mujoco = result["fk"], result["collision"], result["mujoco"]
    if not fk["ok"]:
        why = fk.get("error") or f"off by up to {fk.get('max_error', float('nan')):.3g} m"
        lines.append(f"its forward kinematics do not reproduce the joints ({why}); please "
                     f"report this with the output folder")
    for name, r in collision.get("joints", {}).items():
        if not r["ok"]:
            deeper = 100 * (r["max_penetration"] - r["closed_penetration"])
            lines.append(f"joint '{name}' moves its part {deeper:.1f} cm deeper into the base "
                         f"over its limits than when closed "
                         f"(allowed {100 * PENETRATION_TOL:g} cm); fix its axis, point or limits "
                         f"(Bones panel: select the bone, edit Lower / Upper, Save Joints) or run "
                         f"Optimise Joints again, then Export URDF again")
    if "error" in collision:
        lines.append(f"the collision sweep could not run ({collision['error']})")
    if not mujoco["ok"]:
        lines.append(f"MuJoCo does not compile it ({mujoco.get('error', '')})")
    return lines


def mujoco_check(path: str | Path) -> dict[str, Any]:
    """Whether MuJoCo compiles the URDF (bodies, joints, meshes it made)."""
    import mujoco

    try:
        model = mujoco.MjModel.from_xml_path(str(path))
    except Exception as exc:                              # noqa: BLE001 - report, don't crash
        return {"ok": False, "error": str(exc).strip()[:400]}
    return {"ok": True, "bodies": int(model.nbody), "joints": int(model.njnt),
            "meshes": int(model.nmesh)}
