"""Procedural articulated objects made of boxes: random specs per category, URDF text, ground truth.

Object frame (before the random base pose): x = front (the side with doors and drawers), y = to the
viewer's right when looking at the front, z = up, origin at the centre of the footprint on the floor.
The body is a hollow box (back, sides, top, bottom, plus dividers and shelves) open at the front where
the moving parts sit. Every moving part is a child link of the base with its joint frame axis-aligned
with the object frame; joint value 0 = closed:

- side-hinged door: joint origin on the hinge line at the door's outer face, axis +-z so that a
  positive angle swings the free edge outwards;
- bottom-hinged door: hinge along the bottom edge at the outer face, axis +y (opens downwards);
- drawer: prismatic along +x, joint origin at the centre of the drawer front (a point of the part).

The URDF has a root link ``world`` and a fixed joint ``base_pose`` carrying the base pose, so loading
it at the identity base pose places everything in the world frame. Every box is both a visual and a
collision shape, so the ground truth can be grasped and pushed in PyBullet (manipulation metric).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..model import atomic
from ..model.categories import KINDS
from ..model.joints import Joint
from ..sim import urdf

Rgba = tuple[float, float, float, float]


@dataclass(frozen=True)
class Box:
    """An axis-aligned box in its link frame: ``center``, ``half`` sizes, colour."""

    center: tuple[float, float, float]
    half: tuple[float, float, float]
    rgba: Rgba


@dataclass
class Part:
    """A moving part: joint (frame origin in the object frame, unit axis, limit) and its boxes."""

    name: str
    type: str
    origin: np.ndarray
    axis: np.ndarray
    limit: tuple[float, float]
    boxes: list[Box]
    handle: np.ndarray | None = None      # grasp point in the part frame (None: last box centre)

    @property
    def child(self) -> str:
        return f"{self.name}_link"


@dataclass
class ObjectSpec:
    """One synthetic object: category, base pose (4x4, object -> world), body boxes, moving parts."""

    category: str
    seed: int
    base_pose: np.ndarray
    body: list[Box]
    parts: list[Part] = field(default_factory=list)

    def joints(self) -> list[Joint]:
        """The ground-truth joints in the world frame (no states)."""
        R, t = self.base_pose[:3, :3], self.base_pose[:3, 3]
        return [Joint(name=q.name, type=q.type, axis=R @ q.axis, origin=R @ q.origin + t,
                      limit=q.limit, parent="base", child=q.child) for q in self.parts]

    def boxes_at(self, states: dict[str, float] | None = None
                 ) -> list[tuple[np.ndarray, np.ndarray, str]]:
        """Every box posed in the world at joint ``states`` (missing joints closed).

        Returns (box-to-world 4x4, half sizes, link name) triples.
        """
        states = states or {}
        out = []
        for b in self.body:
            out.append((self.base_pose @ urdf.translation(b.center), np.array(b.half), "base"))
        for q, joint in zip(self.parts, self.joints()):
            T = joint.transform(states.get(q.name, 0.0)) @ self.base_pose @ urdf.translation(q.origin)
            for b in q.boxes:
                out.append((T @ urdf.translation(b.center), np.array(b.half), q.child))
        return out

    def corners(self) -> np.ndarray:
        """World corners (8 per box) of every box of the closed object, (8 * boxes, 3)."""
        signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
        return np.concatenate([(signs * half) @ T[:3, :3].T + T[:3, 3]
                               for T, half, _ in self.boxes_at()])

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """World axis-aligned bounds (min, max) of the closed object."""
        pts = self.corners()
        return pts.min(0), pts.max(0)

    @property
    def key(self) -> tuple[int, int]:
        """Seed sequence prefix of this object's random streams."""
        return (self.seed, KINDS.index(self.category))

    def annotate(self, joints: list[Joint]) -> None:
        """Set each joint's ``extent`` (part's box in the object's axes, closed) and ``handle``."""
        R, t = self.base_pose[:3, :3], self.base_pose[:3, 3]
        for q, joint in zip(self.parts, joints):
            corners = np.array([np.array(b.center) + sgn * np.array(b.half) for b in q.boxes
                                for sgn in (np.array([-1, -1, -1]), np.array([1, 1, 1]))]) + q.origin
            lo, hi = corners.min(0), corners.max(0)
            joint.extent = {"center": [float(v) for v in R @ ((lo + hi) / 2) + t],
                            "axes": [[float(v) for v in row] for row in R.T],
                            "half_size": [float(v) for v in (hi - lo) / 2]}
            handle = q.handle if q.handle is not None else np.array(q.boxes[-1].center)
            joint.handle = {"point": [float(v) for v in R @ (handle + q.origin) + t],
                            "approach": [float(v) + 0.0 for v in -R[:, 0]]}

    def write_gt_urdf(self, root: Path) -> Path:
        """``root/gt.urdf`` (see :meth:`to_urdf`)."""
        path = root / "gt.urdf"
        atomic.write_text(path, self.to_urdf())
        return path

    def to_urdf(self) -> str:
        """URDF text: ``world`` root, fixed ``base_pose`` joint, base link, one link per part."""
        links = [urdf.Link("world"), _link("base", self.body)]
        joints = [urdf.UrdfJoint("base_pose", "fixed", "world", "base", origin=self.base_pose)]
        for q in self.parts:
            links.append(_link(q.child, q.boxes))
            joints.append(urdf.UrdfJoint(q.name, q.type, "base", q.child,
                                         origin=urdf.translation(q.origin),
                                         axis=tuple(float(v) for v in q.axis), limit=q.limit))
        return urdf.write_urdf(self.category, links, joints)


def box_distance(points: np.ndarray, boxes: list[tuple[np.ndarray, np.ndarray, str]]) -> np.ndarray:
    """Unsigned distance (N,) from world points to the nearest surface among posed ``boxes``."""
    best = np.full(len(points), np.inf)
    for T, half, _ in boxes:
        local = (points - T[:3, 3]) @ T[:3, :3]
        q = np.abs(local) - half
        outside = np.linalg.norm(np.maximum(q, 0.0), axis=1)
        inside = np.minimum(q.max(axis=1), 0.0)
        best = np.minimum(best, np.abs(outside + inside))
    return best


def _link(name: str, boxes: list[Box]) -> urdf.Link:
    """A link whose boxes are both visual and collision shapes (unit mass, nominal inertia)."""
    shapes = [(urdf.Box(tuple(2 * h for h in b.half)), urdf.translation(b.center), b.rgba)
              for b in boxes]
    return urdf.Link(name, [urdf.Geometry(s, T, rgba) for s, T, rgba in shapes],
                     [urdf.Geometry(s, T) for s, T, _ in shapes], urdf.Inertial(1.0))
