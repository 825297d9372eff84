"""The room around an object: a textured floor, a wall behind it, sometimes a wall at one side,
and one or two pieces of furniture beside it, as a URDF of boxes (one link per element, so each can
carry its own texture).

Placed in the object's frame (x = front, y = right, z = up, from its yaw and footprint): walls stay
behind and beside the object and never reach in front of it, so cameras in the front half see the
object unobstructed except by furniture at grazing azimuths, as in a real room.
"""

from __future__ import annotations

import math

import numpy as np

from ..sim import urdf
from .texture import make_texture


def room_urdf(base_pose: np.ndarray, half_size: np.ndarray, floor_z: float,
              rng: np.random.Generator, eyes: np.ndarray, target: np.ndarray
              ) -> tuple[str, dict[str, np.ndarray | None]]:
    """URDF text of the room around an object and a texture (or None) per link name.

    ``base_pose``: the object's frame (only its yaw and position are used); ``half_size``: the
    object's half extents along its own x (depth), y (width), z (height) from its frame origin;
    ``floor_z``: world height of the floor. A side wall or piece of furniture that would stand
    between any camera centre in ``eyes`` (N,3) and the object's centre ``target`` (or around a
    camera) is left out: people do not film through walls.
    """
    yaw = math.atan2(base_pose[1, 0], base_pose[0, 0])
    frame = np.eye(4)
    frame[:3, :3] = urdf.rpy_to_matrix((0.0, 0.0, yaw))
    frame[:3, 3] = [base_pose[0, 3], base_pose[1, 3], floor_z]
    d, w, h = (float(v) for v in half_size)
    wall_h = max(2.5, 2 * h + 0.3)
    back = -d - rng.uniform(0.03, 0.4)
    elements: list[tuple[str, tuple, tuple, tuple]] = [          # name, size, centre, rgba
        ("floor", (8.0, 8.0, 0.02), (0.0, 0.0, -0.01), _tone(rng, 0.45, 0.8)),
        ("wall_back", (0.05, 6.0, wall_h), (back - 0.025, 0.0, wall_h / 2), _tone(rng, 0.7, 0.95)),
    ]
    sides = [-1.0, 1.0]
    rng.shuffle(sides)
    if rng.random() < 0.5:                                       # a wall at one side (alcove)
        s = sides.pop()
        y = s * (w + rng.uniform(0.05, 0.6))
        x1 = d + rng.uniform(0.0, 0.3)
        elements.append(("wall_side", (x1 - back, 0.05, wall_h), ((x1 + back) / 2, y + s * 0.025,
                                                                  wall_h / 2), _tone(rng, 0.7, 0.95)))
    for k, s in enumerate(sides[: int(rng.integers(1, len(sides) + 1))]):
        fw, fd = rng.uniform(0.3, 0.8), rng.uniform(0.3, max(0.35, 2 * d))
        fh = rng.uniform(0.4, 1.0) * 2 * h
        y = s * (w + rng.uniform(0.03, 0.3) + fw / 2)
        elements.append((f"furniture_{k}", (fd, fw, fh), (back + fd / 2 + 0.01, y, fh / 2),
                         _tone(rng, 0.25, 0.9, colour=True)))
    inv = np.linalg.inv(frame)
    local_eyes = np.asarray(eyes, float) @ inv[:3, :3].T + inv[:3, 3]
    local_target = inv[:3, :3] @ np.asarray(target, float) + inv[:3, 3]
    elements = [e for e in elements if e[0] in ("floor", "wall_back")
                or not any(_blocks(np.array(e[2]), np.array(e[1]) / 2, eye, local_target)
                           for eye in local_eyes)]
    links, joints = [urdf.Link("room_world", inertial=urdf.Inertial(1.0))], []
    textures: dict[str, np.ndarray | None] = {}
    for name, size, centre, rgba in elements:
        geom = urdf.Geometry(urdf.Box(size), np.eye(4), rgba)
        links.append(urdf.Link(name, [geom], [geom], urdf.Inertial(1.0)))
        joints.append(urdf.UrdfJoint(f"{name}_pose", "fixed", "room_world", name,
                                     origin=frame @ urdf.translation(centre)))
        kind = "tiles" if name == "floor" and rng.random() < 0.5 else \
            str(rng.choice(["grain", "speckle"])) if name == "floor" or rng.random() < 0.5 else "plain"
        textures[name] = make_texture(rng, kind=kind)
    return urdf.write_urdf("room", links, joints), textures


def _blocks(centre: np.ndarray, half: np.ndarray, a: np.ndarray, b: np.ndarray) -> bool:
    """Whether the segment a-b passes through the axis-aligned box (slab test, 5 cm margin)."""
    lo, hi = centre - half - 0.05, centre + half + 0.05
    d = b - a
    t0, t1 = 0.0, 1.0
    for k in range(3):
        if abs(d[k]) < 1e-12:
            if a[k] < lo[k] or a[k] > hi[k]:
                return False
            continue
        u, v = (lo[k] - a[k]) / d[k], (hi[k] - a[k]) / d[k]
        t0, t1 = max(t0, min(u, v)), min(t1, max(u, v))
        if t0 > t1:
            return False
    return True


def _tone(rng: np.random.Generator, lo: float, hi: float, colour: bool = False
          ) -> tuple[float, float, float, float]:
    v = rng.uniform(lo, hi)
    tint = rng.uniform(0.75, 1.0, 3) if colour else rng.uniform(0.93, 1.0, 3)
    c = np.clip(v * tint, 0.0, 1.0)
    return (float(c[0]), float(c[1]), float(c[2]), 1.0)
