"""Articulated URDF assets (PartNet-Mobility style: ``mobility.urdf`` + textured OBJ meshes) as
synthetic subjects: scaled to a real size for their kind, standing on the floor, random yaw.

Frames. The asset is read with yourdfpy (parsing only; the kinematics are done here so that the
ground truth does not depend on the loader it is checked against). Its root frame is taken as
z up with the FRONT along -x (PartNet-Mobility's convention once the URDF's own root joint has
turned its y-up meshes z-up); the object frame of core.synth (x = front) is that turned 180 deg
about z, scaled, and moved so that the footprint's centre is at the origin and the lowest point on
z = 0.

Which joints open a part (the ground truth): revolute and prismatic joints (``continuous`` ones
are wheels and knobs) whose moving subtree is at least ``MIN_PART`` of the object's bounding
diagonal and whose range is at least ``MIN_ANGLE`` (revolute) or ``MIN_TRAVEL`` x the diagonal
(prismatic); ``joints=[...]`` overrides the rule. The closed state is the limit nearest 0 (0 when
the range contains it); the opening direction is towards the other limit, or, when the range spans
both sides of 0 by more than ``BOTH_SIDES`` of it, the side where the part ends farther from the
rest of the object (it swings out, not into the body). In ``gt.urdf`` every selected joint is
re-expressed so that 0 = closed and positive opens (limits (0, opening)); every other joint is
fixed at its closed value. Mesh files (and their MTL and textures) are copied beside gt.urdf.
"""

from __future__ import annotations

import math
import re
import shutil
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..model.errors import InputError
from ..model.joints import Joint, joint_transform, rotation_about_axis
from ..sim import urdf

#: Largest dimension (metres) of real objects per kind, drawn uniformly per capture.
REAL_SIZE = {"microwave": (0.45, 0.6), "oven": (0.6, 0.85), "refrigerator": (1.5, 1.9),
             "dishwasher": (0.8, 0.88), "drawer": (0.5, 1.0), "storage": (0.8, 1.8),
             "cabinet": (0.7, 1.2), "door": (1.95, 2.15), "washing_machine": (0.82, 0.9),
             "box": (0.3, 0.6), "box_rotate": (0.3, 0.6), "safe": (0.4, 0.7),
             "safe_rotate": (0.4, 0.7), "trash_can": (0.5, 0.8), "toilet": (0.7, 0.85),
             "window": (0.8, 1.4), "window_rotate": (0.8, 1.4), "chest": (0.4, 1.0)}
DEFAULT_SIZE = (0.6, 1.0)
MIN_PART, MIN_ANGLE, MIN_TRAVEL, BOTH_SIDES = 0.15, math.radians(20), 0.05, 0.1
#: Object frame = asset root frame turned by this yaw (front from -x to +x).
_FRONT = np.diag([-1.0, -1.0, 1.0])
_MAX_POINTS = 20000


@dataclass
class _Joint:
    name: str
    type: str
    parent: str
    child: str
    origin: np.ndarray                 # child frame in parent frame (unscaled)
    axis: np.ndarray
    limit: tuple[float, float]
    closed: float = 0.0
    sign: float = 1.0                  # +1: opens towards the upper limit
    opening: float = 0.0               # amount from closed to open (radians / unscaled units)


@dataclass
class _Visual:
    name: str
    filename: str
    scale: np.ndarray
    origin: np.ndarray
    points: np.ndarray                 # vertices in the link frame (unscaled), subsampled


@dataclass
class AssetSpec:
    """A URDF asset placed as a synthetic object (same interface as core.synth.objects.ObjectSpec
    where the generator needs it)."""

    category: str
    seed: int
    path: Path
    scale: float
    base_pose: np.ndarray              # object frame -> world
    root: str
    links: dict[str, tuple[list[_Visual], list[_Visual]]]
    tree: list[_Joint]                 # every joint, parents before children
    selected: list[str]
    placement: np.ndarray = field(default_factory=lambda: np.eye(4))  # asset root -> world (rigid)
    key: tuple[int, int] = (0, 0)      # seed sequence prefix of the capture's random streams

    # ----------------------------------------------------------------- kinematics
    def _frames(self) -> dict[str, np.ndarray]:
        """World frame of every link at the closed configuration (scaled tree)."""
        frames = {self.root: self.placement}
        for j in self.tree:
            frames[j.child] = frames[j.parent] @ self._origin(j)
        return frames

    def _origin(self, j: _Joint) -> np.ndarray:
        """Child frame in the parent frame with the joint at its closed value (scaled)."""
        O = j.origin.copy()
        O[:3, 3] *= self.scale
        if j.type in ("revolute", "continuous"):
            M = np.eye(4)
            M[:3, :3] = rotation_about_axis(j.axis, j.closed)
            O = O @ M
        elif j.type == "prismatic":
            O = O @ urdf.translation(j.axis * j.closed * self.scale)
        return O

    def _subtree(self, link: str) -> set[str]:
        out = {link}
        for j in self.tree:
            if j.parent in out:
                out.add(j.child)
        return out

    def _points(self, links: set[str] | None = None) -> np.ndarray:
        frames = self._frames()
        pts = [v.points * self.scale @ (frames[name] @ _scaled(v.origin, self.scale))[:3, :3].T
               + (frames[name] @ _scaled(v.origin, self.scale))[:3, 3]
               for name, (vis, _) in self.links.items() if links is None or name in links
               for v in vis]
        return np.concatenate(pts) if pts else np.zeros((0, 3))

    def joints(self) -> list[Joint]:
        """The ground-truth joints in the world frame (0 = closed, positive opens)."""
        frames = self._frames()
        by_name = {j.name: j for j in self.tree}
        out = []
        for name in self.selected:
            j = by_name[name]
            T = frames[j.child]
            axis = T[:3, :3] @ (j.sign * j.axis)
            hi = j.opening * (self.scale if j.type == "prismatic" else 1.0)
            out.append(Joint(name=name, type=j.type, axis=axis, origin=T[:3, 3].copy(),
                             limit=(0.0, float(hi)), parent="base", child=j.child))
        return out

    def corners(self) -> np.ndarray:
        """World points of the closed object (a subsample of its mesh vertices)."""
        return self._points()

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        pts = self.corners()
        return pts.min(0), pts.max(0)

    def annotate(self, joints: list[Joint]) -> None:
        """Set each joint's ``extent`` (moving subtree's box in the object's axes, closed) and
        ``handle`` (centre of visuals named *handle*, else the point farthest from the axis)."""
        R = self.base_pose[:3, :3]
        frames = self._frames()
        for joint in joints:
            links = self._subtree(joint.child)
            pts = self._points(links)
            local = pts @ R
            lo, hi = local.min(0), local.max(0)
            joint.extent = {"center": [float(v) for v in R @ ((lo + hi) / 2)],
                            "axes": [[float(v) for v in row] for row in R.T],
                            "half_size": [float(v) for v in (hi - lo) / 2]}
            handles = [v.points * self.scale @ (frames[n] @ _scaled(v.origin, self.scale))[:3, :3].T
                       + (frames[n] @ _scaled(v.origin, self.scale))[:3, 3]
                       for n in links for v in self.links[n][0] if "handle" in v.name.lower()]
            if handles:
                point = np.concatenate(handles).mean(0)
            elif joint.type == "revolute":
                off = pts - joint.origin
                off -= np.outer(off @ joint.axis, joint.axis)
                point = pts[int(np.argmax(np.linalg.norm(off, axis=1)))]
            else:
                point = pts[int(np.argmax(pts @ joint.axis))]
            joint.handle = {"point": [float(v) for v in point],
                            "approach": [float(v) + 0.0 for v in -R[:, 0]]}

    # ----------------------------------------------------------------- URDF
    def write_gt_urdf(self, root: Path) -> Path:
        """gt.urdf in ``root`` (meshes copied under ``root/asset/``); ``world`` root link and a
        fixed ``base_pose`` joint, so it loads in the world frame at the identity base pose."""
        copied: dict[str, str] = {}

        def mesh(v: _Visual) -> urdf.Mesh:
            if v.filename not in copied:
                copied[v.filename] = _copy_mesh(self.path.parent, v.filename, root / "asset")
            return urdf.Mesh(copied[v.filename], tuple(float(s) * self.scale for s in v.scale))

        links = [urdf.Link("world")]
        for name, (vis, col) in self.links.items():
            links.append(urdf.Link(
                name, [urdf.Geometry(mesh(v), _scaled(v.origin, self.scale)) for v in vis],
                [urdf.Geometry(mesh(v), _scaled(v.origin, self.scale)) for v in col],
                urdf.Inertial(1.0)))
        joints = [urdf.UrdfJoint("base_pose", "fixed", "world", self.root, origin=self.placement)]
        for j in self.tree:
            if j.name in self.selected:
                hi = j.opening * (self.scale if j.type == "prismatic" else 1.0)
                joints.append(urdf.UrdfJoint(j.name, j.type, j.parent, j.child,
                                             origin=self._origin(j),
                                             axis=tuple(float(v) for v in j.sign * j.axis),
                                             limit=(0.0, float(hi))))
            else:
                joints.append(urdf.UrdfJoint(j.name, "fixed", j.parent, j.child,
                                             origin=self._origin(j)))
        path = root / "gt.urdf"
        path.write_text(urdf.write_urdf(self.category, links, joints), encoding="utf-8")
        return path


def load_asset(path: str | Path, seed: int, kind: str | None = None,
               joints: list[str] | None = None, size: float | None = None,
               yaw: bool = True) -> AssetSpec:
    """Read an articulated URDF and place it as a real-size object (see the module docstring).

    ``kind``: default the name of the asset folder's parent (``<kind>/<id>/mobility.urdf``);
    ``size``: largest dimension in metres (default drawn from :data:`REAL_SIZE` for the kind).
    """
    import yourdfpy

    path = Path(path)
    if not path.is_file():
        raise InputError(path, "URDF file not found", field="--urdf")
    try:
        robot = yourdfpy.URDF.load(str(path), load_meshes=False, build_scene_graph=False,
                                   load_collision_meshes=False, build_collision_scene_graph=False)
    except Exception as exc:  # noqa: BLE001 - yourdfpy raises many kinds on bad XML
        raise InputError(path, f"cannot be read as URDF: {exc}") from exc
    kind = kind or path.parent.parent.name or "object"
    key = (seed, zlib.crc32(f"{kind}/{path.parent.name}".encode()))
    rng = np.random.default_rng(list(key))
    children = {j.child for j in robot.joint_map.values()}
    roots = [name for name in robot.link_map if name not in children]
    if len(roots) != 1:
        raise InputError(path, f"must have exactly one root link, found {roots}")
    tree = _ordered(robot, roots[0])
    links = {name: ([_visual(path, v, f"{name}.visual") for v in link.visuals
                     if v.geometry is not None and v.geometry.mesh is not None],
                    [_visual(path, c, f"{name}.collision", points=False) for c in link.collisions
                     if c.geometry is not None and c.geometry.mesh is not None])
             for name, link in robot.link_map.items()}
    spec = AssetSpec(kind, seed, path, 1.0, np.eye(4), roots[0], links, tree, [], key=key)
    # closed values first (they shape the object), then measure it
    for j in tree:
        lo, hi = j.limit
        j.closed = float(min(max(0.0, lo), hi)) if j.type in ("revolute", "prismatic") else 0.0
    all_pts = spec._points()
    if len(all_pts) == 0:
        raise InputError(path, "has no visual meshes")
    diag = float(np.linalg.norm(all_pts.max(0) - all_pts.min(0)))
    movable = [j for j in tree if j.type in ("revolute", "prismatic", "continuous")]
    names = {j.name for j in movable}
    if joints:
        unknown = [n for n in joints if n not in names]
        if unknown:
            raise InputError(path, f"no movable joint named {', '.join(unknown)} (movable: "
                             f"{', '.join(sorted(names)) or 'none'})", field="--joints")
    for j in movable:
        _direction(spec, j)
    if joints:
        spec.selected = [j.name for j in movable if j.name in joints]
    else:
        spec.selected = [j.name for j in movable if _opens_a_part(spec, j, diag)]
    for j in movable:                                 # continuous joints chosen by name
        if j.type == "continuous" and j.name in spec.selected:
            j.type, j.opening, j.sign = "revolute", math.pi / 2, 1.0
    if not spec.selected:
        raise InputError(path, "no joint opens a part (revolute/prismatic, part >= "
                         f"{MIN_PART:.0%} of the object); name them with --joints")
    # scale and placement
    lo_s, hi_s = REAL_SIZE.get(kind, DEFAULT_SIZE) if size is None else (size, size)
    ext = all_pts.max(0) - all_pts.min(0)
    spec.scale = float(rng.uniform(lo_s, hi_s) / ext.max())
    pts = all_pts * spec.scale @ _FRONT.T
    centre = np.array([(pts[:, 0].min() + pts[:, 0].max()) / 2,
                       (pts[:, 1].min() + pts[:, 1].max()) / 2, pts[:, 2].min()])
    to_object = np.eye(4)
    to_object[:3, :3] = _FRONT
    to_object[:3, 3] = -centre
    a, r, th = (rng.uniform(-math.pi, math.pi) if yaw else 0.0), rng.uniform(0.0, 0.5), \
        rng.uniform(-math.pi, math.pi)
    base = np.eye(4)
    base[:3, :3] = urdf.rpy_to_matrix((0.0, 0.0, a))
    base[:3, 3] = [r * math.cos(th), r * math.sin(th), 0.0] if yaw else 0.0
    spec.base_pose = base
    spec.placement = base @ to_object
    return spec


def _scaled(T: np.ndarray, s: float) -> np.ndarray:
    out = np.array(T, float)
    out[:3, 3] *= s
    return out


def _ordered(robot, root: str) -> list[_Joint]:
    """Joints parents-first from ``root``."""
    out, frontier = [], [root]
    by_parent: dict[str, list] = {}
    for j in robot.joint_map.values():
        by_parent.setdefault(j.parent, []).append(j)
    while frontier:
        link = frontier.pop(0)
        for j in sorted(by_parent.get(link, []), key=lambda j: j.name):
            lim = j.limit
            lo = float(lim.lower) if lim is not None and lim.lower is not None else 0.0
            hi = float(lim.upper) if lim is not None and lim.upper is not None else 0.0
            axis = np.asarray(j.axis if j.axis is not None else (1.0, 0.0, 0.0), float)
            out.append(_Joint(j.name, j.type, j.parent, j.child,
                              np.asarray(j.origin if j.origin is not None else np.eye(4), float),
                              axis / np.linalg.norm(axis), (min(lo, hi), max(lo, hi))))
            frontier.append(j.child)
    return out


def _visual(urdf_path: Path, v, label: str, points: bool = True) -> _Visual:
    m = v.geometry.mesh
    scale = np.ones(3) if m.scale is None else np.broadcast_to(np.asarray(m.scale, float), (3,))
    origin = np.asarray(v.origin if v.origin is not None else np.eye(4), float)
    pts = np.zeros((0, 3))
    if points:
        pts = _vertices(urdf_path.parent / m.filename, label) * scale
    return _Visual(getattr(v, "name", None) or "", m.filename, scale, origin, pts)


def _vertices(path: Path, label: str) -> np.ndarray:
    """Vertices of an OBJ (read directly: 'v x y z' lines), subsampled."""
    if not path.is_file():
        raise InputError(path, "mesh file not found", field=label)
    if path.suffix.lower() == ".obj":
        vals = [ln.split()[1:4] for ln in path.read_text(errors="replace").splitlines()
                if ln.startswith("v ")]
        pts = np.asarray(vals, float).reshape(-1, 3)
    else:
        import trimesh
        pts = np.asarray(trimesh.load(str(path), force="mesh").vertices, float)
    if len(pts) > _MAX_POINTS:
        pts = pts[np.linspace(0, len(pts) - 1, _MAX_POINTS).astype(int)]
    return pts


def _direction(spec: AssetSpec, j: _Joint) -> None:
    """Closed value, opening direction and amount (see the module docstring)."""
    lo, hi = j.limit
    if j.type == "continuous":
        j.opening = 0.0
        return
    up, down = hi - j.closed, j.closed - lo
    span = max(hi - lo, 1e-12)
    if up > BOTH_SIDES * span and down > BOTH_SIDES * span:
        moving = spec._subtree(j.child)
        part = spec._points(moving)
        rest = spec._points(set(spec.links) - moving)
        centre = (rest.min(0) + rest.max(0)) / 2 if len(rest) else np.zeros(3)
        T = spec._frames()[j.child]
        axis, origin = T[:3, :3] @ j.axis, T[:3, 3]
        ends = []
        for value in (up, -down):
            M = joint_transform(j.type, axis, origin, value)
            moved = part @ M[:3, :3].T + M[:3, 3]
            ends.append(float(np.linalg.norm(moved - centre, axis=1).mean()))
        j.sign = 1.0 if ends[0] >= ends[1] else -1.0
    else:
        j.sign = 1.0 if up >= down else -1.0
    j.opening = up if j.sign > 0 else down


def _opens_a_part(spec: AssetSpec, j: _Joint, diag: float) -> bool:
    if j.type not in ("revolute", "prismatic"):
        return False
    pts = spec._points(spec._subtree(j.child))
    if len(pts) == 0 or np.linalg.norm(pts.max(0) - pts.min(0)) < MIN_PART * diag:
        return False
    return j.opening >= (MIN_ANGLE if j.type == "revolute" else MIN_TRAVEL * diag)


_MTLLIB = re.compile(r"^\s*mtllib\s+(.+?)\s*$", re.M)
_MAP = re.compile(r"^\s*map_\w+\s+(?:-\S+\s+\S+\s+)*(.+?)\s*$", re.M)


def _copy_mesh(src_root: Path, rel: str, dst_root: Path) -> str:
    """Copy a mesh (and for OBJ its MTL files and their textures) keeping relative paths; the
    path to write in gt.urdf (relative to the capture folder)."""
    src = (src_root / rel).resolve()
    rel_path = Path(rel)
    if rel_path.is_absolute() or ".." in rel_path.parts:
        rel_path = Path("meshes") / src.name
    dst = dst_root / rel_path
    files = [(src, dst)]
    if src.suffix.lower() == ".obj":
        for lib in _MTLLIB.findall(src.read_text(errors="replace")):
            mtl = src.parent / lib
            if mtl.is_file():
                files.append((mtl, dst.parent / lib))
                for tex in _MAP.findall(mtl.read_text(errors="replace")):
                    if (mtl.parent / tex).is_file():
                        files.append((mtl.parent / tex, (dst.parent / lib).parent / tex))
    for a, b in files:
        b = Path(str(b))
        if not b.exists():
            b.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(a, b)
    return str(Path(dst_root.name) / rel_path)
