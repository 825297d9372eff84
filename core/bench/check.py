"""``artgs bench-check``: manipulation success per category, in the layout of the paper's Table II.

For each capture of the benchmark set (core/bench/sets.py: ``--set tight|realistic|partnet:DIR|
data:DIR``): propose joints (motion route, on the
depth-initialised splat unless ``--iterations``), then a robot opens every part of the capture's
ground-truth ``gt.urdf`` along the proposed joints (core/sim/manipulate.py): "proposals only".
When the project has an ``optimise`` stage it is run next and the check repeated: "with
optimisation". Prints success rate per category and overall, and seconds per check.
"""

from __future__ import annotations

import json
import math
import tempfile
import time
from pathlib import Path

from ..model import layout, registry
from ..model.capture import load_capture
from ..model.errors import InputError, NothingFound
from ..model.joints import read_articulation
from ..model.ply import write_ply
from ..model.progress import QUIET, Progress
from ..model.registry import CheckOptions, ProposeOptions
from .options import BenchCheckOptions
from .sets import materialise, parse_set


def check_out(out: Path, urdf: Path, robot: str) -> dict[str, dict]:
    """Per joint of ``urdf``: the check's result when planned from OUT's joints."""
    from ..stages.check.stage import run as run_check

    figures = run_check(out, None, CheckOptions(urdf=str(urdf), robot=robot, frames=0), QUIET)
    return figures["joints"]


def bench_capture(capture_dir: Path, work: Path, options: BenchCheckOptions) -> dict:
    """Proposals (and optimisation, if the stage exists) for one capture, each checked."""
    from ..pipeline import run_stage
    from ..stages.propose.stage import propose
    from ..stages.reconstruct import initial_splats, reconstruct

    capture = load_capture(capture_dir)
    gt = read_articulation(capture_dir / "gt.json")
    out = work / capture_dir.name
    out.mkdir(parents=True, exist_ok=True)
    if options.iterations > 0:
        reconstruct(capture, out, QUIET, iterations=options.iterations, device=options.device)
    else:
        write_ply(out / layout.SPLAT, initial_splats(capture.static)[0])
    result = {"capture": capture_dir.name, "category": gt.meta.get("category", capture_dir.name),
              "seconds_per_check": 0.0}
    try:
        propose(capture, out, QUIET, ProposeOptions(method="motion", device=options.device))
    except NothingFound:                       # every part counts as not opened
        missed = {j.name: {"success": False, "reason": "no joints proposed"} for j in gt.joints}
        return {**result, "proposals": missed, "optimised": missed}
    t0 = time.perf_counter()
    result["proposals"] = check_out(out, capture_dir / "gt.urdf", options.robot)
    result["seconds_per_check"] = (time.perf_counter() - t0) / max(len(result["proposals"]), 1)
    if "optimise" in registry.names():
        run_stage("optimise", out, registry.stage("optimise").options(), QUIET, capture=capture)
        result["optimised"] = check_out(out, capture_dir / "gt.urdf", options.robot)
    return result


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
    [--seed S] [--category C ...]``."""
    with tempfile.TemporaryDirectory(prefix="artgs-bench-check-") as tmp:
        tmp = Path(tmp)
        bset = parse_set(args.set, args.data)
        captures = [c for c in materialise(bset, tmp / "data", per_category=args.per_category,
                                           seed=args.seed, categories=args.category,
                                           progress=progress, marker="gt.json",
                                           **({} if bset.kind == "data" else
                                              {"width": args.width, "height": args.height}))
                    if (c / "gt.urdf").is_file()]
        if not captures:
            raise InputError(bset.label, "no captures with gt.json and gt.urdf", field="set")
        progress.start("bench-check", f"{len(captures)} captures")
        results = []
        for k, cap in enumerate(captures):
            r = bench_capture(Path(cap), tmp / "out", args)
            results.append(r)
            wins = sum(bool(j["success"]) for j in r["proposals"].values())
            progress.update("bench-check", (k + 1) / len(captures), r["capture"],
                            opened=f"{wins}/{len(r['proposals'])}")
        progress.finish("bench-check", captures=len(captures))
    if progress.mode == "json":
        progress.finished(results=json.dumps(results))
    else:
        print(f"set {bset.label}, robot {args.robot}, splat iterations {args.iterations}, "
              f"{len(captures)} captures")
        print(table(results))
    return 0
