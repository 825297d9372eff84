"""The crop box: an oriented box around the object, drawn by the user (in Blender, an Empty shown as
a cube), stored as ``OUT/crop.json`` so every stage reads the same box (numpy only).

``crop.json``::

    {"frame": "world", "center": [x, y, z], "axes": [[ax], [ay], [az]], "half_size": [hx, hy, hz],
     "source": "blender"}

``axes`` are the box's unit edge directions in the world frame (rows), ``half_size`` the half
extents along them, metres. A point belongs to the object when it lies inside the box. No file:
no crop. Only this module reads or writes the file.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import atomic
from .errors import InputError
from .layout import CROP


@dataclass(frozen=True)
class CropBox:
    """An oriented box in the world frame (see the module docstring)."""

    center: np.ndarray
    axes: np.ndarray          # 3 x 3, rows = unit edge directions
    half_size: np.ndarray
    source: str = "user"

    def contains(self, points: np.ndarray) -> np.ndarray:
        """Bool per point (N x 3, world): inside the box."""
        local = (np.asarray(points, float) - self.center) @ self.axes.T
        return np.all(np.abs(local) <= self.half_size, axis=1)

    def corners(self) -> np.ndarray:
        """The 8 corners (world)."""
        signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
        return self.center + (signs * self.half_size) @ self.axes

    def to_dict(self) -> dict:
        return {"frame": "world", "center": self.center.tolist(), "axes": self.axes.tolist(),
                "half_size": self.half_size.tolist(), "source": self.source}


def crop_from_matrix(matrix: np.ndarray, source: str = "user") -> CropBox:
    """The box that a unit cube [-1, 1]^3 becomes under ``matrix`` (4 x 4, any rotation, scale;
    shear is dropped): Blender's cube Empty of display size 1 under its world matrix."""
    M = np.asarray(matrix, float)
    scale = np.linalg.norm(M[:3, :3], axis=0)
    if np.any(scale < 1e-9):
        raise InputError(CROP, "the crop box is flat (a zero scale)", field="half_size")
    axes = (M[:3, :3] / scale).T
    u, _, vt = np.linalg.svd(axes)          # nearest rotation (drops shear)
    return CropBox(M[:3, 3].copy(), u @ vt, scale, source)


def read_crop(out: str | Path) -> CropBox | None:
    """OUT's crop box, None when OUT has no crop.json. Bad content is an InputError."""
    path = Path(out) / CROP
    if not path.is_file():
        return None
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise InputError(path, f"not readable JSON ({exc})") from None
    if data.get("frame", "world") != "world":
        raise InputError(path, "only the world frame is supported", field="frame")
    values = {}
    for key, shape in (("center", (3,)), ("axes", (3, 3)), ("half_size", (3,))):
        try:
            value = np.asarray(data[key], float)
        except (KeyError, TypeError, ValueError):
            raise InputError(path, f"missing or not numbers (expected shape {shape})",
                             field=key) from None
        if value.shape != shape or not np.all(np.isfinite(value)):
            raise InputError(path, f"expected {shape} finite numbers, got shape {value.shape}",
                             field=key)
        values[key] = value
    if np.any(values["half_size"] <= 0):
        raise InputError(path, "half sizes must be positive", field="half_size")
    if not np.allclose(values["axes"] @ values["axes"].T, np.eye(3), atol=1e-4):
        raise InputError(path, "the axes must be orthonormal rows", field="axes")
    return CropBox(values["center"], values["axes"], values["half_size"],
                   str(data.get("source", "user")))


def write_crop(out: str | Path, box: CropBox) -> Path:
    """Write ``box`` to OUT/crop.json atomically; returns the path."""
    path = Path(out) / CROP
    atomic.write_json(path, box.to_dict())
    return path
