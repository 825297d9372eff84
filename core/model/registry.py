"""The stage registry: the one place a pipeline stage is declared.

Each :class:`StageSpec` names a stage (the CLI sub-command, its ``report.json`` key and the
add-on's stage id), the files it reads and writes in OUT, the dataclass of its user-facing
options, and its run function as a ``"module:function"`` string under ``core`` (imported only when
the stage runs, so this module stays numpy-only and safe in Blender's process). ``artgs <stage>``,
``artgs run`` (the stages in this order), the add-on's stage list and the report all derive from
:data:`STAGES`.

A run function has the signature ``run(out: Path, capture: Capture | None, options, progress)
-> dict`` and returns JSON-able figures; :func:`core.pipeline.run_stage` does the rest (progress
start and finish, timing, the report entry, refusing missing inputs). A ``check`` function,
``check(capture, options)``, refuses unusable input before any stage of a run starts.

Option fields carry ``metadata``: ``help``; ``choices``; ``positional``; ``shared`` (one flag for
all stages in ``artgs run``, e.g. ``--device``).
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

from . import layout
from .errors import InputError

DEVICES = ("auto", "cpu", "cuda")
METHODS = ("motion", "vlm")


def option(default: Any, help: str, **meta: Any) -> Any:  # noqa: A002 - argparse's word
    """A dataclass field with its command-line help (and ``choices``, ``shared``, …)."""
    return field(default=default, metadata={"help": help, **meta})


#: Default working resolution (longer image side, pixels): what 2 CPU cores reconstruct in minutes.
MAX_SIDE = 640


def _max_side() -> Any:
    return option(MAX_SIDE, "working resolution: frames whose longer side is larger are shrunk "
                  "to this many pixels on load, intrinsics scaled (0: as captured)", shared=True)


def _device() -> Any:
    return option("auto", "where torch work runs (auto: CUDA with gsplat if available, else CPU)",
                  choices=DEVICES, shared=True)


@dataclass
class ReconstructOptions:
    """Options of ``artgs reconstruct``."""

    iterations: int | None = option(None, "iteration cap (default: until converged)")
    holdout: int = option(0, "static views held out for evaluation")
    separate: bool = option(True, "for a capture without masks, first separate the object from "
                            "the room and write its box to crop.json, which every stage then "
                            "uses (--no-separate: keep the room)")
    device: str = _device()
    max_side: int = _max_side()


def _robot_twin() -> Any:
    return option(True, "explain the robot arm's pixels by its twin (the robot's Gaussians posed "
                  "by robot_joint_positions); --no-robot-twin for the ablation", shared=True)


@dataclass
class ProposeOptions:
    """Options of ``artgs propose``."""

    method: str = option("motion", "how joints are proposed", choices=METHODS)
    device: str = _device()
    vlm_endpoint: str | None = option(None, "OpenAI-compatible base URL, e.g. "
                                      "http://127.0.0.1:8000/v1 (default: $ARTGS_VLM_ENDPOINT)",
                                      shared=True)
    vlm_model: str | None = option(None, "model name (default: $ARTGS_VLM_MODEL)", shared=True)
    vlm_timeout: float = option(60.0, "seconds for each VLM request, retries included",
                                shared=True)
    max_side: int = _max_side()
    robot_twin: bool = _robot_twin()


@dataclass
class OptimiseOptions:
    """Options of ``artgs optimise``."""

    iterations: int = option(300, "steps of the main fit (the later phases take fractions of it)")
    types: bool = option(True, "choose each joint's type by fitting both hypotheses (--no-types: "
                         "keep the proposals' types)")
    parts: bool = option(True, "remove parts the frames do not show moving and add parts they "
                         "show moving that no joint explains (--no-parts: the proposed parts)")
    assign: bool = option(True, "give each Gaussian to the part whose motion the frames' depth "
                          "supports, kept when it lowers the image loss (--no-assign: the "
                          "skinning's parts)")
    seed: int = option(0, "random seed of the frame sampling")
    cameras: bool = option(False, "learn a small correction (rotation, translation) of each fixed "
                           "interaction camera (--no-cameras: take them as registered)")
    square: bool = option(True, "try each joint along the nearest side of the body's box (its "
                          "up and footprint), kept when it explains the frames no worse than "
                          "the fit (--no-square: the fit's directions)")
    edges: bool = option(True, "try each hinge's point on the edges of its part's box along "
                         "its axis, kept when it explains the frames clearly better "
                         "(--no-edges: the fit's points)")
    depth: bool = option(True, "refine each joint last on the interaction frames' depth, kept "
                         "unless the image loss says it is worse (--no-depth: the rendering "
                         "fit's joints)")
    routes: bool = option(True, "run the optimisation twice, scoring small parts at half and at "
                          "full resolution, and keep the result that explains the frames better "
                          "(--no-routes: half resolution only, in about two thirds of the time)")
    helper: bool = option(True, "share the work with a second process when this one has two "
                          "or more threads: the second route (--routes) runs in it beside the "
                          "first, or with one route, a helper takes the type choice's second fit "
                          "of each joint and half of each fit step's frames (--no-helper: all in "
                          "this one; the result is the same)")
    device: str = _device()
    max_side: int = _max_side()
    robot_twin: bool = _robot_twin()


@dataclass
class ExportOptions:
    """Options of ``artgs export``."""

    face_budget: int = option(5000, "faces of a link's visual mesh (up to twice as many where "
                              "fewer would break its watertightness)")
    voxel: float | None = option(None, "TSDF voxel size in metres (default: a link's extent / 64)")
    views: int = option(32, "rendered depth views per link for the TSDF fusion")
    density: float = option(400.0, "kg/m^3 of the closed part volumes (mass, inertia)")
    collision_threshold: float = option(0.05, "CoACD concavity threshold of the collision pieces")
    max_hulls: int = option(16, "most convex pieces per link")
    effort: float = option(50.0, "joint effort limit (N or N m)")
    velocity: float = option(1.0, "joint velocity limit (rad/s or m/s)")
    damping: float = option(0.1, "joint damping")
    friction: float = option(0.0, "joint friction")
    separate: str = option("auto", "separate the object from the room (auto: when the capture "
                           "has no masks)", choices=("auto", "floor", "none"))


ROBOTS = ("franka_panda", "xarm6")


@dataclass
class CheckOptions:
    """Options of ``artgs check``."""

    urdf: str | None = option(None, "URDF to operate (default: OUT/model.urdf); e.g. a ground "
                              "truth gt.urdf with the joints of OUT/articulation.json as the plan")
    robot: str = option("franka_panda", "robot from pybullet_data", choices=ROBOTS)
    frames: int = option(6, "frames per joint in the PNG strip")


@dataclass(frozen=True)
class StageSpec:
    """One pipeline stage (see the module docstring)."""

    name: str
    title: str
    help: str
    reads: tuple[str, ...]
    writes: tuple[str, ...]
    options: type
    run: str
    check: str | None = None
    needs_capture: bool = True
    #: In ``artgs run``, what stands in for the stage's outputs when it finds nothing
    #: (``NothingFound``) and a later stage can still find it, called as ``(out, options,
    #: progress, reason)`` (``reason``: the error's); None: the run stops there.
    nothing_found: str | None = None


STAGES: tuple[StageSpec, ...] = (
    StageSpec("reconstruct", "Splat", "static Gaussian splat -> OUT/splat.ply",
              reads=(), writes=(layout.SPLAT,), options=ReconstructOptions,
              run="stages.reconstruct:run", check="stages.reconstruct:check"),
    StageSpec("propose", "Bones", "initial joints -> OUT/proposals.json",
              reads=(layout.SPLAT,), writes=(layout.PROPOSALS,), options=ProposeOptions,
              run="stages.propose.stage:run", check="stages.propose.stage:check",
              nothing_found="stages.propose.stage:none_proposed"),
    StageSpec("optimise", "Optimise", "fit joints, states and parts to the interaction frames "
              "-> OUT/articulation.json, OUT/part_labels.npy",
              reads=(layout.SPLAT, layout.PROPOSALS),
              writes=(layout.ARTICULATION, layout.PART_LABELS), options=OptimiseOptions,
              run="stages.optimise.stage:run", check="stages.optimise.stage:check"),
    StageSpec("export", "Export", "part meshes, collision pieces and OUT/model.urdf, validated",
              reads=(layout.SPLAT, layout.ARTICULATION), writes=(layout.URDF,),
              options=ExportOptions, run="stages.export.stage:run"),
    StageSpec("check", "Check", "a robot opens every part in PyBullet along the estimated joints",
              reads=(layout.PROPOSALS,), writes=(layout.CHECK_STRIP,),
              options=CheckOptions, run="stages.check.stage:run", needs_capture=False),
)


def stage(name: str) -> StageSpec:
    """The stage called ``name``."""
    for s in STAGES:
        if s.name == name:
            return s
    raise KeyError(f"no stage {name!r}; stages: {', '.join(names())}")


def names() -> list[str]:
    """Stage names in pipeline order."""
    return [s.name for s in STAGES]


def producer_of(filename: str) -> StageSpec | None:
    """The stage that writes ``filename`` in OUT (None for files no stage writes)."""
    return next((s for s in STAGES if filename in s.writes), None)


def require(out: str | Path, filename: str) -> Path:
    """Path of an input file in OUT, or a clear error naming the stage that makes it."""
    path = Path(out) / filename
    if not path.is_file():
        maker = producer_of(filename)
        hint = f"; run `artgs {maker.name}` first" if maker else ""
        raise InputError(path, f"not found{hint}")
    return path


def option_names(options: type) -> list[str]:
    """Field names of an options dataclass."""
    return [f.name for f in fields(options)]
