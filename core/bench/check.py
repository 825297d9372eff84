"""``artgs bench-check``: manipulation success per category, in the layout of the paper's Table II.

For each capture of the benchmark set (core/bench/sets.py: ``--set tight|realistic|partnet:DIR|
data:DIR``): propose joints (motion route, on the
static splat of :func:`.runs.prepare`), then a robot opens every part of the capture's
ground-truth ``gt.urdf`` along the proposed joints (core/sim/manipulate.py): "proposals only".
When the project has an ``optimise`` stage it is run next and the check repeated: "with
optimisation" (when the motion route finds nothing, no part opens on proposals alone and the
optimisation starts from no joints, as it may still add parts). Prints success rate per category
and overall, and seconds per check. With ``--in-view-robot R`` (generated sets) the same objects
are generated again with robot R opening the parts in view and benchmarked with the robot's twin
and without it (ablation; core/bench/runs.py): one table per variant.
"""

from __future__ import annotations

import json
import math
import tempfile
import time
from dataclasses import replace
from pathlib import Path

from ..model import registry
from ..model.errors import InputError, NothingFound
from ..model.progress import QUIET, Progress
from ..model.registry import CheckOptions
from .options import BenchCheckOptions
from .runs import (ROBOT_FREE, Variant, materialise_variants, motion_proposals, plan_variants,
                   prepare, run_variants, splat_label)
from .sets import parse_set


def check_out(out: Path, urdf: Path, robot: str) -> dict[str, dict]:
    """Per joint of ``urdf``: the check's result when planned from OUT's joints."""
    from ..stages.check.stage import run as run_check

    figures = run_check(out, None, CheckOptions(urdf=str(urdf), robot=robot, frames=0), QUIET)
    return figures["joints"]


def bench_capture(capture_dir: Path, work: Path, options: BenchCheckOptions,
                  variant: Variant = ROBOT_FREE) -> dict:
    """Proposals (and optimisation, if the stage exists) for one capture, each checked; both
    with the robot's twin or without it (``variant.robot_twin``). When the motion route finds
    nothing, no part opens on proposals alone, and the optimisation starts from no joints."""
    from ..pipeline import run_stage

    capture, gt, out = prepare(capture_dir, work, options.iterations, options.device)
    motion_proposals(capture, out, options.device, variant.robot_twin)
    urdf = capture_dir / "gt.urdf"
    t0 = time.perf_counter()
    result = {"capture": capture_dir.name, "category": gt.meta.get("category", capture_dir.name),
              "proposals": check_out(out, urdf, options.robot)}
    result["seconds_per_check"] = (time.perf_counter() - t0) / max(len(result["proposals"]), 1)
    if "optimise" in registry.names():
        optimise = replace(registry.stage("optimise").options(), robot_twin=variant.robot_twin)
        try:
            run_stage("optimise", out, optimise, QUIET, capture=capture)
        except NothingFound:     # OUT keeps no-joint proposals: every part counts as not opened
            pass
        result["optimised"] = check_out(out, urdf, options.robot)
    return result


def opened(joints: dict[str, dict]) -> str:
    """``k/n``: parts opened of a capture's checked parts."""
    return f"{sum(bool(j['success']) for j in joints.values())}/{len(joints)}"


def table(results: list[dict]) -> str:
    """Success rate (%) per category (columns) for each variant (rows), and seconds per check."""
    cats = sorted({r["category"] for r in results})
    head = f"{'':<20}" + "".join(f"{c[:12]:>13}" for c in cats) + f"{'overall':>10}"
    lines = [head, "-" * len(head)]
    for variant, label in (("proposals", "proposals only"), ("optimised", "with optimisation")):
        cells = []
        for group in [[r for r in results if r["category"] == c] for c in cats] + [results]:
            joints = [j for r in group for j in (r.get(variant) or {}).values()]
            cells.append(100.0 * sum(bool(j["success"]) for j in joints) / len(joints)
                         if joints else math.nan)
        lines.append(f"{label:<20}" + "".join("            -" if math.isnan(v) else f"{v:>12.1f}%"
                                              for v in cells[:-1])
                     + ("         -" if math.isnan(cells[-1]) else f"{cells[-1]:>9.1f}%"))
    per = [r["seconds_per_check"] for r in results]
    lines.append(f"seconds per check: {sum(per) / max(len(per), 1):.1f}")
    return "\n".join(lines)


def bench_check(args: BenchCheckOptions, progress: Progress) -> int:
    """``artgs bench-check [--set tight|realistic|partnet:DIR|data:DIR] [--per-category N]
    [--seed S] [--category C ...] [--robot R] [--in-view-robot R]``."""
    bset = parse_set(args.set, args.data)
    variants = plan_variants(bset, args.in_view_robot, "in_view_robot")
    with tempfile.TemporaryDirectory(prefix="artgs-bench-check-") as tmp:
        tmp = Path(tmp)
        sets = [(v, [c for c in caps if (c / "gt.urdf").is_file()]) for v, caps in
                materialise_variants(bset, tmp, variants, per_category=args.per_category,
                                     seed=args.seed, categories=args.category,
                                     progress=progress, marker="gt.json",
                                     **({} if bset.kind == "data" else
                                        {"width": args.width, "height": args.height}))]
        if not sets[0][1]:
            raise InputError(bset.label, "no captures with gt.json and gt.urdf", field="set")
        runs = run_variants(
            sets, lambda cap, work, v: bench_capture(cap, work, args, v), tmp, progress,
            "bench-check", lambda r: {"opened": opened(r["proposals"])})
    if progress.mode == "json":
        progress.finished(results=json.dumps(runs[0][1]),
                          variants=json.dumps([{"title": v.title, "results": results}
                                               for v, results in runs]))
        return 0
    print(f"set {bset.label}, robot {args.robot}, splat {splat_label(args.iterations)}, "
          f"{len(sets[0][1])} captures")
    for v, results in runs:
        if len(runs) > 1:
            print(f"\n{v.title}:")
        print(table(results))
    return 0
