"""What the accuracy benchmarks (bench-propose, bench-optimise, bench-check) share.

- The variants of a set (issue 16): robot-free, and with ``--robot`` (bench-check:
  ``--in-view-robot``) the same objects generated again with that robot opening the parts in view,
  scored once with the robot's twin and once without it (the ablation).
- The loop over the variants' captures with progress.
- The first steps on one capture: the static splat and the motion route's proposals (an empty
  ``Articulation`` when the route finds nothing, so later steps still run).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

from ..geometry.crop_capture import SEPARATION, crop_capture
from ..model import layout
from ..model.crop import read_crop
from ..model.capture import Capture, load_capture
from ..model.errors import InputError, NothingFound
from ..model.joints import Articulation, read_articulation
from ..model.ply import write_ply
from ..model.progress import QUIET, Progress
from ..model.registry import ProposeOptions
from .sets import BenchSet, materialise


@dataclass(frozen=True)
class Variant:
    """One benchmark variant: its table title, the robot in view (None: robot-free) and whether
    the stages explain the robot's pixels by its twin."""

    title: str
    robot: str | None = None
    robot_twin: bool = True


ROBOT_FREE = Variant("robot-free")


def plan_variants(bset: BenchSet, robot: str | None, flag: str = "robot") -> list[Variant]:
    """Robot-free; with ``robot`` also the robot in view with its twin and without (ablation).

    ``flag`` names the option in the error for a ``data:`` set (its captures are used as made).
    """
    if robot is None:
        return [ROBOT_FREE]
    if bset.kind == "data":
        raise InputError("command line", f"--{flag.replace('_', '-')} needs a generated set "
                         "(data: captures are used as they were made)", field=flag)
    return [ROBOT_FREE, Variant(f"{robot} in view, with its twin", robot, True),
            Variant(f"{robot} in view, without the twin (ablation)", robot, False)]


def materialise_variants(bset: BenchSet, work: Path, variants: Sequence[Variant],
                         **kwargs: Any) -> list[tuple[Variant, list[Path]]]:
    """Each variant with its capture folders; a robot's set is generated once for both of its
    variants (``kwargs``: those of :func:`core.bench.sets.materialise`)."""
    sets: dict[str | None, list[Path]] = {}
    for v in variants:
        if v.robot not in sets:
            extra = {"robot": v.robot} if v.robot else {}
            sets[v.robot] = materialise(bset, work / (v.robot or "data"), **kwargs, **extra)
    return [(v, sets[v.robot]) for v in variants]


def run_variants(sets: Sequence[tuple[Variant, list[Path]]],
                 bench: Callable[[Path, Path, Variant], dict[str, Any]], work: Path,
                 progress: Progress, name: str,
                 figures: Callable[[dict[str, Any]], dict[str, Any]] = lambda r: {}
                 ) -> list[tuple[Variant, list[dict[str, Any]]]]:
    """``bench(capture_dir, out_folder, variant)`` for every capture of every variant, with
    progress (``figures`` of a result go into its progress line); results per variant."""
    total = sum(len(caps) for _, caps in sets)
    progress.start(name, f"{total} captures")
    done, out = 0, []
    for k, (variant, caps) in enumerate(sets):
        results = []
        for cap in caps:
            r = bench(Path(cap), work / f"out{k}", variant)
            results.append(r)
            done += 1
            progress.update(name, done / total, r["capture"], **figures(r))
        out.append((variant, results))
    progress.finish(name, captures=total)
    return out


def prepare(capture_dir: Path, work: Path, iterations: int | None = None,
            device: str = "auto") -> tuple[Capture, Articulation, Path]:
    """The capture, its ``gt.json`` and ``work/<capture>/`` holding the static splat:
    depth-initialised (``iterations`` 0), or reconstructed for ``iterations`` iterations (None:
    until converged, as ``artgs run``). A capture without masks is separated from the room first
    and returned as the stages see it, as ``artgs run`` does (core/geometry/crop_capture.py)."""
    from ..stages.reconstruct import initial_splats, reconstruct, separated

    capture = load_capture(capture_dir)
    gt = read_articulation(capture_dir / "gt.json")
    out = work / capture_dir.name
    out.mkdir(parents=True, exist_ok=True)
    box = read_crop(out)
    if box is not None and box.source != SEPARATION:
        capture = crop_capture(capture, box)            # a user's box, as the pipeline applies
    capture, _ = separated(capture, out, QUIET)
    if iterations != 0:
        reconstruct(capture, out, QUIET, iterations=iterations, device=device)
    else:
        write_ply(out / layout.SPLAT, initial_splats(capture.static)[0])
    return capture, gt, out


def splat_label(iterations: int | None) -> str:
    """How the benchmark's static splat was made, for its header line."""
    if iterations == 0:
        return "depth-initialised"
    return "reconstructed " + ("until converged" if iterations is None else
                               f"for {iterations} iterations")


def motion_proposals(capture: Capture, out: Path, device: str = "auto",
                     robot_twin: bool = True) -> Articulation:
    """The motion route's proposals, written to OUT; when it finds nothing an empty
    ``Articulation`` is written instead (the optimisation can still add parts)."""
    from ..stages.propose.stage import no_joints, propose

    try:
        return propose(capture, out, QUIET, ProposeOptions(method="motion", device=device,
                                                           robot_twin=robot_twin))
    except NothingFound:
        return no_joints(out, "motion")
