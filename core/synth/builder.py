"""Laying out one procedural object: the body's panels, doors, drawers, handles and colours."""

from __future__ import annotations

import math

import numpy as np

from .objects import Box, Part, Rgba

#: Handle kinds of objects drawn with variety.
HANDLES = ("bar", "long", "knob", "horizontal", "none")


#: Panel thickness of bodies, doors and drawer fronts (metres).
PANEL = 0.018
GAP = 0.004


class Builder:
    """Collects the boxes of one object while a category generator lays it out."""

    def __init__(self, rng: np.random.Generator, width: float, depth: float, height: float,
                 variety: bool = False) -> None:
        self.rng = rng
        self.W, self.D, self.H = width, depth, height
        self.body: list[Box] = []
        self.parts: list[Part] = []
        self.outer = colour(rng)
        self.inner = shade(self.outer, rng.uniform(0.75, 1.2), rng)
        self.front = shade(self.outer, rng.uniform(0.85, 1.15), rng) if rng.random() < 0.5 \
            else colour(rng)
        self.handle = colour(rng, metal=True)
        self.handle_kind, self.framed = "bar", False
        if variety:                  # drawn after the plain draws: plain objects stay unchanged
            if rng.random() < 0.35:
                self.front = self.outer          # parts in the body's colour (and texture)
            self.handle_kind = str(rng.choice(HANDLES))
            self.framed = bool(rng.random() < 0.4)

    def panel(self, x0: float, x1: float, y0: float, y1: float, z0: float, z1: float,
              rgba: Rgba | None = None) -> None:
        """A fixed box of the body from its bounds in the object frame."""
        self.body.append(box_between(x0, x1, y0, y1, z0, z1, shade(rgba or self.outer, 1.0, self.rng)))

    def hollow_body(self, top: bool = True, front: bool = False) -> None:
        """Back, sides, bottom and (``top``) top panels; open at the front unless ``front``."""
        W, D, H, t = self.W, self.D, self.H, PANEL
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
        W, D, t = self.W, self.D, PANEL
        y0 = -W / 2 + t if y0 is None else y0
        y1 = W / 2 - t if y1 is None else y1
        self.panel(-D / 2 + t, D / 2 - 0.01, y0, y1, z - t / 2, z + t / 2, self.inner)

    def front_strip(self, y0: float, y1: float, z0: float, z1: float) -> None:
        """A fixed front panel (control strip, plinth) flush with the door faces."""
        self.panel(self.D / 2, self.D / 2 + PANEL, y0 + GAP / 2, y1 - GAP / 2,
                   z0 + GAP / 2, z1 - GAP / 2, self.front)

    def _frame(self, y0: float, y1: float, z0: float, z1: float, x: float) -> list[Box]:
        """A raised frame (four strips) on a door face spanning [y0,y1]x[z0,z1] at depth ``x``."""
        if not self.framed:
            return []
        b = min(0.06, 0.12 * min(y1 - y0, z1 - z0))
        c = shade(self.front, 0.9, self.rng)
        return [box_between(x, x + 0.012, y0, y1, z0, z0 + b, c), box_between(x, x + 0.012, y0, y1, z1 - b, z1, c),
                box_between(x, x + 0.012, y0, y0 + b, z0 + b, z1 - b, c),
                box_between(x, x + 0.012, y1 - b, y1, z0 + b, z1 - b, c)]

    def _grip(self, x: float, y: float, z: float, along: str, length: float, depth: float = 0.03
              ) -> tuple[list[Box], np.ndarray]:
        """Handle boxes at the point (x on the face, y, z) of a part frame and its grasp point.

        ``along`` = y or z: the bar's direction for the kind ``bar``; ``long`` bars are 2.5 x as
        long, ``knob`` is a small cube, ``none`` is a grip recess (no box)."""
        kind = self.handle_kind
        if kind == "none":
            return [], np.array([x, y, z])
        if kind == "knob":
            return [box_between(x, x + 0.035, y - 0.017, y + 0.017, z - 0.017, z + 0.017, self.handle)], \
                np.array([x + 0.02, y, z])
        if kind == "long":
            length *= 2.5
        if kind == "horizontal":
            along = "y" if along == "z" else "z"
        hy = length / 2 if along == "y" else 0.011
        hz = length / 2 if along == "z" else 0.011
        box = box_between(x, x + depth, y - hy, y + hy, z - hz, z + hz, self.handle)
        return [box], np.array(box.center)

    def side_door(self, name: str, y0: float, y1: float, z0: float, z1: float, hinge: str,
                  limit: tuple[float, float], face: float | None = None,
                  thickness: float = PANEL, handle_z: float = 0.0) -> None:
        """A door covering the front cell [y0,y1]x[z0,z1], hinged on its ``hinge`` (left/right).

        Its outer face is at x = ``face`` (default: a panel in front of the body)."""
        y0, y1, z0, z1 = y0 + GAP / 2, y1 - GAP / 2, z0 + GAP / 2, z1 - GAP / 2
        t, w, h = thickness, y1 - y0, z1 - z0
        face = self.D / 2 + PANEL if face is None else face
        left = hinge == "left"
        origin = np.array([face, y0 if left else y1, (z0 + z1) / 2])
        s = 1.0 if left else -1.0              # direction from the hinge to the free edge, along y
        axis = np.array([0.0, 0.0, -s])
        boxes = [box_between(-t, 0, 0, s * w, -h / 2, h / 2, self.front)]
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
        y0, y1, z0, z1 = y0 + GAP / 2, y1 - GAP / 2, z0 + GAP / 2, z1 - GAP / 2
        t, w, h = PANEL, y1 - y0, z1 - z0
        origin = np.array([self.D / 2 + t, (y0 + y1) / 2, z0])
        boxes = [box_between(-t, 0, -w / 2, w / 2, 0, h, self.front)]
        boxes += self._frame(-w / 2, w / 2, 0, h, 0.0)
        hz = h - min(0.05, 0.15 * h)
        grip, point = self._grip(0.0, 0.0, hz, "y", 0.6 * w if self.handle_kind != "long" else 0.36 * w)
        self.parts.append(Part(name, "revolute", origin, np.array([0.0, 1.0, 0.0]), limit,
                               boxes + grip, point))

    def round_door(self, name: str, yc: float, zc: float, r: float, limit: tuple[float, float]
                   ) -> None:
        """A round door (a disc of slabs) hinged at its left edge, over a square hole."""
        t = 0.03
        origin = np.array([self.D / 2 + PANEL + t, yc - r, zc])
        boxes = []
        n = 9
        for k in range(n):
            za, zb = -r + 2 * r * k / n, -r + 2 * r * (k + 1) / n
            half = math.sqrt(max(r * r - max(za * za, zb * zb), 0.0)) if k not in (n // 2,) else r
            half = max(half, 0.2 * r)
            boxes.append(box_between(-t, 0, r - half, r + half, za, zb, self.front))
        boxes.append(box_between(-t + 0.002, 0.004, 0.35 * r, 1.65 * r, -0.65 * r, 0.65 * r,
                          shade(self.inner, 0.6, self.rng)))                # glass
        grip, point = self._grip(0.0, 2 * r - 0.04, 0.0, "z", 0.3 * r)
        self.parts.append(Part(name, "revolute", origin, np.array([0.0, 0.0, -1.0]), limit,
                               boxes + grip, point))

    def drawer(self, name: str, y0: float, y1: float, z0: float, z1: float) -> None:
        """A drawer: front panel over the cell plus a tray (bottom, sides, back) inside the body."""
        y0, y1, z0, z1 = y0 + GAP / 2, y1 - GAP / 2, z0 + GAP / 2, z1 - GAP / 2
        t, w, h = PANEL, y1 - y0, z1 - z0
        origin = np.array([self.D / 2 + t / 2, (y0 + y1) / 2, (z0 + z1) / 2])
        tray_depth = self.D - 2.5 * t
        tw, th = w / 2 - 0.02, 0.7 * h
        x0 = -t / 2 - tray_depth
        bottom = -h / 2 + 0.015
        boxes = [box_between(-t / 2, t / 2, -w / 2, w / 2, -h / 2, h / 2, self.front),
                 box_between(x0, -t / 2, -tw, tw, bottom, bottom + 0.012, self.inner),
                 box_between(x0, -t / 2, -tw, -tw + 0.012, bottom, bottom + th, self.inner),
                 box_between(x0, -t / 2, tw - 0.012, tw, bottom, bottom + th, self.inner),
                 box_between(x0, x0 + 0.012, -tw + 0.012, tw - 0.012, bottom, bottom + th, self.inner)]
        boxes += self._frame(-w / 2, w / 2, -h / 2, h / 2, t / 2)
        length = min(0.5 * w, 0.3) if self.handle_kind != "long" else 0.35 * w
        grip, point = self._grip(t / 2, 0.0, 0.0, "y", length, depth=0.025)
        limit = (0.0, float(self.rng.uniform(0.6, 0.85) * tray_depth))
        self.parts.append(Part(name, "prismatic", origin, np.array([1.0, 0.0, 0.0]), limit,
                               boxes + grip, point))



def box_between(x0: float, x1: float, y0: float, y1: float, z0: float, z1: float, rgba: Rgba) -> Box:
    lo, hi = np.minimum([x0, y0, z0], [x1, y1, z1]), np.maximum([x0, y0, z0], [x1, y1, z1])
    return Box(tuple(float(v) for v in (lo + hi) / 2), tuple(float(v) for v in (hi - lo) / 2), rgba)


def colour(rng: np.random.Generator, metal: bool = False) -> Rgba:
    if metal:
        g = rng.uniform(0.15, 0.8)
        return (g, g, min(1.0, g * 1.05), 1.0)
    hue, sat, val = rng.uniform(0, 1), rng.uniform(0.0, 0.6), rng.uniform(0.35, 0.95)
    rgb = _hsv(hue, sat, val)
    return (rgb[0], rgb[1], rgb[2], 1.0)


def shade(rgba: Rgba, factor: float, rng: np.random.Generator) -> Rgba:
    """``rgba`` scaled by ``factor`` with a small per-panel variation."""
    f = factor * rng.uniform(0.92, 1.08, size=3)
    c = np.clip(np.array(rgba[:3]) * f, 0.02, 1.0)
    return (float(c[0]), float(c[1]), float(c[2]), 1.0)


def _hsv(h: float, s: float, v: float) -> tuple[float, float, float]:
    i = int(h * 6) % 6
    f = h * 6 - math.floor(h * 6)
    p_, q, t = v * (1 - s), v * (1 - f * s), v * (1 - (1 - f) * s)
    return [(v, t, p_), (q, v, p_), (p_, v, t), (p_, q, v), (t, p_, v), (v, p_, q)][i]
