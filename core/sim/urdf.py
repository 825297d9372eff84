"""URDF writing: a small typed description of links and joints, serialised to URDF text.

Used by every producer of URDF in the project (synthetic ground truth, rendered assets, export).
Conventions:

- Every pose is a 4x4 matrix. A joint's ``origin`` is the child link frame expressed in the PARENT
  link's frame (as URDF requires); its ``axis`` is expressed in the joint (= child link) frame.
  :func:`joint_in_parent` turns a world-frame joint (axis, a point on the axis) into that form.
- A geometry's ``origin`` is its pose in its link's frame.
- Names are sanitised (:func:`sanitize_name`): letters, digits, ``_`` and ``-``; link and joint
  names must be unique, which :func:`write_urdf` checks.
- Numbers are written with 12 significant digits, so poses survive the text round trip to ~1e-12.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from xml.sax.saxutils import quoteattr

import numpy as np

Rgba = tuple[float, float, float, float]


@dataclass(frozen=True)
class Box:
    """A box of full edge lengths ``size`` (metres), centred at its geometry origin."""

    size: tuple[float, float, float]


@dataclass(frozen=True)
class Cylinder:
    """A cylinder along the local z axis."""

    radius: float
    length: float


@dataclass(frozen=True)
class Mesh:
    """A mesh file (path as written into the URDF, usually relative to it) with a per-axis scale."""

    filename: str
    scale: tuple[float, float, float] = (1.0, 1.0, 1.0)


Shape = Box | Cylinder | Mesh


@dataclass(frozen=True)
class Geometry:
    """A visual or collision element: shape, pose in the link frame, optional colour."""

    shape: Shape
    origin: np.ndarray = field(default_factory=lambda: np.eye(4))
    rgba: Rgba | None = None


@dataclass(frozen=True)
class Inertial:
    """Mass (kg), centre of mass in the link frame, inertia tensor (3x3) about the centre of mass."""

    mass: float
    com: tuple[float, float, float] = (0.0, 0.0, 0.0)
    inertia: np.ndarray = field(default_factory=lambda: 0.1 * np.eye(3))


@dataclass
class Link:
    """A URDF link: visuals, collisions and an inertial (None = no inertial element)."""

    name: str
    visuals: list[Geometry] = field(default_factory=list)
    collisions: list[Geometry] = field(default_factory=list)
    inertial: Inertial | None = None


@dataclass
class UrdfJoint:
    """A URDF joint: ``origin`` = child frame in the parent frame, ``axis`` in the joint frame."""

    name: str
    type: str                                  # revolute | prismatic | continuous | fixed
    parent: str
    child: str
    origin: np.ndarray = field(default_factory=lambda: np.eye(4))
    axis: tuple[float, float, float] = (1.0, 0.0, 0.0)
    limit: tuple[float, float] | None = None
    effort: float = 10.0
    velocity: float = 1.0
    damping: float = 0.0
    friction: float = 0.0


_NAME_BAD = re.compile(r"[^A-Za-z0-9_\-]")


def sanitize_name(name: str) -> str:
    """``name`` made safe for URDF and file names (other characters -> ``_``; never empty)."""
    clean = _NAME_BAD.sub("_", str(name).strip())
    return clean or "_"


def box_inertial(mass: float, size, com=(0.0, 0.0, 0.0)) -> Inertial:
    """Inertial of a solid box of full edge lengths ``size`` centred at ``com``."""
    x, y, z = (float(v) for v in size)
    I = mass / 12.0 * np.diag([y * y + z * z, x * x + z * z, x * x + y * y])
    return Inertial(float(mass), tuple(float(v) for v in com), I)


def translation(xyz) -> np.ndarray:
    """4x4 pure translation."""
    T = np.eye(4)
    T[:3, 3] = np.asarray(xyz, float)
    return T


def rpy_to_matrix(rpy) -> np.ndarray:
    """URDF roll-pitch-yaw (fixed axes x, y, z) -> 3x3 rotation ``Rz(yaw) Ry(pitch) Rx(roll)``."""
    r, p, y = (float(v) for v in rpy)
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def matrix_to_rpy(R: np.ndarray) -> tuple[float, float, float]:
    """3x3 rotation -> URDF roll-pitch-yaw (inverse of :func:`rpy_to_matrix`, also at gimbal lock)."""
    R = np.asarray(R, float)
    sp = -R[2, 0]
    if abs(sp) < 1.0 - 1e-12:
        pitch = math.asin(sp)
        roll = math.atan2(R[2, 1], R[2, 2])
        yaw = math.atan2(R[1, 0], R[0, 0])
    else:                                      # pitch = +-90 deg: only roll - yaw (or + yaw) is defined
        pitch = math.copysign(math.pi / 2, sp)
        roll = 0.0
        yaw = math.atan2(-R[0, 1], R[1, 1])
    return roll, pitch, yaw


def joint_in_parent(parent_to_world: np.ndarray, axis_world, point_world
                    ) -> tuple[np.ndarray, tuple[float, float, float]]:
    """A world-frame joint (unit axis, point on the axis) as URDF wants it: the joint frame in the
    parent link frame (placed at ``point_world``, oriented as the parent) and the axis in it."""
    inv = np.linalg.inv(parent_to_world)
    origin = translation(inv[:3, :3] @ np.asarray(point_world, float) + inv[:3, 3])
    axis = inv[:3, :3] @ np.asarray(axis_world, float)
    axis = axis / np.linalg.norm(axis)
    return origin, (float(axis[0]), float(axis[1]), float(axis[2]))


def write_urdf(robot: str, links: list[Link], joints: list[UrdfJoint], extensions: str = "") -> str:
    """URDF text of the robot; checks that names are unique and joints connect known links.

    ``extensions``: XML put verbatim inside ``<robot>`` for other readers (e.g. a ``<mujoco>``
    element; PyBullet and yourdfpy ignore unknown elements)."""
    names = [sanitize_name(k.name) for k in links]
    if len(set(names)) != len(names):
        raise ValueError(f"duplicate link names in {names}")
    jnames = [sanitize_name(j.name) for j in joints]
    if len(set(jnames)) != len(jnames):
        raise ValueError(f"duplicate joint names in {jnames}")
    known = set(names)
    for j in joints:
        for end in (j.parent, j.child):
            if sanitize_name(end) not in known:
                raise ValueError(f"joint {j.name!r} refers to unknown link {end!r}")
    lines = ['<?xml version="1.0"?>', f"<robot name={quoteattr(sanitize_name(robot))}>"]
    if extensions:
        lines.append(f"  {extensions}")
    for link in links:
        lines += _link(link)
    for j in joints:
        lines += _joint(j)
    lines.append("</robot>")
    return "\n".join(lines) + "\n"


def _f(x: float) -> str:
    v = float(x)
    return "0" if v == 0 else f"{v:.12g}"


def _v(v) -> str:
    return " ".join(_f(x) for x in v)


def _origin(T: np.ndarray) -> str:
    T = np.asarray(T, float)
    return f'<origin xyz="{_v(T[:3, 3])}" rpy="{_v(matrix_to_rpy(T[:3, :3]))}"/>'


def _shape(shape: Shape) -> str:
    if isinstance(shape, Box):
        return f'<box size="{_v(shape.size)}"/>'
    if isinstance(shape, Cylinder):
        return f'<cylinder radius="{_f(shape.radius)}" length="{_f(shape.length)}"/>'
    return f"<mesh filename={quoteattr(shape.filename)} scale=\"{_v(shape.scale)}\"/>"


def _link(link: Link) -> list[str]:
    name = sanitize_name(link.name)
    if link.inertial is None and not link.visuals and not link.collisions:
        return [f'  <link name="{name}"/>']
    lines = [f'  <link name="{name}">']
    if link.inertial is not None:
        m, I = link.inertial, np.asarray(link.inertial.inertia, float)
        lines += [f'    <inertial><origin xyz="{_v(m.com)}" rpy="0 0 0"/><mass value="{_f(m.mass)}"/>'
                  f'<inertia ixx="{_f(I[0, 0])}" ixy="{_f(I[0, 1])}" ixz="{_f(I[0, 2])}" '
                  f'iyy="{_f(I[1, 1])}" iyz="{_f(I[1, 2])}" izz="{_f(I[2, 2])}"/></inertial>']
    for k, g in enumerate(link.visuals):
        lines += ["    <visual>", f"      {_origin(g.origin)}",
                  f"      <geometry>{_shape(g.shape)}</geometry>"]
        if g.rgba is not None:
            lines.append(f'      <material name="{name}_{k}"><color rgba="{_v(g.rgba)}"/></material>')
        lines.append("    </visual>")
    for g in link.collisions:
        lines += ["    <collision>", f"      {_origin(g.origin)}",
                  f"      <geometry>{_shape(g.shape)}</geometry>", "    </collision>"]
    lines.append("  </link>")
    return lines


def _joint(j: UrdfJoint) -> list[str]:
    lines = [f'  <joint name="{sanitize_name(j.name)}" type="{j.type}">',
             f'    <parent link="{sanitize_name(j.parent)}"/>',
             f'    <child link="{sanitize_name(j.child)}"/>',
             f"    {_origin(j.origin)}"]
    if j.type != "fixed":
        lines.append(f'    <axis xyz="{_v(j.axis)}"/>')
        if j.damping or j.friction:
            lines.append(f'    <dynamics damping="{_f(j.damping)}" friction="{_f(j.friction)}"/>')
    if j.type in ("revolute", "prismatic"):
        lo, hi = j.limit if j.limit is not None else (0.0, 0.0)
        lines.append(f'    <limit lower="{_f(lo)}" upper="{_f(hi)}" effort="{_f(j.effort)}" '
                     f'velocity="{_f(j.velocity)}"/>')
    elif j.type == "continuous":
        lines.append(f'    <limit effort="{_f(j.effort)}" velocity="{_f(j.velocity)}"/>')
    lines.append("  </joint>")
    return lines
