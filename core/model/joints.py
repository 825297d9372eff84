"""Joints and the ``articulation.json`` / ``proposals.json`` schema (shared/spec/outputs.md).

Numpy only: the Blender process reads and writes these files too.

Per joint, beyond the spec's ``name type axis origin limit parent child states``, proposals carry:
``source`` (``vlm``, ``motion``, ``user``, or ``optimise`` for a part only the optimisation found), ``confidence`` (0..1), ``bbox`` ([x1, y1, x2, y2] pixels
in the view named by the file's ``view``), ``handle`` ({"point": xyz, "approach": unit xyz}) and
``extent`` (the moving part's oriented box in the closed state: {"center": xyz, "axes": 3 unit row
vectors, "half_size": xyz}). Unknown keys are kept on read and written back unchanged.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from . import atomic
from .errors import InputError
from .jsonio import read_json_object

JOINT_TYPES = ("revolute", "prismatic")
SOURCES = ("vlm", "motion", "user", "optimise")   # optimise: a part the optimisation found
_SPEC_KEYS = {"name", "type", "axis", "origin", "limit", "parent", "child", "states"}
_PROPOSAL_KEYS = {"source", "confidence", "bbox", "handle", "extent"}


@dataclass
class Joint:
    """One joint in the world frame: unit ``axis``, a point ``origin`` on it, ``limit`` (lo, hi)."""

    name: str
    type: str
    axis: np.ndarray
    origin: np.ndarray
    limit: tuple[float, float] = (0.0, 0.0)
    parent: str = "base"
    child: str = ""
    states: dict[int, float] | None = None
    source: str | None = None
    confidence: float | None = None
    bbox: list[float] | None = None
    handle: dict[str, list[float]] | None = None
    extent: dict[str, Any] | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.axis = np.asarray(self.axis, float).reshape(3)
        n = np.linalg.norm(self.axis)
        if n > 0:
            self.axis = self.axis / n
        self.origin = np.asarray(self.origin, float).reshape(3)
        self.limit = (float(self.limit[0]), float(self.limit[1]))
        if not self.child:
            self.child = f"{self.name}_link"

    def transform(self, value: float) -> np.ndarray:
        """4x4 world-frame rigid motion of the child part at joint value ``value``."""
        return joint_transform(self.type, self.axis, self.origin, value)

    def to_dict(self) -> dict[str, Any]:
        """The JSON object of this joint (spec keys first, optional keys only when set)."""
        d: dict[str, Any] = {
            "name": self.name, "type": self.type,
            "axis": [float(v) for v in self.axis], "origin": [float(v) for v in self.origin],
            "limit": [self.limit[0], self.limit[1]], "parent": self.parent, "child": self.child,
        }
        if self.states is not None:
            d["states"] = {str(k): float(v) for k, v in sorted(self.states.items())}
        for key in ("source", "confidence", "bbox", "handle", "extent"):
            value = getattr(self, key)
            if value is not None:
                d[key] = value
        d.update(self.extra)
        return d

    @classmethod
    def from_dict(cls, d: Any, file: str | Path = "<joints>", index: int = 0) -> "Joint":
        """Parse and validate one joint object; errors name the file, joint and field."""
        where = f"joint {index}" + (f" ('{d.get('name')}')" if isinstance(d, dict) and d.get("name") else "")
        if not isinstance(d, dict):
            raise InputError(file, "a joint must be a JSON object", frame=where)

        def bad(fld: str, msg: str) -> InputError:
            return InputError(file, msg, frame=where, field=fld)

        for key in ("name", "type", "axis", "origin"):
            if key not in d:
                raise bad(key, "missing")
        if not isinstance(d["name"], str) or not d["name"]:
            raise bad("name", "must be a non-empty string")
        if d["type"] not in JOINT_TYPES:
            raise bad("type", f"must be one of {JOINT_TYPES}, not {d['type']!r}")
        axis = _vec3(d["axis"], bad, "axis")
        if np.linalg.norm(axis) < 1e-9:
            raise bad("axis", "must be a non-zero vector")
        origin = _vec3(d["origin"], bad, "origin")
        limit = d.get("limit", [0.0, 0.0])
        if (not isinstance(limit, (list, tuple)) or len(limit) != 2
                or not all(_finite(v) for v in limit)):
            raise bad("limit", "must be two numbers [lower, upper]")
        if limit[0] > limit[1]:
            raise bad("limit", f"lower {limit[0]} is above upper {limit[1]}")
        states = d.get("states")
        if states is not None:
            if not isinstance(states, dict) or not all(_finite(v) for v in states.values()):
                raise bad("states", "must map interaction time to a number")
            try:
                states = {int(k): float(v) for k, v in states.items()}
            except ValueError as exc:
                raise bad("states", "keys must be integer times") from exc
        source = d.get("source")
        if source is not None and source not in SOURCES:
            raise bad("source", f"must be one of {SOURCES}, not {source!r}")
        extra = {k: v for k, v in d.items() if k not in _SPEC_KEYS | _PROPOSAL_KEYS}
        return cls(name=d["name"], type=d["type"], axis=axis, origin=origin,
                   limit=(float(limit[0]), float(limit[1])), parent=str(d.get("parent", "base")),
                   child=str(d.get("child") or f"{d['name']}_link"), states=states, source=source,
                   confidence=d.get("confidence"), bbox=d.get("bbox"), handle=d.get("handle"),
                   extent=d.get("extent"), extra=extra)


@dataclass
class Articulation:
    """The contents of an articulation or proposals file."""

    joints: list[Joint]
    meta: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {"frame": "world", **self.meta, "joints": [j.to_dict() for j in self.joints]}


def read_articulation(path: str | Path) -> Articulation:
    """Read and validate ``articulation.json`` or ``proposals.json``."""
    path = Path(path)
    data = read_json_object(path)
    if data.get("frame", "world") != "world":
        raise InputError(path, f"only the 'world' frame is supported, not {data['frame']!r}",
                         field="frame")
    joints = data.get("joints")
    if not isinstance(joints, list):
        raise InputError(path, "must be a list of joints", field="joints")
    parsed = [Joint.from_dict(j, path, i) for i, j in enumerate(joints)]
    names = [j.name for j in parsed]
    dup = {n for n in names if names.count(n) > 1}
    if dup:
        raise InputError(path, f"joint names must be unique; repeated: {sorted(dup)}", field="joints")
    meta = {k: v for k, v in data.items() if k not in ("frame", "joints")}
    return Articulation(parsed, meta)


def write_articulation(path: str | Path, articulation: Articulation) -> None:
    """Write an articulation or proposals file atomically."""
    atomic.write_json(path, articulation.to_dict())


def rotation_about_axis(axis: np.ndarray, angle: float) -> np.ndarray:
    """3x3 rotation by ``angle`` radians about the unit ``axis`` (Rodrigues)."""
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    Kx = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + math.sin(angle) * Kx + (1 - math.cos(angle)) * (Kx @ Kx)


def joint_transform(kind: str, axis: np.ndarray, origin: np.ndarray, value: float) -> np.ndarray:
    """4x4 rigid motion of a revolute (angle about the axis line) or prismatic (slide) joint."""
    T = np.eye(4)
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    if kind == "revolute":
        R = rotation_about_axis(axis, value)
        T[:3, :3] = R
        T[:3, 3] = np.asarray(origin, float) - R @ np.asarray(origin, float)
    elif kind == "prismatic":
        T[:3, 3] = axis * value
    else:
        raise ValueError(f"unknown joint type {kind!r}")
    return T


def motion_direction(kind: str, axis: np.ndarray, origin: np.ndarray, point: np.ndarray
                     ) -> np.ndarray | None:
    """Unit direction in which ``point`` on a joint's part starts to move as the joint's value
    grows from 0: a hinge's axis x lever, a slide's axis; None for a point on a hinge's axis."""
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    line = np.cross(axis, np.asarray(point, float) - np.asarray(origin, float)) \
        if kind == "revolute" else axis
    norm = float(np.linalg.norm(line))
    return line / norm if norm > 1e-6 else None


def opening_approach(kind: str, axis: np.ndarray, origin: np.ndarray, point: np.ndarray,
                     opening: float) -> np.ndarray | None:
    """A handle's approach: against the motion that opens the part (``opening``, the joint's
    value when open; its sign says which way the part opens) at ``point``
    (:func:`motion_direction`). None for a point on a hinge's axis or no opening."""
    pull = motion_direction(kind, axis, origin, point)
    if pull is None or not opening:
        return None
    return -math.copysign(1.0, opening) * pull


def _finite(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _vec3(v: Any, bad, name: str) -> np.ndarray:
    if not isinstance(v, (list, tuple)) or len(v) != 3 or not all(_finite(x) for x in v):
        raise bad(name, "must be three finite numbers")
    return np.asarray(v, float)
