"""Options of the benchmark commands (plain dataclasses: the CLI derives its flags from them)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from ..model.categories import CATEGORIES, EXTRA_KINDS
from ..model.registry import DEVICES, option
from ..model.robots import ROBOTS
from ..render.constants import LOW_PASS


#: Help of every benchmark's ``--set`` (core/bench/sets.py defines the sets).
SET_HELP = ("benchmark set: tight | realistic | partnet:DIR (DIR/<kind>/<id>/mobility.urdf) | "
            "data:DIR (default tight); see core/bench/sets.py")


def _in_view_robot() -> Any:
    """The robot opening the parts in view during the capture (issue 16's variants)."""
    return option(None, "generated sets: also the same objects opened by this robot in view, "
                  "scored with its twin and without (ablation)", choices=tuple(ROBOTS))


@dataclass
class BenchRenderOptions:
    """``artgs bench-render``: rasterizer speed."""

    sizes: list[int] = field(default_factory=lambda: [128, 256],
                             metadata={"help": "image sizes (square)"})
    counts: list[int] = field(default_factory=lambda: [20000, 50000],
                              metadata={"help": "Gaussian counts"})
    runs: int = option(15, "timed runs per case")
    no_reference: bool = option(False, "skip the slow pure-torch reference")
    low_pass: float = option(LOW_PASS, f"2D dilation in px^2 (default: the project's {LOW_PASS}; "
                             "0.3 = original 3DGS)")


@dataclass
class BenchReconstructOptions:
    """``artgs bench-reconstruct``: reconstruction quality and speed per category."""

    set: str | None = option(None, SET_HELP)
    data: str | None = option(None, "capture folders already made (= --set data:DIR)")
    per_category: int = option(1, "objects per category (generated sets)")
    seed: int = option(0, "seed of the generated set")
    device: str = option("auto", "where torch work runs", choices=DEVICES)


@dataclass
class SetOptions:
    """What the accuracy benchmarks share: the set, the generated set's shape, the splat."""

    set: str | None = option(None, SET_HELP)
    data: str | None = option(None, "capture folders already made (= --set data:DIR)")
    per_category: int = option(1, "objects per category (generated sets)")
    seed: int = option(0, "seed of the generated set")
    category: list[str] | None = option(None, "generated sets: only these categories",
                                        choices=CATEGORIES + EXTRA_KINDS)
    width: int = option(160, "generated sets: image width")
    height: int = option(120, "generated sets: image height")
    iterations: int | None = option(None, "static splat: reconstruction iteration cap (default: "
                                    "until converged, as artgs run; 0: the depth-initialised "
                                    "splat, faster and less accurate)")
    device: str = option("auto", "where torch work runs", choices=DEVICES)


@dataclass
class BenchProposeOptions(SetOptions):
    """``artgs bench-propose``: proposal accuracy per category (motion route)."""

    per_category: int = option(2, "objects per category (generated sets)")
    depth_noise: float = option(0.0, "generated sets: depth noise std-dev, metres")
    simultaneous: bool = option(False, "generated sets: the first two joints also move together")
    robot: str | None = _in_view_robot()


@dataclass
class BenchOptimiseOptions(SetOptions):
    """``artgs bench-optimise``: joint accuracy without and with the optimisation; basin rate."""

    opt_iterations: int = option(300, "steps of the main articulation fit")
    opt_seed: int = option(0, "random seed of the articulation fit (the frames each step draws): "
                           "runs with other seeds show how much one run tells")
    basin: int = option(0, "perturbed-start runs per capture (10-30 deg, 5-15 cm; every second "
                        "one also of the wrong type, without states) for the basin rate")
    robot: str | None = _in_view_robot()


@dataclass
class BenchBatchOptions:
    """``artgs bench-batch``: captures per hour of ``artgs batch`` per worker count."""

    data: str | None = option(None, "folder of capture folders (default: generate --count)")
    count: int = option(4, "generated sets: captures (the seven categories in turn)")
    seed: int = option(0, "generated sets: seed")
    width: int = option(160, "generated sets: image width")
    height: int = option(120, "generated sets: image height")
    static_views: int = option(24, "generated sets: static views")
    iterations: int | None = option(None, "reconstruction iteration cap (default: until converged)")
    workers: list[int] = field(default_factory=lambda: [1, 2],
                               metadata={"help": "worker counts to time"})
    ray: bool = option(False, "run the batches on a private local Ray instead of the process pool")
    device: str = option("auto", "where torch work runs", choices=DEVICES)


@dataclass
class BenchCheckOptions(SetOptions):
    """``artgs bench-check``: manipulation success per category (the paper's Table II)."""

    per_category: int = option(2, "objects per category (generated sets)")
    category: list[str] | None = option(None, "generated sets: only these categories",
                                        choices=CATEGORIES)
    robot: str = option("franka_panda", "robot from pybullet_data that performs the check",
                        choices=ROBOTS)
    in_view_robot: str | None = _in_view_robot()
