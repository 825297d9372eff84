"""Capture folders (shared/spec/capture-format.md) read into typed data, validated up front."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .cameras import Camera

PHASES = ("static", "interaction")


@dataclass
class Frame:
    """One RGB-D frame, loaded and validated.

    ``rgb`` (H,W,3) uint8; ``depth`` (H,W) float32 metres, 0 where there is no measurement;
    ``mask`` (H,W) bool or None (None: every pixel is object).
    """

    index: int
    file_path: str
    camera: Camera
    rgb: np.ndarray
    depth: np.ndarray | None
    mask: np.ndarray | None
    phase: str = "static"
    time: int | None = None
    robot_joint_positions: list[float] | None = None


@dataclass
class Capture:
    """A whole capture: frames in file order, plus the optional robot model name."""

    root: Path
    frames: list[Frame]
    robot: str | None = None
    meta: dict = field(default_factory=dict)

    @property
    def static(self) -> list[Frame]:
        return [f for f in self.frames if f.phase == "static"]

    @property
    def interaction(self) -> list[Frame]:
        return [f for f in self.frames if f.phase == "interaction"]

    @property
    def times(self) -> list[int]:
        """Sorted distinct interaction steps."""
        return sorted({f.time for f in self.interaction if f.time is not None})
