"""``artgs bench-optimise``: joint accuracy per category without and with the optimisation.

For each capture of the benchmark set (core.bench.sets: ``--set tight|realistic|partnet:DIR``,
generated into a temporary folder, or ``--data DIR``):
the static splat (:func:`.runs.prepare`: reconstructed until converged, or per
``--iterations``), the motion route's proposals (core.stages.propose), then the optimisation
(core.stages.optimise); both scored against
``gt.json`` (core.geometry.metrics.match_joints). Prints per category: joints, type accuracy, AE
mean/worst (deg), OE mean/worst (cm, revolute joints), extra joints (matched to no true one)
before -> after, and wall and CPU seconds
of optimisation per object; then the basin rate: from ``--basin`` starts per capture made from the
ground truth with the axis turned by 10–30° and the line moved by 5–15 cm (every second one also
of the wrong type, without states), the share of joints that end with the right type within 1°
and 1 cm, overall and per kind of start.
"""

from __future__ import annotations

import copy
import json
import math
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..geometry.metrics import match_joints
from ..model import layout
from ..model.capture import Capture
from ..model.errors import NothingFound
from ..model.joints import (Articulation, Joint, read_articulation, rotation_about_axis,
                            write_articulation)
from ..model.progress import QUIET, Progress
from ..model.registry import OptimiseOptions
from .options import BenchOptimiseOptions
from .propose import summarize
from .runs import (materialise_variants, motion_proposals, plan_variants, prepare, run_variants,
                   splat_label)
from .sets import parse_set


def _scores(pred, gt) -> list[dict]:
    return [{"joint": s.true_name, "pred": s.pred_name, "type_ok": s.type_correct,
             "ae": s.axis_error_deg, "oe": s.origin_error_cm} for s in match_joints(pred, gt)]


def extra_joints(pred, scores: list[dict]) -> int:
    """Predicted joints matched to no true joint (spurious parts a user would have to delete);
    the AE/OE figures, one per true joint, do not see them."""
    return len(pred) - len({s["pred"] for s in scores if s["pred"] is not None})


def perturbed(joints, rng: np.random.Generator, wrong_type: bool = False) -> list:
    """Copies of ``joints`` with the axis turned by 10–30° and the line moved by 5–15 cm (their
    states, the true ones, are kept); ``wrong_type``: also of the other type, without states or
    limits (a hinge drawn as a slide: the optimisation must find the type and the states)."""
    out = []
    for j in joints:
        j = copy.deepcopy(j)
        p = np.cross(j.axis, rng.normal(size=3))
        j.axis = rotation_about_axis(p / np.linalg.norm(p), math.radians(rng.uniform(10, 30))) @ j.axis
        d = rng.normal(size=3)
        d -= (d @ j.axis) * j.axis
        j.origin = j.origin + rng.uniform(0.05, 0.15) * d / np.linalg.norm(d)
        if wrong_type:
            j.type = "prismatic" if j.type == "revolute" else "revolute"
            j.states, j.limit = None, (0.0, 0.0)
        out.append(j)
    return out


#: The kinds of perturbed starts of the basin runs, in turn.
STARTS = ("perturbed", "wrong type")


def optimised_joints(out: Path, capture: Capture, options: OptimiseOptions) -> list[Joint]:
    """``artgs optimise`` on OUT and its joints; none when it finds no moving part (the stage
    then raises NothingFound and leaves OUT as it was: every true joint counts as missed)."""
    from ..stages.optimise import optimise

    try:
        optimise(out, capture, QUIET, options)
    except NothingFound:
        return []
    return read_articulation(out / layout.ARTICULATION).joints


def bench_capture(capture_dir: Path, work: Path, options: OptimiseOptions,
                  iterations: int | None = None, basin: int = 0, seed: int = 0) -> dict:
    """Propose, optimise and score one capture; plus ``basin`` perturbed-start runs. The
    proposals use the twin as the optimisation does (``options.robot_twin``)."""
    capture, gt, out = prepare(capture_dir, work, iterations, options.device)
    proposals = motion_proposals(capture, out, options.device, options.robot_twin)
    t0, c0 = time.perf_counter(), time.process_time()
    after = optimised_joints(out, capture, options)
    seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
    category = gt.meta.get("category", capture_dir.name)
    before, scored = _scores(proposals.joints, gt.joints), _scores(after, gt.joints)
    result = {"capture": capture_dir.name, "category": category, "seconds": seconds,
              "cpu_seconds": cpu, "before": before, "after": scored,
              "extra_before": extra_joints(proposals.joints, before),
              "extra_after": extra_joints(after, scored), "basin": []}
    rng = np.random.default_rng([seed, len(capture_dir.name)])
    for i in range(basin):
        kind = STARTS[i % len(STARTS)]
        start = perturbed(gt.joints, rng, wrong_type=kind == "wrong type")
        write_articulation(out / layout.PROPOSALS, Articulation(start, {"source": "bench"}))
        result["basin"] += [{**s, "start": kind}
                            for s in _scores(optimised_joints(out, capture, options), gt.joints)]
    return result


def format_table(before: list[dict], after: list[dict]) -> str:
    """Per category: joints, type %, AE mean/worst, OE mean/worst, extra joints (matched to no
    true joint: :func:`extra_joints`) before -> after, wall and CPU seconds of optimisation per
    object (CPU: user + system time of the process, all threads; comparable between a quiet
    and a loaded machine, where wall seconds are not)."""
    def f(v: float, p: int = 2) -> str:
        return "-" if math.isnan(v) else f"{v:.{p}f}"
    head = (f"{'category':<13}{'joints':>7}{'type %':>12}{'AE mean':>15}{'AE worst':>15}"
            f"{'OE mean cm':>15}{'OE worst cm':>15}{'extra':>8}{'s/obj':>7}{'CPU s':>7}")
    lines = [head, "-" * len(head)]
    for b, a in zip(before, after):
        types = f"{100 * b['type_acc']:.0f}->{100 * a['type_acc']:.0f}"
        lines.append(
            f"{a['category']:<13}{a['joints']:>7}{types:>12}"
            f"{f(b['ae_mean']) + '->' + f(a['ae_mean']):>15}{f(b['ae_max']) + '->' + f(a['ae_max']):>15}"
            f"{f(b['oe_mean']) + '->' + f(a['oe_mean']):>15}{f(b['oe_max']) + '->' + f(a['oe_max']):>15}"
            f"{str(b['extra']) + '->' + str(a['extra']):>8}"
            f"{a['seconds']:>7.1f}{a['cpu_seconds']:>7.1f}")
    return "\n".join(lines)


def basin_rate(results: list[dict], ae: float = 1.0, oe: float = 1.0,
               start: str | None = None) -> tuple[float, int]:
    """Share of perturbed-start joints (of the ``start`` kind of :data:`STARTS`, or all) ending
    with the right type within ``ae`` degrees and ``oe`` cm, and their count."""
    scores = [s for r in results for s in r["basin"] if start in (None, s.get("start"))]
    ok = [s["type_ok"] and s["ae"] <= ae and (s["oe"] is None or s["oe"] <= oe) for s in scores]
    return (sum(ok) / len(ok) if ok else math.nan), len(ok)


def comparison(title: str, base: dict, row: dict) -> str:
    """One line: ``row``'s overall type %, AE mean and OE mean against the robot-free ``base``
    (relative change in %; ``-`` where the robot-free figure is zero or not applicable)."""
    def rel(key: str, unit: str, scale: float = 1.0, p: int = 2) -> str:
        v, b = scale * row[key], scale * base[key]
        if math.isnan(v) or math.isnan(b):
            return "- (robot-free -)"
        change = "-" if b == 0 else f"{100 * (v - b) / b:+.0f} %"
        return f"{v:.{p}f}{unit} (robot-free {b:.{p}f}{unit}, {change})"
    return (f"{title}: type {rel('type_acc', ' %', 100, 0)}, AE mean {rel('ae_mean', ' deg')}, "
            f"OE mean {rel('oe_mean', ' cm')}")


def bench_optimise(args: BenchOptimiseOptions, progress: Progress) -> int:
    """``artgs bench-optimise [--set tight|realistic|partnet:DIR|data:DIR] [--per-category N]
    [--seed S] [--category C ...] [--width W --height H] [--iterations N] [--opt-iterations N]
    [--opt-seed S] [--basin N] [--robot R]``."""
    base = OptimiseOptions(iterations=args.opt_iterations, device=args.device, seed=args.opt_seed)
    bset = parse_set(args.set, args.data)
    variants = plan_variants(bset, args.robot)
    with tempfile.TemporaryDirectory(prefix="artgs-bench-optimise-") as tmp:
        tmp = Path(tmp)
        sets = materialise_variants(bset, tmp, variants, per_category=args.per_category,
                                    seed=args.seed, categories=args.category, progress=progress,
                                    marker="gt.json", width=args.width, height=args.height)
        runs = run_variants(
            sets, lambda cap, work, v: bench_capture(
                cap, work, replace(base, robot_twin=v.robot_twin), args.iterations, args.basin,
                args.seed),
            tmp, progress, "bench-optimise",
            lambda r: {"seconds": round(r["seconds"], 1),
                       "worst_ae": round(max((s["ae"] for s in r["after"]), default=0.0), 2)})
    tables = [(v, summarize([{**r, "scores": r["before"], "extra": r["extra_before"]}
                             for r in results]),
               summarize([{**r, "scores": r["after"], "extra": r["extra_after"]}
                          for r in results]), results)
              for v, results in runs]
    if progress.mode == "json":
        _, before, after, results = tables[0]
        rate, n = basin_rate(results)
        progress.finished(before=json.dumps(before), after=json.dumps(after), basin_rate=rate,
                          basin_joints=n, results=json.dumps(results),
                          variants=json.dumps([{"title": v.title, "before": b, "after": a}
                                               for v, b, a, _ in tables]))
        return 0
    print(f"set {bset.label}, {len(sets[0][1])} captures, splat {splat_label(args.iterations)}, "
          f"optimisation iterations {args.opt_iterations}, seed {args.opt_seed}")
    for v, before, after, results in tables:
        if len(tables) > 1:
            print(f"\n{v.title}:")
        print(format_table(before, after))
        rate, n = basin_rate(results)
        if n:
            kinds = ", ".join(f"{k} {100 * r:.0f} % of {m}" for k in STARTS
                              for r, m in [basin_rate(results, start=k)] if m)
            print(f"basin: {100 * rate:.0f} % of {n} joints from perturbed starts (10-30 deg, "
                  f"5-15 cm; {kinds}) end with the right type within 1 deg and 1 cm")
    if len(tables) > 1:
        print("\nafter optimisation, overall, against robot-free:")
        for v, _, after, _ in tables[1:]:
            print(comparison(v.title, tables[0][2][-1], after[-1]))
    return 0
