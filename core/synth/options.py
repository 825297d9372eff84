"""Options of ``artgs synth`` (a plain dataclass: the CLI derives its flags from it)."""

from __future__ import annotations

from dataclasses import dataclass

from ..model.categories import CATEGORIES
from ..model.registry import option
from ..model.robots import ROBOTS


@dataclass
class SynthOptions:
    """Synthetic articulated objects with ground truth, one capture folder per object."""

    out: str = option(None, "folder to write; one capture folder per object", positional=True)
    category: list[str] | None = option(None, "categories to generate (default all seven)",
                                        choices=CATEGORIES)
    per_category: int = option(1, "objects per category")
    seed: int = option(0, "seed of the set")
    width: int = option(160, "image width")
    height: int = option(120, "image height")
    static_views: int = option(24, "static views per object")
    steps: int = option(6, "interaction steps per joint")
    depth_noise: float = option(0.0, "depth noise std-dev, metres")
    simultaneous: bool = option(False, "also move two joints at once in the interaction sequence")
    robot: str | None = option(None, "robot arm that opens the parts in the interaction frames "
                               "(in RGB and depth, not in the masks)", choices=tuple(ROBOTS))
