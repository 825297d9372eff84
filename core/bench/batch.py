"""``artgs bench-batch``: batch throughput (captures per hour) on this machine, per worker count.

The same captures (``--data``, or ``--count`` synthetic ones generated in a temporary folder, the
seven categories in turn) go through ``artgs batch`` on the local pool once per worker count, from
scratch each time (``force``), after an untimed warm-up capture that fills numba's kernel cache.
Captures per hour = captures / wall time; the README turns these into an estimate for N nodes.
"""

from __future__ import annotations

import dataclasses
import tempfile
from pathlib import Path

from ..batch.run import BatchOptions, run_batch
from ..model import registry
from ..model.categories import CATEGORIES
from ..model.progress import QUIET, Progress
from ..synth.generate import generate_object
from .options import BenchBatchOptions
from .reconstruct import captures_in


def _stage_options(iterations: int | None, device: str) -> dict:
    options = {}
    for spec in registry.STAGES:
        opts = spec.options()
        names = {f.name for f in dataclasses.fields(opts)}
        changes = {"device": device} if "device" in names else {}
        if spec.name == "reconstruct" and iterations is not None:
            changes["iterations"] = iterations
        options[spec.name] = dataclasses.replace(opts, **changes)
    return options


def bench_batch(options: BenchBatchOptions, progress: Progress) -> int:
    """Print wall time and captures per hour for each worker count."""
    stage_options = _stage_options(options.iterations, options.device)
    with tempfile.TemporaryDirectory(prefix="artgs-bench-batch-") as tmp:
        tmp = Path(tmp)
        if options.data:
            captures = captures_in(Path(options.data))
        else:
            captures = [generate_object(tmp / "data" / f"{CATEGORIES[i % len(CATEGORIES)]}_{i:02d}",
                                        CATEGORIES[i % len(CATEGORIES)], options.seed * 1000 + i,
                                        width=options.width, height=options.height,
                                        static_views=options.static_views)
                        for i in range(options.count)]
        progress.log(f"{len(captures)} captures; warm-up run (numba kernel cache)")
        run_batch(captures[:1], tmp / "warmup", stage_options, BatchOptions(workers=1), QUIET)
        rows = []
        for workers in options.workers:
            progress.log(f"{workers} worker(s)…")
            result = run_batch(captures, tmp / f"w{workers}", stage_options,
                               BatchOptions(workers=workers, ray=options.ray, force=True), QUIET)
            t = result.totals
            seconds = [r["seconds"] for r in result.rows if r["status"] == "ok"]
            rows.append((workers, len(captures), t["ok"], t["wall_seconds"],
                         sum(seconds) / max(1, len(seconds)), t["captures_per_hour"] or 0.0))
    print(f"{'workers':>7} {'captures':>8} {'ok':>3} {'wall s':>8} {'s/capture':>9} "
          f"{'captures/hour':>13}")
    for w, n, ok, wall, per, rate in rows:
        print(f"{w:>7} {n:>8} {ok:>3} {wall:>8.1f} {per:>9.1f} {rate:>13.1f}")
    if len(rows) > 1 and rows[0][5]:
        print(f"speed-up {rows[-1][0]} vs {rows[0][0]} worker(s): {rows[-1][5] / rows[0][5]:.2f}x")
    return 0
