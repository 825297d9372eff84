"""Robot models from ``pybullet_data``: their URDF, kinematic chain, and coloured link surfaces.

yourdfpy parses the URDF (a maintained URDF reader, so joints, mimics and inline materials are read
as ROS does); trimesh loads the visual meshes and samples their surfaces (area-uniform, with colour
from the texture or vertex colours the mesh carries, times the URDF material colour). The samples
are what the robot's Gaussian twin is made of (core/stages/robot_twin.py); they are cached on disk
per robot model and spacing (``$ARTGS_CACHE`` or ``~/.cache/artgs/robots``), since loading and
sampling meshes takes seconds.
"""

from __future__ import annotations

import io
import math
import os
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from ..geometry.kinematics import Chain, ChainJoint
from ..model import atomic
from ..model.robots import RobotModel

#: Bump when the sampling changes, so stale cache files are not used.
_SAMPLES_VERSION = 1


def pybullet_data_path() -> Path:
    import pybullet_data
    return Path(pybullet_data.getDataPath())


def robot_urdf(model: RobotModel) -> Path:
    """The model's URDF inside ``pybullet_data``."""
    return pybullet_data_path() / model.urdf


def _parse(urdf: Path):
    import yourdfpy
    return yourdfpy.URDF.load(str(urdf), load_meshes=False, build_scene_graph=False)


@lru_cache(maxsize=8)
def load_chain(urdf: Path) -> Chain:
    """The joint tree of ``urdf`` (parents first) for core.geometry.kinematics."""
    robot = _parse(Path(urdf)).robot
    children = {j.child for j in robot.joints}
    roots = [link.name for link in robot.links if link.name not in children]
    ordered: list[ChainJoint] = []
    frontier = list(roots[:1])
    remaining = list(robot.joints)
    while frontier:
        link = frontier.pop(0)
        for j in [j for j in remaining if j.parent == link]:
            remaining.remove(j)
            mimic = (j.mimic.joint, float(j.mimic.multiplier or 1.0), float(j.mimic.offset or 0.0)) \
                if j.mimic is not None else None
            axis = np.asarray(j.axis if j.axis is not None else (1.0, 0.0, 0.0), float)
            if not np.linalg.norm(axis) > 0:   # fixed joints may say "0 0 0"
                axis = np.array([1.0, 0.0, 0.0])
            limit = (-math.inf, math.inf)
            if j.type in ("revolute", "prismatic") and j.limit is not None \
                    and j.limit.lower is not None and j.limit.upper is not None:
                limit = (float(j.limit.lower), float(j.limit.upper))
            ordered.append(ChainJoint(j.name, j.type, j.parent, j.child,
                                      np.eye(4) if j.origin is None else np.asarray(j.origin, float),
                                      axis / np.linalg.norm(axis), mimic, limit))
            frontier.append(j.child)
    actuated = tuple(j.name for j in ordered if j.type != "fixed" and j.mimic is None)
    return Chain(roots[0], tuple(ordered), actuated)


@dataclass
class LinkSurface:
    """Surface samples of one link's visual meshes, in the link frame: points (N,3), unit normals
    (N,3), RGB colours (N,3) in 0..1."""

    points: np.ndarray
    normals: np.ndarray
    colors: np.ndarray


def _resolve(filename: str, urdf: Path) -> Path:
    """A mesh path of the URDF (``package://pkg/...`` or relative) as a file."""
    name = filename.split("://", 1)[1] if "://" in filename else filename
    for base in (urdf.parent, urdf.parent.parent):
        parts = Path(name).parts
        for k in range(len(parts)):
            p = base.joinpath(*parts[k:])
            if p.is_file():
                return p
    raise FileNotFoundError(f"{urdf}: mesh {filename!r} not found")


def _sample_mesh(mesh, n: int, rng: np.random.Generator) -> tuple[np.ndarray, ...]:
    import trimesh
    points, faces, colors = trimesh.sample.sample_surface(mesh, n, sample_color=True,
                                                          seed=int(rng.integers(1 << 31)))
    if colors is None or mesh.visual.kind is None:   # no colour in the mesh file: the material's
        colors = np.full((len(points), 4), 255.0)
    return points, mesh.face_normals[faces], np.asarray(colors, float)[:, :3] / 255.0


def sample_link_surfaces(model: RobotModel, spacing: float) -> dict[str, LinkSurface]:
    """Area-uniform samples every ``spacing`` metres (on average) over each link's visual meshes,
    cached on disk."""
    path = _cache_dir() / f"{model.name}_{spacing * 1000:.1f}mm_v{_SAMPLES_VERSION}.npz"
    if path.is_file():
        with np.load(path) as z:
            links = sorted({k.rsplit("/", 1)[0] for k in z.files})
            return {k: LinkSurface(z[f"{k}/points"], z[f"{k}/normals"], z[f"{k}/colors"])
                    for k in links}
    surfaces = _sample(model, spacing)
    buf = io.BytesIO()
    np.savez_compressed(buf, **{f"{k}/{f}": getattr(s, f).astype(np.float32) for k, s in
                                surfaces.items() for f in ("points", "normals", "colors")})
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic.write_bytes(path, buf.getvalue())
    return surfaces


def _cache_dir() -> Path:
    root = os.environ.get("ARTGS_CACHE")
    return Path(root) / "robots" if root else Path.home() / ".cache" / "artgs" / "robots"


def _sample(model: RobotModel, spacing: float) -> dict[str, LinkSurface]:
    import trimesh
    urdf = robot_urdf(model)
    robot = _parse(urdf).robot
    colours = {m.name: m.color.rgba for m in robot.materials if m.color is not None}
    for link in robot.links:
        for v in link.visuals:
            if v.material is not None and v.material.color is not None:
                colours.setdefault(v.material.name, v.material.color.rgba)
    rng = np.random.default_rng(0)
    out: dict[str, LinkSurface] = {}
    for link in robot.links:
        parts = []
        for v in link.visuals:
            if v.geometry is None or v.geometry.mesh is None:
                continue
            mesh = trimesh.load(_resolve(v.geometry.mesh.filename, urdf), force="mesh")
            if v.geometry.mesh.scale is not None:
                mesh.apply_scale(v.geometry.mesh.scale)
            if v.origin is not None:
                mesh.apply_transform(v.origin)
            n = max(int(mesh.area / spacing ** 2), 16)
            P, N, C = _sample_mesh(mesh, n, rng)
            rgba = None
            if v.material is not None:
                rgba = v.material.color.rgba if v.material.color is not None \
                    else colours.get(v.material.name)
            if rgba is not None:
                C = C * np.asarray(rgba, float)[:3]
            parts.append((P, N, C))
        if parts:
            out[link.name] = LinkSurface(*(np.concatenate([p[i] for p in parts]) for i in range(3)))
    return out
