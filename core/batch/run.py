""":func:`run_batch`: every capture of a batch through the pipeline, resumable, one bar, a summary.

- A capture whose outputs are complete and newer than its inputs (:func:`core.resume.complete`),
  run with the same options, is skipped; in the others, stages already finished are not re-run
  (``pipeline.run(..., resume=True)``). ``force`` re-runs everything.
- Each capture runs in a worker (local pool or Ray); its errors are its own (status ``failed``
  with the message), a worker that dies is retried up to ``retries`` times (then ``died``).
- Ctrl-C: workers are cancelled (outputs in OUT are written atomically, so a cancelled stage
  leaves the previous files), the summary is written, and :class:`KeyboardInterrupt` propagates
  (exit 130); the next call continues where this one stopped.
"""

from __future__ import annotations

import dataclasses
import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..resume import complete
from ..model.outdir import claim_out
from ..model.progress import Progress
from . import summary
from .bar import BatchBar
from .jobs import Job, plan
from .worker import Outcome


@dataclass
class BatchOptions:
    """How a batch runs (the stages' own options are passed separately)."""

    workers: int = 1                 # local processes, or concurrent tasks of an auto-started Ray
    ray: bool = False                # run captures as Ray tasks
    address: str | None = None       # Ray cluster to connect to (None: start one on 127.0.0.1)
    retries: int = 2                 # restarts of a capture whose worker died
    cpus: int = 1                    # Ray: CPUs per capture task (local: the slot's share)
    gpus: float | None = None        # Ray: GPUs per capture task (None: 1 if --device cuda)
    force: bool = False              # re-run captures and stages that are already done


@dataclass
class BatchResult:
    """The summary rows (one per capture, in the order given) and the totals."""

    rows: list[dict[str, Any]]
    totals: dict[str, Any]
    cancelled: bool = False

    @property
    def all_ok(self) -> bool:
        return all(r["status"] in ("ok", "skipped") for r in self.rows)


def options_record(stage_options: dict[str, Any]) -> dict[str, Any]:
    """The stages' options as plain JSON (recorded per capture; a change means a re-run)."""
    return json.loads(json.dumps({k: dataclasses.asdict(v) for k, v in sorted(stage_options.items())},
                                 default=str))


def run_batch(captures: list[str | Path], out_dir: str | Path, stage_options: dict[str, Any],
              options: BatchOptions, progress: Progress) -> BatchResult:
    """Run every capture into ``out_dir/<name>/``; writes and returns the summary.

    Raises :class:`KeyboardInterrupt` after writing the summary when cancelled.
    """
    out_dir = Path(out_dir)
    jobs = plan(captures, out_dir)
    with claim_out(out_dir, "artgs batch"):   # one batch per DIR at a time
        return _run_batch(jobs, out_dir, stage_options, options, progress)


def _run_batch(jobs: list[Job], out_dir: Path, stage_options: dict[str, Any],
               options: BatchOptions, progress: Progress) -> BatchResult:
    record = options_record(stage_options)
    previous = {r.get("name"): r for r in summary.read_previous(out_dir).get("captures", [])
                if isinstance(r, dict)}
    todo: list[Job] = []
    skipped: list[Job] = []
    for job in jobs:
        # outputs are reused only where the capture last ran with these options (or no record)
        reuse = not options.force and previous.get(job.name, {}).get("options") in (None, record)
        if reuse and complete(job.out, job.capture):
            skipped.append(job)
        else:
            todo.append(dataclasses.replace(job, resume=reuse))
    for job in todo:
        job.log.parent.mkdir(parents=True, exist_ok=True)
        job.log.write_text("", encoding="utf-8")

    workers = max(1, options.workers)
    bar = BatchBar(progress, len(jobs), len(skipped), workers)
    for job in skipped:
        progress.log(f"{job.name}: outputs complete and newer than the capture, skipped")
    bar.show()
    outcomes: dict[str, Outcome] = {}

    def ended(job: Job, outcome: Outcome) -> None:
        outcomes[job.name] = outcome
        bar.ended(job, outcome)

    start = time.monotonic()
    cancelled = False
    try:
        if todo:
            _run(todo, stage_options, options, workers, bar, ended)
    except KeyboardInterrupt:
        cancelled = True
    interrupted = set(bar.running) if cancelled else set()
    bar.close()
    wall = time.monotonic() - start

    rows = []
    for job in jobs:
        outcome = outcomes.get(job.name)
        r = summary.row(job, outcome, "skipped" if job in skipped else
                        "cancelled" if job.name in interrupted else None)
        ran = job in skipped or job.name in outcomes or job.name in interrupted
        r["options"] = record if ran else previous.get(job.name, {}).get("options")
        rows.append(r)
    backend = "ray" if options.ray else "local"
    total = summary.totals(rows, wall, workers, backend)
    summary.write(out_dir, rows, total, record)
    if progress.mode == "text":
        print(summary.table(rows, total))
    progress.finished(summary=str(out_dir / "batch_summary.json"), **{
        k: total[k] for k in ("captures", "ok", "skipped", "failed", "died", "cancelled")})
    if cancelled:
        raise KeyboardInterrupt
    return BatchResult(rows, total)


def _run(jobs: list[Job], stage_options: dict[str, Any], options: BatchOptions, workers: int,
         bar: BatchBar, ended) -> None:
    if options.ray:
        from .ray_pool import run_ray

        gpus = options.gpus
        if gpus is None:
            gpus = float(any(getattr(o, "device", None) == "cuda" for o in stage_options.values()))
        run_ray(jobs, stage_options, options.address, workers, max(1, options.cpus), gpus,
                options.retries, bar.started, ended, bar.retrying)
    else:
        from .local import run_local

        run_local(jobs, stage_options, workers, options.retries, bar.started, ended, bar.retrying)
