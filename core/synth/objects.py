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

import math
from pathlib import Path
from dataclasses import dataclass, field

import numpy as np

from ..model.categories import CATEGORIES, EXTRA_KINDS
from ..model import atomic
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


# --------------------------------------------------------------------------- random specs

#: Panel thickness of bodies, doors and drawer fronts (metres).
_PANEL = 0.018
_GAP = 0.004


class _Builder:
    """Collects the boxes of one object while a category generator lays it out."""

    def __init__(self, rng: np.random.Generator, width: float, depth: float, height: float,
                 variety: bool = False) -> None:
        self.rng = rng
        self.W, self.D, self.H = width, depth, height
        self.body: list[Box] = []
        self.parts: list[Part] = []
        self.outer = _colour(rng)
        self.inner = _shade(self.outer, rng.uniform(0.75, 1.2), rng)
        self.front = _shade(self.outer, rng.uniform(0.85, 1.15), rng) if rng.random() < 0.5 \
            else _colour(rng)
        self.handle = _colour(rng, metal=True)
        self.handle_kind, self.framed = "bar", False
        if variety:                  # drawn after the plain draws: plain objects stay unchanged
            if rng.random() < 0.35:
                self.front = self.outer          # parts in the body's colour (and texture)
            self.handle_kind = str(rng.choice(HANDLES))
            self.framed = bool(rng.random() < 0.4)

    def panel(self, x0: float, x1: float, y0: float, y1: float, z0: float, z1: float,
              rgba: Rgba | None = None) -> None:
        """A fixed box of the body from its bounds in the object frame."""
        self.body.append(_box(x0, x1, y0, y1, z0, z1, _shade(rgba or self.outer, 1.0, self.rng)))

    def hollow_body(self, top: bool = True, front: bool = False) -> None:
        """Back, sides, bottom and (``top``) top panels; open at the front unless ``front``."""
        W, D, H, t = self.W, self.D, self.H, _PANEL
        self.panel(-D / 2, -D / 2 + t, -W / 2, W / 2, 0, H)                     # back
        self.panel(-D / 2, D / 2, -W / 2, -W / 2 + t, 0, H)                     # sides
        self.panel(-D / 2, D / 2, W / 2 - t, W / 2, 0, H)
        if top:
            self.panel(-D / 2, D / 2, -W / 2 + t, W / 2 - t, H - t, H)          # top
        self.panel(-D / 2, D / 2, -W / 2 + t, W / 2 - t, 0, t)                  # bottom
        if front:
            self.panel(D / 2 - t, D / 2, -W / 2 + t, W / 2 - t, t, H)

    def shelf(self, z: float, y0: float | None = None, y1: float | None = None) -> None:
        """A horizontal inner panel (shelf or divider) at height ``z``."""
        W, D, t = self.W, self.D, _PANEL
        y0 = -W / 2 + t if y0 is None else y0
        y1 = W / 2 - t if y1 is None else y1
        self.panel(-D / 2 + t, D / 2 - 0.01, y0, y1, z - t / 2, z + t / 2, self.inner)

    def front_strip(self, y0: float, y1: float, z0: float, z1: float) -> None:
        """A fixed front panel (control strip, plinth) flush with the door faces."""
        self.panel(self.D / 2, self.D / 2 + _PANEL, y0 + _GAP / 2, y1 - _GAP / 2,
                   z0 + _GAP / 2, z1 - _GAP / 2, self.front)

    def _frame(self, y0: float, y1: float, z0: float, z1: float, x: float) -> list[Box]:
        """A raised frame (four strips) on a door face spanning [y0,y1]x[z0,z1] at depth ``x``."""
        if not self.framed:
            return []
        b = min(0.06, 0.12 * min(y1 - y0, z1 - z0))
        c = _shade(self.front, 0.9, self.rng)
        return [_box(x, x + 0.012, y0, y1, z0, z0 + b, c), _box(x, x + 0.012, y0, y1, z1 - b, z1, c),
                _box(x, x + 0.012, y0, y0 + b, z0 + b, z1 - b, c),
                _box(x, x + 0.012, y1 - b, y1, z0 + b, z1 - b, c)]

    def _grip(self, x: float, y: float, z: float, along: str, length: float, depth: float = 0.03
              ) -> tuple[list[Box], np.ndarray]:
        """Handle boxes at the point (x on the face, y, z) of a part frame and its grasp point.

        ``along`` = y or z: the bar's direction for the kind ``bar``; ``long`` bars are 2.5 x as
        long, ``knob`` is a small cube, ``none`` is a grip recess (no box)."""
        kind = self.handle_kind
        if kind == "none":
            return [], np.array([x, y, z])
        if kind == "knob":
            return [_box(x, x + 0.035, y - 0.017, y + 0.017, z - 0.017, z + 0.017, self.handle)], \
                np.array([x + 0.02, y, z])
        if kind == "long":
            length *= 2.5
        if kind == "horizontal":
            along = "y" if along == "z" else "z"
        hy = length / 2 if along == "y" else 0.011
        hz = length / 2 if along == "z" else 0.011
        box = _box(x, x + depth, y - hy, y + hy, z - hz, z + hz, self.handle)
        return [box], np.array(box.center)

    def side_door(self, name: str, y0: float, y1: float, z0: float, z1: float, hinge: str,
                  limit: tuple[float, float], face: float | None = None,
                  thickness: float = _PANEL, handle_z: float = 0.0) -> None:
        """A door covering the front cell [y0,y1]x[z0,z1], hinged on its ``hinge`` (left/right).

        Its outer face is at x = ``face`` (default: a panel in front of the body)."""
        y0, y1, z0, z1 = y0 + _GAP / 2, y1 - _GAP / 2, z0 + _GAP / 2, z1 - _GAP / 2
        t, w, h = thickness, y1 - y0, z1 - z0
        face = self.D / 2 + _PANEL if face is None else face
        left = hinge == "left"
        origin = np.array([face, y0 if left else y1, (z0 + z1) / 2])
        s = 1.0 if left else -1.0              # direction from the hinge to the free edge, along y
        axis = np.array([0.0, 0.0, -s])
        boxes = [_box(-t, 0, 0, s * w, -h / 2, h / 2, self.front)]
        boxes += self._frame(min(0, s * w), max(0, s * w), -h / 2, h / 2, 0.0)
        hl = min(max(0.3 * h, 0.1), 0.5)
        hy = s * (w - min(0.06, 0.15 * w))
        hz = float(np.clip(handle_z, -h / 2 + hl, h / 2 - hl)) if handle_z else 0.0
        if self.handle_kind == "horizontal":
            hl = min(hl, 0.4 * w)
            hy = s * (w - 0.04 - hl / 2)
        grip, point = self._grip(0.0, hy, hz, "z", hl)
        self.parts.append(Part(name, "revolute", origin, axis, limit, boxes + grip, point))

    def bottom_door(self, name: str, y0: float, y1: float, z0: float, z1: float,
                    limit: tuple[float, float]) -> None:
        """A door covering the front cell, hinged along its bottom edge (opens downwards)."""
        y0, y1, z0, z1 = y0 + _GAP / 2, y1 - _GAP / 2, z0 + _GAP / 2, z1 - _GAP / 2
        t, w, h = _PANEL, y1 - y0, z1 - z0
        origin = np.array([self.D / 2 + t, (y0 + y1) / 2, z0])
        boxes = [_box(-t, 0, -w / 2, w / 2, 0, h, self.front)]
        boxes += self._frame(-w / 2, w / 2, 0, h, 0.0)
        hz = h - min(0.05, 0.15 * h)
        grip, point = self._grip(0.0, 0.0, hz, "y", 0.6 * w if self.handle_kind != "long" else 0.36 * w)
        self.parts.append(Part(name, "revolute", origin, np.array([0.0, 1.0, 0.0]), limit,
                               boxes + grip, point))

    def round_door(self, name: str, yc: float, zc: float, r: float, limit: tuple[float, float]
                   ) -> None:
        """A round door (a disc of slabs) hinged at its left edge, over a square hole."""
        t = 0.03
        origin = np.array([self.D / 2 + _PANEL + t, yc - r, zc])
        boxes = []
        n = 9
        for k in range(n):
            za, zb = -r + 2 * r * k / n, -r + 2 * r * (k + 1) / n
            half = math.sqrt(max(r * r - max(za * za, zb * zb), 0.0)) if k not in (n // 2,) else r
            half = max(half, 0.2 * r)
            boxes.append(_box(-t, 0, r - half, r + half, za, zb, self.front))
        boxes.append(_box(-t + 0.002, 0.004, 0.35 * r, 1.65 * r, -0.65 * r, 0.65 * r,
                          _shade(self.inner, 0.6, self.rng)))                # glass
        grip, point = self._grip(0.0, 2 * r - 0.04, 0.0, "z", 0.3 * r)
        self.parts.append(Part(name, "revolute", origin, np.array([0.0, 0.0, -1.0]), limit,
                               boxes + grip, point))

    def drawer(self, name: str, y0: float, y1: float, z0: float, z1: float) -> None:
        """A drawer: front panel over the cell plus a tray (bottom, sides, back) inside the body."""
        y0, y1, z0, z1 = y0 + _GAP / 2, y1 - _GAP / 2, z0 + _GAP / 2, z1 - _GAP / 2
        t, w, h = _PANEL, y1 - y0, z1 - z0
        origin = np.array([self.D / 2 + t / 2, (y0 + y1) / 2, (z0 + z1) / 2])
        tray_depth = self.D - 2.5 * t
        tw, th = w / 2 - 0.02, 0.7 * h
        x0 = -t / 2 - tray_depth
        bottom = -h / 2 + 0.015
        boxes = [_box(-t / 2, t / 2, -w / 2, w / 2, -h / 2, h / 2, self.front),
                 _box(x0, -t / 2, -tw, tw, bottom, bottom + 0.012, self.inner),
                 _box(x0, -t / 2, -tw, -tw + 0.012, bottom, bottom + th, self.inner),
                 _box(x0, -t / 2, tw - 0.012, tw, bottom, bottom + th, self.inner),
                 _box(x0, x0 + 0.012, -tw + 0.012, tw - 0.012, bottom, bottom + th, self.inner)]
        boxes += self._frame(-w / 2, w / 2, -h / 2, h / 2, t / 2)
        length = min(0.5 * w, 0.3) if self.handle_kind != "long" else 0.35 * w
        grip, point = self._grip(t / 2, 0.0, 0.0, "y", length, depth=0.025)
        limit = (0.0, float(self.rng.uniform(0.6, 0.85) * tray_depth))
        self.parts.append(Part(name, "prismatic", origin, np.array([1.0, 0.0, 0.0]), limit,
                               boxes + grip, point))


#: Handle kinds of objects drawn with variety.
HANDLES = ("bar", "long", "knob", "horizontal", "none")


def random_spec(category: str, seed: int, variety: bool = False) -> ObjectSpec:
    """A random object of ``category`` (one of :data:`KINDS`); the same (category, seed, variety)
    always gives the same object. ``variety``: parts may share the body's colour, handles of
    several kinds or none, framed doors, layouts beyond the plain ones; the object stands on z = 0.
    """
    if category not in KINDS:
        raise ValueError(f"unknown category {category!r}; expected one of {KINDS}")
    if category not in CATEGORIES and not variety:
        raise ValueError(f"{category!r} objects exist only with variety")
    rng = np.random.default_rng([seed, KINDS.index(category)])
    b = _LAYOUTS[category](rng, variety)
    yaw = rng.uniform(-math.pi, math.pi)
    r = rng.uniform(0.0, 0.5)
    a = rng.uniform(-math.pi, math.pi)
    if category == "microwave":
        z = float(rng.choice([0.0, rng.uniform(0.7, 0.95)]))
    else:
        z = 0.0 if rng.random() < 0.5 else float(rng.uniform(-0.2, 0.4))
    pose = np.eye(4)
    pose[:3, :3] = np.array([[math.cos(yaw), -math.sin(yaw), 0.0],
                             [math.sin(yaw), math.cos(yaw), 0.0], [0.0, 0.0, 1.0]])
    pose[:3, 3] = [r * math.cos(a), r * math.sin(a), 0.0 if variety else z]
    return ObjectSpec(category, seed, pose, b.body, b.parts)


def _revolute_limit(rng: np.random.Generator, lo: float, hi: float) -> tuple[float, float]:
    return (0.0, float(rng.uniform(lo, hi)))


def _dishwasher(rng: np.random.Generator, variety: bool) -> _Builder:
    b = _Builder(rng, rng.uniform(0.55, 0.65), rng.uniform(0.55, 0.65), rng.uniform(0.8, 0.9), variety)
    b.hollow_body()
    strip = rng.uniform(0.08, 0.12)
    b.front_strip(-b.W / 2, b.W / 2, b.H - strip, b.H)
    b.shelf(rng.uniform(0.4, 0.55) * b.H)
    b.bottom_door("door", -b.W / 2, b.W / 2, 0.0, b.H - strip, _revolute_limit(rng, 1.35, 1.57))
    return b


def _oven(rng: np.random.Generator, variety: bool) -> _Builder:
    b = _Builder(rng, rng.uniform(0.55, 0.76), rng.uniform(0.55, 0.65), rng.uniform(0.55, 0.9), variety)
    b.hollow_body()
    strip = rng.uniform(0.1, 0.15)
    plinth = rng.uniform(0.05, 0.12) if rng.random() < 0.5 else 0.0
    b.front_strip(-b.W / 2, b.W / 2, b.H - strip, b.H)
    if plinth:
        b.front_strip(-b.W / 2, b.W / 2, 0.0, plinth)
    b.shelf(plinth + 0.45 * (b.H - strip - plinth))
    b.bottom_door("door", -b.W / 2, b.W / 2, plinth, b.H - strip, _revolute_limit(rng, 1.25, 1.57))
    return b


def _microwave(rng: np.random.Generator, variety: bool) -> _Builder:
    b = _Builder(rng, rng.uniform(0.45, 0.65), rng.uniform(0.35, 0.45), rng.uniform(0.3, 0.38), variety)
    b.hollow_body()
    split = b.W / 2 - rng.uniform(0.22, 0.3) * b.W
    b.panel(-b.D / 2 + _PANEL, b.D / 2, split, split + _PANEL, _PANEL, b.H - _PANEL, b.inner)
    b.front_strip(split, b.W / 2, 0.0, b.H)
    b.side_door("door", -b.W / 2, split, 0.0, b.H, "left", _revolute_limit(rng, 1.4, 1.9))
    return b


def _refrigerator(rng: np.random.Generator, variety: bool) -> _Builder:
    b = _Builder(rng, rng.uniform(0.6, 0.9), rng.uniform(0.6, 0.75), rng.uniform(1.4, 1.8), variety)
    b.hollow_body()
    layout = rng.choice(["single", "top_bottom", "french"])
    hinge = str(rng.choice(["left", "right"]))
    W, H = b.W, b.H
    if layout == "single":
        for k in range(int(rng.integers(2, 4))):
            b.shelf(H * (k + 1) / 4)
        b.side_door("door", -W / 2, W / 2, 0.0, H, hinge, _revolute_limit(rng, 1.4, 2.0))
    elif layout == "top_bottom":
        split = H * rng.uniform(0.62, 0.72)
        b.shelf(split)
        b.shelf(split / 2)
        b.side_door("door_bottom", -W / 2, W / 2, 0.0, split, hinge, _revolute_limit(rng, 1.4, 2.0))
        b.side_door("door_top", -W / 2, W / 2, split, H, hinge, _revolute_limit(rng, 1.4, 2.0))
    else:
        b.shelf(H / 3)
        b.shelf(2 * H / 3)
        b.side_door("door_left", -W / 2, 0.0, 0.0, H, "left", _revolute_limit(rng, 1.4, 2.0))
        b.side_door("door_right", 0.0, W / 2, 0.0, H, "right", _revolute_limit(rng, 1.4, 2.0))
    return b


def _storage(rng: np.random.Generator, variety: bool) -> _Builder:
    b = _Builder(rng, rng.uniform(0.4, 1.2), rng.uniform(0.35, 0.6), rng.uniform(0.5, 1.8), variety)
    b.hollow_body()
    W, H = b.W, b.H
    plinth = rng.uniform(0.05, 0.1) if rng.random() < 0.5 else 0.0
    if plinth:
        b.front_strip(-W / 2, W / 2, 0.0, plinth)
    shelves = int(rng.integers(1, 4))
    for k in range(shelves):
        b.shelf(plinth + (H - plinth) * (k + 1) / (shelves + 1))
    if W > 0.6 and rng.random() < 0.7:
        b.side_door("door_left", -W / 2, 0.0, plinth, H, "left", _revolute_limit(rng, 1.4, 2.0))
        b.side_door("door_right", 0.0, W / 2, plinth, H, "right", _revolute_limit(rng, 1.4, 2.0))
    else:
        b.side_door("door", -W / 2, W / 2, plinth, H, str(rng.choice(["left", "right"])),
                    _revolute_limit(rng, 1.4, 2.0))
    return b


def _drawer_unit(rng: np.random.Generator, variety: bool) -> _Builder:
    b = _Builder(rng, rng.uniform(0.4, 1.0), rng.uniform(0.4, 0.6), rng.uniform(0.3, 1.2), variety)
    b.hollow_body()
    W, H = b.W, b.H
    plinth = rng.uniform(0.04, 0.1) if rng.random() < 0.5 else 0.0
    if plinth:
        b.front_strip(-W / 2, W / 2, 0.0, plinth)
    n = int(rng.integers(1, 4)) if H >= 0.45 else int(rng.integers(1, 3))
    edges = plinth + (H - plinth) * np.arange(n + 1) / n
    for k in range(n):
        if k > 0:
            b.shelf(edges[k])
        b.drawer(f"drawer_{k}", -W / 2, W / 2, edges[k], edges[k + 1])
    return b


def _cabinet(rng: np.random.Generator, variety: bool) -> _Builder:
    b = _Builder(rng, rng.uniform(0.4, 0.9), rng.uniform(0.4, 0.6), rng.uniform(0.7, 1.2), variety)
    b.hollow_body()
    W, H = b.W, b.H
    if variety and rng.random() < 0.5:          # a door beside a column of stacked drawers
        split = -W / 2 + rng.uniform(0.45, 0.6) * W
        b.panel(-b.D / 2 + _PANEL, b.D / 2, split - _PANEL / 2, split + _PANEL / 2, _PANEL,
                H - _PANEL, b.inner)
        b.side_door("door", -W / 2, split, 0.0, H, "left", _revolute_limit(rng, 1.4, 2.0))
        n = int(rng.integers(2, 4))
        for k in range(n):
            if k > 0:
                b.shelf(H * k / n, split + _PANEL / 2, W / 2 - _PANEL)
            b.drawer(f"drawer_{k}", split, W / 2, H * k / n, H * (k + 1) / n)
        return b
    split = H - rng.uniform(0.15, 0.25)
    b.shelf(split)
    b.shelf(split / 2)
    b.side_door("door", -W / 2, W / 2, 0.0, split, str(rng.choice(["left", "right"])),
                _revolute_limit(rng, 1.4, 2.0))
    b.drawer("drawer", -W / 2, W / 2, split, H)
    return b


def _room_door(rng: np.random.Generator, variety: bool) -> _Builder:
    """A room door in its frame (posts, lintel, threshold); opens towards the viewer."""
    b = _Builder(rng, rng.uniform(0.85, 1.1), rng.uniform(0.1, 0.15), rng.uniform(2.0, 2.2), variety)
    W, D, H = b.W, b.D, b.H
    post = rng.uniform(0.05, 0.08)
    b.panel(-D / 2, D / 2, -W / 2, -W / 2 + post, 0, H)
    b.panel(-D / 2, D / 2, W / 2 - post, W / 2, 0, H)
    b.panel(-D / 2, D / 2, -W / 2 + post, W / 2 - post, H - post, H)
    b.panel(-D / 2, D / 2, -W / 2 + post, W / 2 - post, 0, 0.01)
    b.side_door("door", -W / 2 + post, W / 2 - post, 0.01, H - post,
                str(rng.choice(["left", "right"])), _revolute_limit(rng, 1.3, 1.8), face=D / 2,
                thickness=0.04, handle_z=1.0 - (H - post) / 2)
    return b


def _washing_machine(rng: np.random.Generator, variety: bool) -> _Builder:
    """A front loader: closed body with a control strip and a round door over a square hole."""
    b = _Builder(rng, rng.uniform(0.58, 0.62), rng.uniform(0.5, 0.62), rng.uniform(0.82, 0.88),
                 variety)
    b.hollow_body()
    W, H = b.W, b.H
    strip = rng.uniform(0.12, 0.16)
    b.front_strip(-W / 2, W / 2, H - strip, H)
    r = rng.uniform(0.16, 0.21)
    zc = (H - strip) * rng.uniform(0.5, 0.58)
    a = 0.75 * r
    b.front_strip(-W / 2, W / 2, 0.0, zc - a)
    b.front_strip(-W / 2, W / 2, zc + a, H - strip)
    b.front_strip(-W / 2, -a, zc - a, zc + a)
    b.front_strip(a, W / 2, zc - a, zc + a)
    b.round_door("door", 0.0, zc, r, _revolute_limit(rng, 1.4, 1.9))
    return b


def _chest(rng: np.random.Generator, variety: bool) -> _Builder:
    """A box or chest with a lid hinged at the top of its back."""
    b = _Builder(rng, rng.uniform(0.4, 1.0), rng.uniform(0.3, 0.6), rng.uniform(0.3, 0.6), variety)
    b.hollow_body(top=False, front=True)
    W, D, H, t = b.W, b.D, b.H, _PANEL
    origin = np.array([-D / 2, 0.0, H])
    boxes = [_box(0, D, -W / 2, W / 2, 0, t, b.front)]
    grip, point = b._grip(D, 0.0, -0.01, "y", min(0.3 * W, 0.2), depth=0.025)
    b.parts.append(Part("lid", "revolute", origin, np.array([0.0, -1.0, 0.0]),
                        _revolute_limit(rng, 1.2, 1.9), boxes + grip, point))
    return b


_LAYOUTS = {"dishwasher": _dishwasher, "refrigerator": _refrigerator, "oven": _oven,
            "microwave": _microwave, "storage": _storage, "drawer": _drawer_unit,
            "cabinet": _cabinet, "door": _room_door, "washing_machine": _washing_machine,
            "chest": _chest}

#: Everything the generator makes: the seven categories, then kinds drawn only with variety.
KINDS = CATEGORIES + EXTRA_KINDS


# --------------------------------------------------------------------------- helpers

def _box(x0: float, x1: float, y0: float, y1: float, z0: float, z1: float, rgba: Rgba) -> Box:
    lo, hi = np.minimum([x0, y0, z0], [x1, y1, z1]), np.maximum([x0, y0, z0], [x1, y1, z1])
    return Box(tuple(float(v) for v in (lo + hi) / 2), tuple(float(v) for v in (hi - lo) / 2), rgba)


def _colour(rng: np.random.Generator, metal: bool = False) -> Rgba:
    if metal:
        g = rng.uniform(0.15, 0.8)
        return (g, g, min(1.0, g * 1.05), 1.0)
    hue, sat, val = rng.uniform(0, 1), rng.uniform(0.0, 0.6), rng.uniform(0.35, 0.95)
    rgb = _hsv(hue, sat, val)
    return (rgb[0], rgb[1], rgb[2], 1.0)


def _shade(rgba: Rgba, factor: float, rng: np.random.Generator) -> Rgba:
    """``rgba`` scaled by ``factor`` with a small per-panel variation."""
    f = factor * rng.uniform(0.92, 1.08, size=3)
    c = np.clip(np.array(rgba[:3]) * f, 0.02, 1.0)
    return (float(c[0]), float(c[1]), float(c[2]), 1.0)


def _hsv(h: float, s: float, v: float) -> tuple[float, float, float]:
    i = int(h * 6) % 6
    f = h * 6 - math.floor(h * 6)
    p_, q, t = v * (1 - s), v * (1 - f * s), v * (1 - (1 - f) * s)
    return [(v, t, p_), (q, v, p_), (p_, v, t), (p_, q, v), (t, p_, v), (v, p_, q)][i]


def _link(name: str, boxes: list[Box]) -> urdf.Link:
    """A link whose boxes are both visual and collision shapes (unit mass, nominal inertia)."""
    shapes = [(urdf.Box(tuple(2 * h for h in b.half)), urdf.translation(b.center), b.rgba)
              for b in boxes]
    return urdf.Link(name, [urdf.Geometry(s, T, rgba) for s, T, rgba in shapes],
                     [urdf.Geometry(s, T) for s, T, _ in shapes], urdf.Inertial(1.0))
