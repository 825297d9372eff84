"""Reading any URDF into world-frame joints and link poses, and rewriting its joints (numpy and
xml.etree only: Blender's process imports this).

:func:`read_urdf` gives, at zero joint values, every link's world pose, its visual meshes (file
resolved next to the URDF; ``package://`` stripped to a relative path), and the revolute,
continuous and prismatic joints as :class:`core.model.joints.Joint` in the world frame (axis and
origin = the joint frame's position) — ours, PyBullet's examples and PartNet-Mobility's
``mobility.urdf`` alike. :func:`rewrite_joints` writes a copy of a URDF whose joints are replaced
by edited world-frame joints: the child link frame moves to the new joint origin (its orientation
is kept) and everything expressed in that frame (visuals, collisions, inertial, child joints) is
re-expressed so nothing else moves. Generating new URDFs is core/sim/urdf.py's job.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import InputError
from .joints import Articulation, Joint

MOVABLE = ("revolute", "continuous", "prismatic")


@dataclass
class Visual:
    """A visual mesh of a link: file, pose in the link frame, scale, colour (RGBA or None)."""

    path: Path | None
    origin: np.ndarray
    scale: np.ndarray
    rgba: tuple[float, float, float, float] | None = None
    box: np.ndarray | None = None        # full edge lengths, for <box> geometry


@dataclass
class UrdfModel:
    """What :func:`read_urdf` found."""

    name: str
    root: str
    link_poses: dict[str, np.ndarray]            # world pose at zero joint values
    visuals: dict[str, list[Visual]] = field(default_factory=dict)
    joints: list[Joint] = field(default_factory=list)
    moving_link: dict[str, str] = field(default_factory=dict)   # link -> joint that moves it


def read_urdf(path: str | Path) -> UrdfModel:
    """Parse ``path`` (see the module docstring); errors name the file and element."""
    path = Path(path)
    tree = _parse(path)
    robot = tree.getroot()
    links = {el.get("name"): el for el in robot.findall("link")}
    joints = robot.findall("joint")
    children = {j.find("child").get("link") for j in joints if j.find("child") is not None}
    roots = [n for n in links if n not in children]
    if len(roots) != 1:
        raise InputError(path, f"needs exactly one root link, found {roots}", field="link")
    poses = {roots[0]: np.eye(4)}
    parent_of: dict[str, tuple[str, ET.Element]] = {}
    for j in joints:
        name = j.get("name")
        parent, child = j.find("parent"), j.find("child")
        if parent is None or child is None:
            raise InputError(path, "joint without parent or child", frame=name, field="joint")
        parent_of[child.get("link")] = (parent.get("link"), j)
    pending = [n for n in links if n != roots[0]]
    world_joints, moving = [], {}
    colours = _materials(robot)
    while pending:
        ready = [n for n in pending if parent_of.get(n, (None,))[0] in poses]
        if not ready:
            raise InputError(path, f"links not connected to the root: {pending}", field="joint")
        for link in ready:
            parent, j = parent_of[link]
            T = poses[parent] @ _origin(j)
            poses[link] = T
            kind = j.get("type")
            moving[link] = moving.get(parent, "") if kind not in MOVABLE else j.get("name")
            if kind in MOVABLE:
                axis_el = j.find("axis")
                axis = _floats(axis_el.get("xyz"), 3) if axis_el is not None else np.array([1.0, 0, 0])
                lim = j.find("limit")
                if kind == "continuous":
                    limit = (-math.pi, math.pi)
                else:
                    limit = (float(lim.get("lower", 0)) if lim is not None else 0.0,
                             float(lim.get("upper", 0)) if lim is not None else 0.0)
                world_joints.append(Joint(j.get("name"), "prismatic" if kind == "prismatic"
                                          else "revolute", T[:3, :3] @ axis, T[:3, 3],
                                          limit, parent=parent, child=link))
            pending.remove(link)
    # joints' parent links: the nearest link up the tree moved by a joint (or the root)
    for wj in world_joints:
        up = wj.parent
        while up != roots[0] and up not in {j.child for j in world_joints}:
            up = parent_of[up][0]
        wj.parent = "base" if up == roots[0] else up
    visuals = {n: [_visual(v, path, colours) for v in el.findall("visual")] for n, el in links.items()}
    return UrdfModel(robot.get("name", path.stem), roots[0], poses, visuals, world_joints,
                     {k: v for k, v in moving.items() if v})


def articulation_of(model: UrdfModel) -> Articulation:
    """The URDF's movable joints as an articulation (world frame, zero state)."""
    return Articulation([Joint(j.name, j.type, j.axis, j.origin, j.limit, parent=j.parent,
                               child=j.child) for j in model.joints], {"source_urdf": model.name})


def rewrite_joints(src: str | Path, joints: list[Joint], dst: str | Path) -> None:
    """Copy URDF ``src`` to ``dst`` with its movable joints set to the world-frame ``joints``
    (matched by name; others unchanged). Mesh paths are made absolute when ``dst`` is elsewhere."""
    src, dst = Path(src), Path(dst)
    tree = _parse(src)
    robot = tree.getroot()
    model = read_urdf(src)
    poses = dict(model.link_poses)
    by_name = {j.name: j for j in joints}
    link_el = {el.get("name"): el for el in robot.findall("link")}
    # new world pose of each link: the edited joint's origin, the link's old orientation
    new_poses = dict(poses)
    for wj in model.joints:
        if wj.name not in by_name:
            continue
        new = by_name[wj.name]
        T = np.eye(4)
        T[:3, :3] = poses[wj.child][:3, :3]
        T[:3, 3] = new.origin
        new_poses[wj.child] = T
    for el in robot.findall("joint"):
        parent = el.find("parent").get("link")
        child = el.find("child").get("link")
        origin = np.linalg.inv(new_poses[parent]) @ new_poses[child]
        _set_origin(el, origin)
        name = el.get("name")
        if name in by_name and el.get("type") in MOVABLE:
            new = by_name[name]
            axis = new_poses[child][:3, :3].T @ np.asarray(new.axis, float)
            axis_el = el.find("axis")
            if axis_el is None:
                axis_el = ET.SubElement(el, "axis")
            axis_el.set("xyz", _fmt(axis / np.linalg.norm(axis)))
            lim = el.find("limit")
            if el.get("type") != "continuous":
                if lim is None:
                    lim = ET.SubElement(el, "limit", effort="10", velocity="1")
                lim.set("lower", f"{new.limit[0]:.12g}")
                lim.set("upper", f"{new.limit[1]:.12g}")
            el.set("type", new.type if el.get("type") != "continuous" or new.type != "revolute"
                   else "continuous")
    for name, el in link_el.items():
        delta = np.linalg.inv(new_poses[name]) @ poses[name]
        if np.allclose(delta, np.eye(4), atol=1e-15):
            continue
        for tag in ("visual", "collision", "inertial"):
            for sub in el.findall(tag):
                _set_origin(sub, delta @ _origin(sub))
    if src.parent.resolve() != dst.parent.resolve():
        for mesh in robot.iter("mesh"):
            resolved = _resolve(mesh.get("filename", ""), src)
            if resolved is not None:
                mesh.set("filename", str(resolved))
    dst.parent.mkdir(parents=True, exist_ok=True)
    tree.write(dst, encoding="unicode", xml_declaration=True)


def _parse(path: Path) -> ET.ElementTree:
    if not path.is_file():
        raise InputError(path, "not found")
    try:
        tree = ET.parse(path)
    except ET.ParseError as exc:
        raise InputError(path, f"not valid XML ({exc})") from exc
    if tree.getroot().tag != "robot":
        raise InputError(path, f"root element must be <robot>, not <{tree.getroot().tag}>")
    return tree


def _floats(text: str | None, n: int) -> np.ndarray:
    values = [float(v) for v in (text or "").split()]
    if len(values) != n:
        raise ValueError(f"expected {n} numbers, got {text!r}")
    return np.array(values)


def _rpy(r: float, p: float, y: float) -> np.ndarray:
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def _to_rpy(R: np.ndarray) -> np.ndarray:
    sp = -R[2, 0]
    if abs(sp) < 1.0 - 1e-12:
        return np.array([math.atan2(R[2, 1], R[2, 2]), math.asin(sp), math.atan2(R[1, 0], R[0, 0])])
    return np.array([0.0, math.copysign(math.pi / 2, sp), math.atan2(-R[0, 1], R[1, 1])])


def _origin(el: ET.Element) -> np.ndarray:
    o = el.find("origin")
    T = np.eye(4)
    if o is not None:
        T[:3, 3] = _floats(o.get("xyz", "0 0 0"), 3)
        T[:3, :3] = _rpy(*_floats(o.get("rpy", "0 0 0"), 3))
    return T


def _set_origin(el: ET.Element, T: np.ndarray) -> None:
    o = el.find("origin")
    if o is None:
        o = ET.Element("origin")
        el.insert(0, o)
    o.set("xyz", _fmt(T[:3, 3]))
    o.set("rpy", _fmt(_to_rpy(T[:3, :3])))


def _fmt(v) -> str:
    return " ".join("0" if float(x) == 0 else f"{float(x):.15g}" for x in v)


def _materials(robot: ET.Element) -> dict[str, tuple]:
    out = {}
    for m in robot.iter("material"):
        c = m.find("color")
        if m.get("name") and c is not None and c.get("rgba"):
            out[m.get("name")] = tuple(float(v) for v in c.get("rgba").split())
    return out


def _resolve(filename: str, urdf: Path) -> Path | None:
    if not filename:
        return None
    if filename.startswith("package://"):
        rel = filename[len("package://"):]
        candidates = [urdf.parent / rel, urdf.parent / rel.split("/", 1)[-1]]
    elif filename.startswith("file://"):
        candidates = [Path(filename[len("file://"):])]
    else:
        candidates = [Path(filename) if Path(filename).is_absolute() else urdf.parent / filename]
    for c in candidates:
        if c.is_file():
            return c.resolve()
    return candidates[0]


def _visual(el: ET.Element, urdf: Path, colours: dict) -> Visual:
    geom = el.find("geometry")
    mesh = geom.find("mesh") if geom is not None else None
    box = geom.find("box") if geom is not None else None
    mat = el.find("material")
    rgba = None
    if mat is not None:
        c = mat.find("color")
        rgba = (tuple(float(v) for v in c.get("rgba").split()) if c is not None
                else colours.get(mat.get("name")))
    if mesh is not None:
        scale = _floats(mesh.get("scale"), 3) if mesh.get("scale") else np.ones(3)
        return Visual(_resolve(mesh.get("filename", ""), urdf), _origin(el), scale, rgba)
    size = _floats(box.get("size"), 3) if box is not None else None
    return Visual(None, _origin(el), np.ones(3), rgba, size)
