"""Running stages: one stage (:func:`run_stage`) or all of them in registry order (:func:`run`).

Stages are declared once in :mod:`core.model.registry`; this module resolves their run functions
lazily, refuses an unusable OUT and missing inputs before work (naming the path, or the stage
that makes a missing file), holds OUT's lock while stages write (a second run into the same OUT
is refused, naming the first's pid), removes temporaries a killed run left, and records each
stage's figures and time in OUT/report.json. ``artgs run`` checks every stage's options against
the capture before the first stage starts.
"""

from __future__ import annotations

import importlib
import time
from pathlib import Path
from typing import Any, Callable

from .geometry.crop_capture import SEPARATED_BY, SEPARATION, crop_capture
from .model import layout, registry
from .model.crop import read_crop
from .model.capture import Capture, load_capture, resolution_note
from .model.errors import NothingFound
from .model.outdir import claim_out
from .model.joints import Articulation, read_articulation
from .model.progress import Progress
from .model.registry import StageSpec
from .resume import resume_since, stage_finished


def resolve(ref: str) -> Callable[..., Any]:
    """The function named by a registry reference ``"module:function"`` (module under core)."""
    module, func = ref.split(":")
    return getattr(importlib.import_module(f"{__package__}.{module}"), func)


def default_options(spec: StageSpec | str) -> Any:
    """The stage's options with every default."""
    spec = registry.stage(spec) if isinstance(spec, str) else spec
    return spec.options()


def _max_side(options: Any) -> int | None:
    """The working resolution a stage's options ask for (None: frames as captured)."""
    return getattr(options, "max_side", None) or None


def _log_resolution(capture: Capture, progress: Progress) -> None:
    note = resolution_note(capture)
    if note:
        progress.log(note)


def check_stage(spec: StageSpec, capture: Capture | None, options: Any) -> None:
    """Refuse options the capture cannot serve (the stage's ``check``), before any work."""
    if spec.check is not None and (capture is not None or not spec.needs_capture):
        resolve(spec.check)(capture, options)


def run_stage(spec: StageSpec | str, out: str | Path, options: Any, progress: Progress, *,
              capture: Capture | str | Path | None = None) -> dict[str, Any]:
    """Run one stage on OUT; returns its figures (also written to report.json).

    ``capture``: a loaded capture, its folder, or None for the one recorded in OUT's report.
    """
    spec = registry.stage(spec) if isinstance(spec, str) else spec
    out = Path(out)
    with claim_out(out, f"artgs {spec.name}"):
        return _run_stage(spec, out, options, progress, capture)


def _run_stage(spec: StageSpec, out: Path, options: Any, progress: Progress,
               capture: Capture | str | Path | None) -> dict[str, Any]:
    for name in spec.reads:
        registry.require(out, name)
    loaded: Capture | None = None
    if spec.needs_capture:
        loaded = capture if isinstance(capture, Capture) else \
            load_capture(layout.capture_of(out, capture), max_side=_max_side(options))
        _log_resolution(loaded, progress)
        box = read_crop(out)
        if not (box is not None and box.source == SEPARATION and spec.name == SEPARATED_BY):
            loaded = crop_capture(loaded, box)      # the separating stage makes its box anew
    check_stage(spec, loaded, options)
    progress.start(spec.name, spec.title.lower())
    figures = resolve(spec.run)(out, loaded, options, progress)
    seconds = round(progress.finish(spec.name, **{k: v for k, v in figures.items()
                                                   if isinstance(v, (int, float, str))}), 2)
    figures = {**figures, "seconds": seconds}
    if loaded is not None:
        layout.update_report(out, capture=str(Path(loaded.root).resolve()))
    layout.update_report(out, spec.name, **figures)
    return figures


def run(capture_dir: str | Path, out: str | Path, progress: Progress,
        options: dict[str, Any] | None = None, *, resume: bool = False) -> Articulation:
    """Every registered stage in order on one capture; returns the articulation in OUT.

    ``options``: per stage name, its options dataclass (defaults for the others). Every stage's
    check runs before the first stage starts. While no stage writes ``articulation.json``, the
    proposals are written as it, marked ``"optimised": false``. A stage that finds nothing and
    declares a ``nothing_found`` stand-in (the proposals: none, so that the optimisation searches
    the frames for moving parts) lets the run go on. ``resume``: a stage already
    finished in OUT for this capture (:func:`core.resume.stage_finished`) is not run again.
    """
    options = {s.name: (options or {}).get(s.name) or s.options() for s in registry.STAGES}
    out = Path(out)
    with claim_out(out, "artgs run"):
        return _run(Path(capture_dir), out, progress, options, resume)


def _run(capture_dir: Path, out: Path, progress: Progress, options: dict[str, Any],
         resume: bool) -> Articulation:
    start = time.perf_counter()
    progress.start("validate", "checking the capture")
    max_side = next((m for m in map(_max_side, options.values()) if m is not None), None)
    capture = load_capture(capture_dir, max_side=max_side)
    _log_resolution(capture, progress)
    for spec in registry.STAGES:
        check_stage(spec, capture, options[spec.name])
    progress.finish("validate", frames=len(capture.frames), interaction=len(capture.interaction))

    since = resume_since(out, capture_dir) if resume else None
    for spec in registry.STAGES:
        if since is not None and stage_finished(spec, out, since):
            progress.log(f"{spec.name}: already done, skipped")
            continue
        try:
            run_stage(spec, out, options[spec.name], progress, capture=capture)
        except NothingFound as nothing:
            if spec.nothing_found is None:
                raise
            figures = resolve(spec.nothing_found)(out, options, progress, nothing.reason)
            layout.update_report(out, spec.name, **figures)

    articulation = read_articulation(out / layout.ARTICULATION)
    layout.update_report(out, "run", seconds=round(time.perf_counter() - start, 2),
                         joints=len(articulation.joints))
    return articulation
