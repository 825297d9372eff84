"""``artgs bench-*``: the benchmark commands, each an options dataclass and a function."""

from __future__ import annotations

import argparse
from dataclasses import dataclass

from ..bench import options as bench_options
from ..model.progress import Progress
from .options import add_options, build


@dataclass(frozen=True)
class Benchmark:
    """A benchmark command: its options and its function (``"module:function"`` under core)."""

    name: str
    help: str
    options: type
    run: str


BENCHMARKS = (
    Benchmark("bench-render", "rasterizer speed benchmark", bench_options.BenchRenderOptions,
              "bench.render:bench_render"),
    Benchmark("bench-reconstruct", "reconstruction quality/speed per category",
              bench_options.BenchReconstructOptions, "bench.reconstruct:bench_reconstruct"),
    Benchmark("bench-propose", "proposal accuracy per category (motion route)",
              bench_options.BenchProposeOptions, "bench.propose:bench_propose"),
    Benchmark("bench-optimise", "joint accuracy per category without and with the "
              "optimisation; basin rate from perturbed starts",
              bench_options.BenchOptimiseOptions, "bench.optimise:bench_optimise"),
    Benchmark("bench-batch", "batch throughput: captures per hour for 1, 2, … local workers",
              bench_options.BenchBatchOptions, "bench.batch:bench_batch"),
    Benchmark("bench-check", "manipulation success per category (paper's Table II)",
              bench_options.BenchCheckOptions, "bench.check:bench_check"),
)


def add_parsers(sub: argparse._SubParsersAction, common) -> None:
    """One sub-command per benchmark."""
    for b in BENCHMARKS:
        p = sub.add_parser(b.name, help=b.help)
        add_options(p, b.options)
        common(p)
        p.set_defaults(handler=lambda args, progress, b=b: _run(b, args, progress))


def _run(b: Benchmark, args: argparse.Namespace, progress: Progress) -> int:
    from ..pipeline import resolve

    return resolve(b.run)(build(b.options, args), progress)
