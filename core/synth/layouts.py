"""Random objects per category: each category's layout drawn with a seeded generator."""

from __future__ import annotations

import math

import numpy as np

from ..model.categories import CATEGORIES, KINDS
from .builder import PANEL, Builder, box_between
from .objects import ObjectSpec, Part

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


def _dishwasher(rng: np.random.Generator, variety: bool) -> Builder:
    b = Builder(rng, rng.uniform(0.55, 0.65), rng.uniform(0.55, 0.65), rng.uniform(0.8, 0.9), variety)
    b.hollow_body()
    strip = rng.uniform(0.08, 0.12)
    b.front_strip(-b.W / 2, b.W / 2, b.H - strip, b.H)
    b.shelf(rng.uniform(0.4, 0.55) * b.H)
    b.bottom_door("door", -b.W / 2, b.W / 2, 0.0, b.H - strip, _revolute_limit(rng, 1.35, 1.57))
    return b


def _oven(rng: np.random.Generator, variety: bool) -> Builder:
    b = Builder(rng, rng.uniform(0.55, 0.76), rng.uniform(0.55, 0.65), rng.uniform(0.55, 0.9), variety)
    b.hollow_body()
    strip = rng.uniform(0.1, 0.15)
    plinth = rng.uniform(0.05, 0.12) if rng.random() < 0.5 else 0.0
    b.front_strip(-b.W / 2, b.W / 2, b.H - strip, b.H)
    if plinth:
        b.front_strip(-b.W / 2, b.W / 2, 0.0, plinth)
    b.shelf(plinth + 0.45 * (b.H - strip - plinth))
    b.bottom_door("door", -b.W / 2, b.W / 2, plinth, b.H - strip, _revolute_limit(rng, 1.25, 1.57))
    return b


def _microwave(rng: np.random.Generator, variety: bool) -> Builder:
    b = Builder(rng, rng.uniform(0.45, 0.65), rng.uniform(0.35, 0.45), rng.uniform(0.3, 0.38), variety)
    b.hollow_body()
    split = b.W / 2 - rng.uniform(0.22, 0.3) * b.W
    b.panel(-b.D / 2 + PANEL, b.D / 2, split, split + PANEL, PANEL, b.H - PANEL, b.inner)
    b.front_strip(split, b.W / 2, 0.0, b.H)
    b.side_door("door", -b.W / 2, split, 0.0, b.H, "left", _revolute_limit(rng, 1.4, 1.9))
    return b


def _refrigerator(rng: np.random.Generator, variety: bool) -> Builder:
    b = Builder(rng, rng.uniform(0.6, 0.9), rng.uniform(0.6, 0.75), rng.uniform(1.4, 1.8), variety)
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


def _storage(rng: np.random.Generator, variety: bool) -> Builder:
    b = Builder(rng, rng.uniform(0.4, 1.2), rng.uniform(0.35, 0.6), rng.uniform(0.5, 1.8), variety)
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


def _drawer_unit(rng: np.random.Generator, variety: bool) -> Builder:
    b = Builder(rng, rng.uniform(0.4, 1.0), rng.uniform(0.4, 0.6), rng.uniform(0.3, 1.2), variety)
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


def _cabinet(rng: np.random.Generator, variety: bool) -> Builder:
    b = Builder(rng, rng.uniform(0.4, 0.9), rng.uniform(0.4, 0.6), rng.uniform(0.7, 1.2), variety)
    b.hollow_body()
    W, H = b.W, b.H
    if variety and rng.random() < 0.5:          # a door beside a column of stacked drawers
        split = -W / 2 + rng.uniform(0.45, 0.6) * W
        b.panel(-b.D / 2 + PANEL, b.D / 2, split - PANEL / 2, split + PANEL / 2, PANEL,
                H - PANEL, b.inner)
        b.side_door("door", -W / 2, split, 0.0, H, "left", _revolute_limit(rng, 1.4, 2.0))
        n = int(rng.integers(2, 4))
        for k in range(n):
            if k > 0:
                b.shelf(H * k / n, split + PANEL / 2, W / 2 - PANEL)
            b.drawer(f"drawer_{k}", split, W / 2, H * k / n, H * (k + 1) / n)
        return b
    split = H - rng.uniform(0.15, 0.25)
    b.shelf(split)
    b.shelf(split / 2)
    b.side_door("door", -W / 2, W / 2, 0.0, split, str(rng.choice(["left", "right"])),
                _revolute_limit(rng, 1.4, 2.0))
    b.drawer("drawer", -W / 2, W / 2, split, H)
    return b


def _room_door(rng: np.random.Generator, variety: bool) -> Builder:
    """A room door in its frame (posts, lintel, threshold); opens towards the viewer."""
    b = Builder(rng, rng.uniform(0.85, 1.1), rng.uniform(0.1, 0.15), rng.uniform(2.0, 2.2), variety)
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


def _washing_machine(rng: np.random.Generator, variety: bool) -> Builder:
    """A front loader: closed body with a control strip and a round door over a square hole."""
    b = Builder(rng, rng.uniform(0.58, 0.62), rng.uniform(0.5, 0.62), rng.uniform(0.82, 0.88),
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


def _chest(rng: np.random.Generator, variety: bool) -> Builder:
    """A box or chest with a lid hinged at the top of its back."""
    b = Builder(rng, rng.uniform(0.4, 1.0), rng.uniform(0.3, 0.6), rng.uniform(0.3, 0.6), variety)
    b.hollow_body(top=False, front=True)
    W, D, H, t = b.W, b.D, b.H, PANEL
    origin = np.array([-D / 2, 0.0, H])
    boxes = [box_between(0, D, -W / 2, W / 2, 0, t, b.front)]
    grip, point = b._grip(D, 0.0, -0.01, "y", min(0.3 * W, 0.2), depth=0.025)
    b.parts.append(Part("lid", "revolute", origin, np.array([0.0, -1.0, 0.0]),
                        _revolute_limit(rng, 1.2, 1.9), boxes + grip, point))
    return b


_LAYOUTS = {"dishwasher": _dishwasher, "refrigerator": _refrigerator, "oven": _oven,
            "microwave": _microwave, "storage": _storage, "drawer": _drawer_unit,
            "cabinet": _cabinet, "door": _room_door, "washing_machine": _washing_machine,
            "chest": _chest}
