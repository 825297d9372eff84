"""``artgs bench-optimise``: joint accuracy per category without and with the optimisation.

For each capture of the benchmark set (core.bench.sets: ``--set tight|realistic|partnet:DIR``,
generated into a temporary folder, or ``--data DIR``):
the static splat (depth-initialised, or reconstructed for ``--iterations``), the motion route's
proposals (core.stages.propose), then the optimisation (core.stages.optimise); both scored against
``gt.json`` (core.geometry.metrics.match_joints). Prints per category: joints, type accuracy, AE
mean/worst (deg), OE mean/worst (cm, revolute joints) before -> after, and wall and CPU seconds
of optimisation per object; then the basin rate: from ``--basin`` starts per capture made from the
ground truth with the axis turned by 10–30° and the line moved by 5–15 cm, the share of joints
that end within 1° and 1 cm.
"""

from __future__ import annotations

import copy
import json
import math
import tempfile
import time
from pathlib import Path

import numpy as np

from ..geometry.metrics import match_joints
from ..model import layout
from ..model.capture import load_capture
from ..model.errors import NothingFound
from ..model.joints import Articulation, read_articulation, rotation_about_axis, write_articulation
from ..model.ply import write_ply
from ..model.progress import QUIET, Progress
from ..model.registry import OptimiseOptions, ProposeOptions
from .options import BenchOptimiseOptions
from .propose import summarize
from .sets import materialise, parse_set


def _scores(pred, gt) -> list[dict]:
    return [{"joint": s.true_name, "pred": s.pred_name, "type_ok": s.type_correct,
             "ae": s.axis_error_deg, "oe": s.origin_error_cm} for s in match_joints(pred, gt)]


def perturbed(joints, rng: np.random.Generator) -> list:
    """Copies of ``joints`` with the axis turned by 10–30° and the line moved by 5–15 cm (their
    states, the true ones, are kept)."""
    out = []
    for j in joints:
        j = copy.deepcopy(j)
        p = np.cross(j.axis, rng.normal(size=3))
        j.axis = rotation_about_axis(p / np.linalg.norm(p), math.radians(rng.uniform(10, 30))) @ j.axis
        d = rng.normal(size=3)
        d -= (d @ j.axis) * j.axis
        j.origin = j.origin + rng.uniform(0.05, 0.15) * d / np.linalg.norm(d)
        out.append(j)
    return out


def bench_capture(capture_dir: Path, work: Path, options, iterations: int = 0, basin: int = 0,
                  seed: int = 0) -> dict:
    """Propose, optimise and score one capture; plus ``basin`` perturbed-start runs."""
    from ..stages.optimise import optimise
    from ..stages.propose.stage import propose
    from ..stages.reconstruct import initial_splats, reconstruct

    capture = load_capture(capture_dir)
    gt = read_articulation(capture_dir / "gt.json")
    out = work / capture_dir.name
    out.mkdir(parents=True, exist_ok=True)
    if iterations > 0:
        reconstruct(capture, out, QUIET, iterations=iterations, device=options.device)
    else:
        write_ply(out / layout.SPLAT, initial_splats(capture.static)[0])
    try:
        proposals = propose(capture, out, QUIET,
                            ProposeOptions(method="motion", device=options.device))
    except NothingFound:   # the motion route found nothing: the optimisation starts from no joints
        proposals = Articulation([], {"source": "motion"})
        write_articulation(out / layout.PROPOSALS, proposals)
    t0, c0 = time.perf_counter(), time.process_time()
    optimise(out, capture, QUIET, options)
    seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
    after = read_articulation(out / layout.ARTICULATION)
    category = gt.meta.get("category", capture_dir.name)
    result = {"capture": capture_dir.name, "category": category, "seconds": seconds,
              "cpu_seconds": cpu,
              "before": _scores(proposals.joints, gt.joints),
              "after": _scores(after.joints, gt.joints), "basin": []}
    rng = np.random.default_rng([seed, len(capture_dir.name)])
    for _ in range(basin):
        start = perturbed(gt.joints, rng)
        write_articulation(out / layout.PROPOSALS, Articulation(start, {"source": "bench"}))
        optimise(out, capture, QUIET, options)
        result["basin"] += _scores(read_articulation(out / layout.ARTICULATION).joints, gt.joints)
    return result


def format_table(before: list[dict], after: list[dict]) -> str:
    """Per category: joints, type %, AE mean/worst, OE mean/worst before -> after, wall and CPU
    seconds of optimisation per object (CPU: user + system time of the process, all threads;
    comparable between a quiet and a loaded machine, where wall seconds are not)."""
    def f(v: float, p: int = 2) -> str:
        return "-" if math.isnan(v) else f"{v:.{p}f}"
    head = (f"{'category':<13}{'joints':>7}{'type %':>12}{'AE mean':>15}{'AE worst':>15}"
            f"{'OE mean cm':>15}{'OE worst cm':>15}{'s/obj':>7}{'CPU s':>7}")
    lines = [head, "-" * len(head)]
    for b, a in zip(before, after):
        types = f"{100 * b['type_acc']:.0f}->{100 * a['type_acc']:.0f}"
        lines.append(
            f"{a['category']:<13}{a['joints']:>7}{types:>12}"
            f"{f(b['ae_mean']) + '->' + f(a['ae_mean']):>15}{f(b['ae_max']) + '->' + f(a['ae_max']):>15}"
            f"{f(b['oe_mean']) + '->' + f(a['oe_mean']):>15}{f(b['oe_max']) + '->' + f(a['oe_max']):>15}"
            f"{a['seconds']:>7.1f}{a['cpu_seconds']:>7.1f}")
    return "\n".join(lines)


def basin_rate(results: list[dict], ae: float = 1.0, oe: float = 1.0) -> tuple[float, int]:
    """Share of perturbed-start joints ending within ``ae`` degrees and ``oe`` cm, and their count."""
    scores = [s for r in results for s in r["basin"]]
    ok = [s["type_ok"] and s["ae"] <= ae and (s["oe"] is None or s["oe"] <= oe) for s in scores]
    return (sum(ok) / len(ok) if ok else math.nan), len(ok)


def bench_optimise(args: BenchOptimiseOptions, progress: Progress) -> int:
    """``artgs bench-optimise [--set tight|realistic|partnet:DIR|data:DIR] [--per-category N]
    [--seed S] [--category C ...] [--width W --height H] [--iterations N] [--opt-iterations N]
    [--basin N]``."""
    options = OptimiseOptions(iterations=args.opt_iterations, device=args.device)
    bset = parse_set(args.set, args.data)
    with tempfile.TemporaryDirectory(prefix="artgs-bench-optimise-") as tmp:
        tmp = Path(tmp)
        captures = materialise(bset, tmp / "data", per_category=args.per_category,
                               seed=args.seed, categories=args.category, progress=progress,
                               marker="gt.json", width=args.width, height=args.height)
        progress.start("bench-optimise", f"{len(captures)} captures")
        results = []
        for k, cap in enumerate(captures):
            r = bench_capture(Path(cap), tmp / "out", options, args.iterations, args.basin,
                              args.seed)
            results.append(r)
            progress.update("bench-optimise", (k + 1) / len(captures), r["capture"],
                            seconds=round(r["seconds"], 1),
                            worst_ae=round(max((s["ae"] for s in r["after"]), default=0.0), 2))
        before = summarize([{**r, "scores": r["before"]} for r in results])
        after = summarize([{**r, "scores": r["after"]} for r in results])
        rate, n = basin_rate(results)
        progress.finish("bench-optimise", captures=len(captures))
    if progress.mode == "json":
        progress.finished(before=json.dumps(before), after=json.dumps(after), basin_rate=rate,
                          basin_joints=n, results=json.dumps(results))
    else:
        print(f"set {bset.label}, {len(captures)} captures, splat iterations {args.iterations}, "
              f"optimisation iterations {args.opt_iterations}")
        print(format_table(before, after))
        if n:
            print(f"basin: {100 * rate:.0f} % of {n} joints from perturbed starts (10-30 deg, "
                  f"5-15 cm) end within 1 deg and 1 cm")
    return 0
