"""``make demo``: a synthetic cabinet capture, then the whole pipeline headless through the add-on.

    python scripts/demo.py OUT

Writes OUT/capture/ (the generated capture, with its ground truth gt.json / gt.urdf) and, in OUT,
the engine's outputs (splat.ply, proposals.json, articulation.json, part_labels.npy, model.urdf,
parts/, check.png, report.json) plus scene.blend, preview.png (a
labelled contact sheet of every stage's result) and stages/<stage>.png (its panels, one per file).
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

from artgs.core.model.joints import read_articulation
from artgs.core.geometry.metrics import match_joints
from artgs.core.synth.generate import generate_object

#: Reconstruction iteration cap: enough for a recognisable splat, keeps the demo to minutes on a CPU.
ITERATIONS = 300


def main(argv: list[str]) -> int:
    if len(argv) != 1:
        sys.exit("usage: demo.py OUT")
    out = Path(argv[0]).resolve()
    t0 = time.perf_counter()
    capture = generate_object(out / "capture", "cabinet", 0)
    print(f"capture: {capture} ({time.perf_counter() - t0:.1f} s)", flush=True)
    script = Path(__file__).resolve().parent / "headless_pipeline.py"
    code = subprocess.call([sys.executable, str(script), str(capture), str(out),
                            "--iterations", str(ITERATIONS), "--panels", str(out / "stages")])
    if code != 0:
        return code
    print(f"\nOutput folder: {out}  ({time.perf_counter() - t0:.0f} s)")
    for path in sorted(p for p in out.iterdir() if p.is_file()):
        print(f"  {path.name:18s} {path.stat().st_size:>10,d} bytes")
    print(f"  {'capture/':18s} the generated capture (ground truth: capture/gt.json)")
    gt = read_articulation(capture / "gt.json").joints
    for title, name in (("Proposed", "proposals.json"), ("Optimised", "articulation.json")):
        if not (out / name).is_file():
            continue
        print(f"\n{title} joints ({name}) against the ground truth (shared/spec/metrics.md):")
        for s in match_joints(read_articulation(out / name).joints, gt):
            oe = "" if s.origin_error_cm is None else f", origin error {s.origin_error_cm:.2f} cm"
            print(f"  {s.true_name}: {s.pred_name or 'missed'}, type "
                  f"{'right' if s.type_correct else 'WRONG'}, axis error "
                  f"{s.axis_error_deg:.2f} deg{oe}")
    check = json.loads((out / "report.json").read_text()).get("stages", {}).get("check")
    if check:
        print(f"\nManipulation check (check.png): {json.dumps(check.get('joints', check))[:400]}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
