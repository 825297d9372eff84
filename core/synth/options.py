"""Options of ``artgs synth`` (a plain dataclass: the CLI derives its flags from it)."""

from __future__ import annotations

from dataclasses import dataclass

from ..model.categories import CATEGORIES, EXTRA_KINDS, KINDS
from ..model.regime import PRESETS
from ..model.registry import option
from ..model.robots import ROBOTS


@dataclass
class SynthOptions:
    """Synthetic articulated objects with ground truth, one capture folder per object."""

    out: str = option(None, "folder to write; one capture folder per object", positional=True)
    category: list[str] | None = option(None, "categories to generate (default all seven, plus "
                                        f"{', '.join(EXTRA_KINDS)} in regimes with variety)",
                                        choices=KINDS)
    per_category: int = option(1, "objects per category")
    seed: int = option(0, "seed of the set")
    width: int = option(160, "image width")
    height: int = option(120, "image height")
    static_views: int = option(24, "static views per object")
    steps: int = option(6, "interaction steps per joint")
    depth_noise: float = option(0.0, "depth noise std-dev, metres")
    simultaneous: bool = option(False, "also move two joints at once in the interaction sequence")
    regime: str = option("tight", "capture regime preset (realistic: the benchmarks' default; "
                         "each of its settings has its own flag below)", choices=tuple(PRESETS))
    urdf: list[str] | None = option(None, "render these articulated URDFs (e.g. PartNet-Mobility "
                                    "<kind>/<id>/mobility.urdf) instead of procedural objects")
    kind: str | None = option(None, "--urdf: the object's kind, for its real size (default: the "
                              "asset folder's parent folder name)")
    joints: list[str] | None = option(None, "--urdf: the joints that open parts (default: the rule "
                                      "in core/synth/asset.py)")
    size: float | None = option(None, "--urdf: largest dimension in metres (default: drawn for "
                                "the kind)")
    robot: str | None = option(None, "robot arm that opens the parts in the interaction frames "
                               "(in RGB and depth, not in the masks)", choices=tuple(ROBOTS))
