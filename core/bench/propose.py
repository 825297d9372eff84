"""``artgs bench-propose``: accuracy of the motion route per category on synthetic captures.

For each capture of the benchmark set (core.bench.sets: ``--set tight|realistic|partnet:DIR``,
generated into a temporary folder, or ``--data DIR``):
make the static splat (:func:`.runs.prepare`: reconstructed until converged as ``artgs run`` does,
or ``--iterations`` N; 0 = depth-initialised, faster and less accurate), run the motion route
(core.propose.propose) and score it against ``gt.json`` (core.metrics.match_joints).
Prints per category: joints, type accuracy, AE mean/worst (deg), OE mean/worst (cm, revolute
joints), seconds per capture; then overall.
"""

from __future__ import annotations

import json
import math
import tempfile
import time
from pathlib import Path

import numpy as np

from ..geometry.metrics import match_joints
from ..model.progress import Progress
from .options import BenchProposeOptions
from .runs import (materialise_variants, motion_proposals, plan_variants, prepare, run_variants,
                   splat_label)
from .sets import parse_set


def bench_capture(capture_dir: Path, work: Path, device: str = "auto",
                  iterations: int | None = None,
                  robot_twin: bool = True) -> dict:
    """Propose joints for one synthetic capture and score them against its gt.json.

    The static splat: :func:`.runs.prepare` (``iterations``).
    """
    capture, gt, out = prepare(capture_dir, work, iterations, device)
    t0 = time.perf_counter()
    art = motion_proposals(capture, out, device, robot_twin)
    seconds = time.perf_counter() - t0
    scores = match_joints(art.joints, gt.joints)
    return {"capture": capture_dir.name, "category": gt.meta.get("category", capture_dir.name),
            "seconds": seconds, "predicted": len(art.joints),
            "scores": [{"joint": s.true_name, "pred": s.pred_name, "type_ok": s.type_correct,
                        "ae": s.axis_error_deg, "oe": s.origin_error_cm} for s in scores]}


def summarize(results: list[dict]) -> list[dict]:
    """Rows per category plus an ``overall`` row (``extra``: the results' extra joints, where
    they count them)."""
    rows = []
    cats = sorted({r["category"] for r in results})
    for name, group in [(c, [r for r in results if r["category"] == c]) for c in cats] + \
            [("overall", results)]:
        scores = [s for r in group for s in r["scores"]]
        ae = [s["ae"] for s in scores]
        oe = [s["oe"] for s in scores if s["oe"] is not None]
        rows.append({"category": name, "captures": len(group), "joints": len(scores),
                     "type_acc": sum(s["type_ok"] for s in scores) / max(len(scores), 1),
                     "ae_mean": float(np.mean(ae)) if ae else math.nan,
                     "ae_max": max(ae) if ae else math.nan,
                     "oe_mean": float(np.mean(oe)) if oe else math.nan,
                     "oe_max": max(oe) if oe else math.nan,
                     "extra": sum(r.get("extra", 0) for r in group),
                     "seconds": float(np.mean([r["seconds"] for r in group])),
                     "cpu_seconds": float(np.mean([r.get("cpu_seconds", math.nan)
                                                   for r in group]))})
    return rows


def format_table(rows: list[dict]) -> str:
    w = max([13] + [len(r["category"]) + 1 for r in rows])
    head = (f"{'category':<{w}}{'caps':>5}{'joints':>7}{'type':>7}{'AE mean':>9}{'AE max':>8}"
            f"{'OE mean':>9}{'OE max':>8}{'s/cap':>7}")
    lines = [head, "-" * len(head)]
    for r in rows:
        def f(v: float, w: int, p: int) -> str:
            return f"{'-':>{w}}" if math.isnan(v) else f"{v:>{w}.{p}f}"
        lines.append(f"{r['category']:<{w}}{r['captures']:>5}{r['joints']:>7}"
                     f"{100 * r['type_acc']:>6.0f}%{f(r['ae_mean'], 9, 2)}{f(r['ae_max'], 8, 2)}"
                     f"{f(r['oe_mean'], 9, 2)}{f(r['oe_max'], 8, 2)}{r['seconds']:>7.1f}")
    return "\n".join(lines)


def bench_propose(args: BenchProposeOptions, progress: Progress) -> int:
    """``artgs bench-propose [--set tight|realistic|partnet:DIR|data:DIR] [--per-category N]
    [--seed S] [--depth-noise s] [--simultaneous] [--category C ...] [--width W --height H]
    [--iterations N] [--robot R]``."""
    bset = parse_set(args.set, args.data)
    variants = plan_variants(bset, args.robot)
    with tempfile.TemporaryDirectory(prefix="artgs-bench-propose-") as tmp:
        tmp = Path(tmp)
        sets = materialise_variants(bset, tmp, variants, per_category=args.per_category,
                                    seed=args.seed, categories=args.category, progress=progress,
                                    marker="gt.json", width=args.width, height=args.height,
                                    depth_noise=args.depth_noise, simultaneous=args.simultaneous)
        runs = run_variants(
            sets, lambda cap, work, v: bench_capture(cap, work, args.device, args.iterations,
                                                      robot_twin=v.robot_twin),
            tmp, progress, "bench-propose",
            lambda r: {"seconds": round(r["seconds"], 1),
                       "worst_ae": round(max((s["ae"] for s in r["scores"]), default=0.0), 2)})
    tables = [(v, summarize(results), results) for v, results in runs]
    captures = sets[0][1]
    if progress.mode == "json":
        progress.finished(**{f"rows{k or ''}": json.dumps(rows)
                             for k, (_, rows, _) in enumerate(tables)},
                          results=json.dumps(tables[0][2]))
    else:
        print(f"set {bset.label}, seed {args.seed}, depth noise {args.depth_noise} m, "
              f"simultaneous {args.simultaneous}, splat {splat_label(args.iterations)}, "
              f"{len(captures)} captures")
        for variant, rows, _ in tables:
            if len(tables) > 1:
                print(f"\n{variant.title}:")
            print(format_table(rows))
    return 0
