"""``artgs propose``: initial joints from motion (default) or a VLM -> OUT/proposals.json.

Reads OUT/splat.ply (from ``artgs reconstruct``) and the capture; writes OUT/proposals.json
atomically (articulation.json schema plus per-joint ``source``, ``confidence``, ``bbox``,
``handle``, ``extent``; top-level ``source`` = the method and the route's ``meta``) and records
the stage in OUT/report.json. Bad input is refused before any work; on failure nothing in OUT
is touched.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from ...model import layout
from ...model.capture import TRANSFORMS, Capture, load_capture
from ...model.errors import InputError, NothingFound
from ...model.joints import Articulation, write_articulation
from ...model.ply import read_ply
from ...model.progress import Progress

STAGE = "propose"
METHODS = ("motion", "vlm")
_NOTHING_FOUND_HINT = {
    "motion": "Check that the interaction frames show a part moving between times.",
    "vlm": "The VLM's answers held no usable joint; try another model or --method motion.",
}


def check_inputs(capture: Capture, out: str | Path, method: str, vlm: Any) -> Path:
    """Refuse unusable input before any work; returns the splat's path."""
    check_capture(capture, method, vlm)
    return layout.require(out, layout.SPLAT, "reconstruct")


def check_capture(capture: Capture, method: str, vlm: Any) -> None:
    """Refuse a method the capture or the configuration cannot serve (before reconstruction)."""
    if method not in METHODS:
        raise InputError("--method", f"must be one of {METHODS}, not {method!r}")
    if method == "vlm" and vlm is None:
        from .vlm.client import vlm_config
        vlm_config()   # raises, naming $ARTGS_VLM_ENDPOINT / $ARTGS_VLM_MODEL
    if method == "motion":
        tj = Path(capture.root) / TRANSFORMS
        frames = [f for f in capture.interaction if f.depth is not None and f.time is not None]
        if len(capture.times) < 2 or not frames:
            raise InputError(tj, "the motion route needs interaction frames: RGB-D frames with "
                             "\"phase\": \"interaction\", a \"depth_file_path\" and an integer "
                             "\"time\", at two or more times (time 0 = closed) from fixed cameras; "
                             f"found {len(capture.interaction)} interaction frame(s) at "
                             f"{len(capture.times)} time(s). Use --method vlm without them",
                             field="frames")
        missing = [f for f in capture.interaction if f.depth is None]
        if missing:
            raise InputError(tj, "the motion route needs depth on every interaction frame",
                             frame=missing[0].index, field="depth_file_path")


def propose(capture: Capture, out: str | Path, progress: Progress, *, method: str = "motion",
            device: str = "auto", vlm: Any = None) -> Articulation:
    """Propose joints for ``capture`` with ``method`` and write OUT/proposals.json.

    ``vlm``: a ``core.vlm_client.VlmConfig`` (method ``vlm``; default from the environment).
    """
    out = Path(out)
    splat_path = check_inputs(capture, out, method, vlm)
    arrays = read_ply(splat_path)
    t0 = time.perf_counter()
    if method == "motion":
        from .motion import propose_motion
        opacity = 1.0 / (1.0 + np.exp(-np.asarray(arrays.opacity_logits, float)))
        joints, meta = propose_motion(capture, arrays.means, opacity,
                                      lambda camera: _render_depth(arrays, camera, device),
                                      progress)
    else:
        from ...render.gaussians import Gaussians
        from .vlm.propose import propose_vlm
        from .vlm.client import vlm_config
        joints, meta = propose_vlm(capture, Gaussians.from_arrays(arrays), progress,
                                   vlm or vlm_config(), device)
    if not joints:
        kept = (f"{out / layout.PROPOSALS} is left as it was" if (out / layout.PROPOSALS).exists()
                else f"no {layout.PROPOSALS} written")
        raise NothingFound(f"the {method} route found no joints; {kept}. "
                           + _NOTHING_FOUND_HINT[method])
    articulation = Articulation(joints, {"source": method, **meta})
    write_articulation(out / layout.PROPOSALS, articulation)
    layout.update_report(out, STAGE, seconds=round(time.perf_counter() - t0, 2),
                         joints=len(joints), method=method,
                         types=[j.type for j in joints])
    return articulation


def propose_stage(capture: Capture, out: str | Path, progress: Progress, *, method: str = "motion",
                  device: str = "auto", vlm=None) -> Articulation:
    """:func:`propose` as a pipeline stage, between progress start and finish."""
    progress.start(STAGE, f"proposing joints ({method})")
    articulation = propose(capture, out, progress, method=method, device=device, vlm=vlm)
    progress.finish(STAGE, joints=len(articulation.joints))
    return articulation


def _render_depth(arrays, camera, device: str) -> np.ndarray:
    """Depth of the splat seen by ``camera`` (for interaction cameras without a time-0 frame)."""
    import torch

    from ...render.device import resolve_device
    from ...render.gaussians import Gaussians
    from ...render.rasterize import render
    g = Gaussians.from_arrays(arrays, device=resolve_device(device))
    with torch.no_grad():
        res = render(g, camera)
    depth = res.depth.cpu().numpy()
    return np.where(res.alpha.cpu().numpy() > 0.5, depth, 0.0)


def propose_command(args, progress: Progress) -> int:
    """``artgs propose OUT [--capture C] [--method motion|vlm] [--device D] [--vlm-...]``."""
    out = Path(args.out)
    vlm = None
    if args.method == "vlm":
        from .vlm.client import vlm_config
        vlm = vlm_config(args.vlm_endpoint, args.vlm_model, args.vlm_timeout)
    layout.require(out, layout.SPLAT, "reconstruct")
    capture_path = layout.capture_of(out, args.capture)
    capture = load_capture(capture_path)
    check_inputs(capture, out, args.method, vlm)
    articulation = propose_stage(capture, out, progress, method=args.method, device=args.device,
                                 vlm=vlm)
    if args.capture is not None:
        layout.update_report(out, capture=str(Path(capture_path).resolve()))
    for j in articulation.joints:
        unit = "rad" if j.type == "revolute" else "m"
        progress.log(f"{j.name}: {j.type} axis {np.round(j.axis, 3).tolist()} origin "
                     f"{np.round(j.origin, 3).tolist()} limit [{j.limit[0]:.3f}, {j.limit[1]:.3f}] "
                     f"{unit} confidence {j.confidence}")
    progress.finished(proposals=str(out / layout.PROPOSALS))
    return 0
