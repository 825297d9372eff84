"""``artgs propose``: initial joints from motion (default) or a VLM -> OUT/proposals.json.

Reads OUT/splat.ply (from ``artgs reconstruct``) and the capture; writes OUT/proposals.json
atomically (articulation.json schema plus per-joint ``source``, ``confidence``, ``bbox``,
``handle``, ``extent``; top-level ``source`` = the method and the route's ``meta``). Bad input is refused before any work; on failure nothing in OUT
is touched.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ...model import layout
from ...model.capture import Capture
from ...model.transforms import TRANSFORMS
from ...model.errors import InputError, NothingFound
from ...model.joints import Articulation, write_articulation
from ...model.ply import read_ply
from ...model.progress import Progress
from ...model.registry import METHODS, ProposeOptions, require

_NOTHING_FOUND_HINT = {
    "motion": "Check that the interaction frames show a part moving between times.",
    "vlm": "The VLM's answers held no usable joint; try another model or --method motion.",
}


def check(capture: Capture, options: ProposeOptions) -> None:
    """Refuse a method the capture or the configuration cannot serve (before any work)."""
    method = options.method
    if method not in METHODS:
        raise InputError("--method", f"must be one of {METHODS}, not {method!r}")
    if method == "vlm":
        vlm_of(options)   # raises, naming $ARTGS_VLM_ENDPOINT / $ARTGS_VLM_MODEL
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


def vlm_of(options: ProposeOptions) -> Any:
    """The VLM configuration of ``options`` (environment variables fill what is not given)."""
    from .vlm.client import vlm_config
    return vlm_config(options.vlm_endpoint, options.vlm_model, options.vlm_timeout)


def propose(capture: Capture, out: str | Path, progress: Progress,
            options: ProposeOptions | None = None) -> Articulation:
    """Propose joints for ``capture`` and write OUT/proposals.json (refuses bad input first)."""
    options = options or ProposeOptions()
    out = Path(out)
    check(capture, options)
    arrays = read_ply(require(out, layout.SPLAT))
    if options.method == "motion":
        from .motion.route import propose_motion
        opacity = 1.0 / (1.0 + np.exp(-np.asarray(arrays.opacity_logits, float)))
        joints, meta = propose_motion(capture, arrays.means, opacity,
                                      lambda camera: splat_depth(arrays, camera, options.device),
                                      progress, robot_depth=twin_depth(
                                          capture, options.robot_twin, options.device))
    else:
        from ...render.gaussians import Gaussians
        from .vlm.propose import propose_vlm
        joints, meta = propose_vlm(capture, Gaussians.from_arrays(arrays), progress,
                                   vlm_of(options), options.device)
    if not joints:
        kept = (f"{out / layout.PROPOSALS} is left as it was" if (out / layout.PROPOSALS).exists()
                else f"no {layout.PROPOSALS} written")
        seen = meta.get("nothing_seen", "")
        raise NothingFound(f"the {options.method} route found no joints; {kept}. "
                           + (f"{seen[0].upper()}{seen[1:]}. " if seen else "")
                           + _NOTHING_FOUND_HINT[options.method], reason=seen)
    articulation = Articulation(joints, {"source": options.method, **meta})
    write_articulation(out / layout.PROPOSALS, articulation)
    for j in joints:
        unit = "rad" if j.type == "revolute" else "m"
        progress.log(f"{j.name}: {j.type} axis {np.round(j.axis, 3).tolist()} origin "
                     f"{np.round(j.origin, 3).tolist()} limit [{j.limit[0]:.3f}, {j.limit[1]:.3f}] "
                     f"{unit} confidence {j.confidence}")
    return articulation


def run(out: Path, capture: Capture, options: ProposeOptions, progress: Progress) -> dict[str, Any]:
    """The propose stage (registry entry): OUT/proposals.json and its figures."""
    articulation = propose(capture, out, progress, options)
    return {"joints": len(articulation.joints), "method": options.method,
            "types": [j.type for j in articulation.joints]}


def no_joints(out: Path, method: str) -> Articulation:
    """Write OUT/proposals.json with no joints (``"found": "none"``): what a route that found
    nothing leaves for the optimisation, which may still add parts from the frames."""
    empty = Articulation([], {"source": method, "found": "none"})
    write_articulation(out / layout.PROPOSALS, empty)
    return empty


def none_proposed(out: Path, options: dict[str, Any], progress: Progress, reason: str = ""
                  ) -> dict[str, Any]:
    """``artgs run`` after the route found nothing: OUT/proposals.json with no joints, so the
    optimisation searches the interaction frames for parts that move (it adds them from what
    the frames show changing); a run whose optimisation cannot add parts (``--no-parts``) stops
    here instead, as ``artgs propose`` does. ``reason``: why the route saw nothing (logged)."""
    method = options["propose"].method
    why = f" ({reason})" if reason else ""
    if not options["optimise"].parts:
        raise NothingFound(f"the {method} route found no joints{why} and the optimisation may "
                           "not add parts (--no-parts); " + _NOTHING_FOUND_HINT[method],
                           reason=reason)
    no_joints(out, method)
    progress.log(f"propose: the {method} route found no joints{why}; {layout.PROPOSALS} holds "
                 "none and the optimisation searches the interaction frames for moving parts",
                 level="warning")
    return {"joints": 0, "method": method, "types": [], "found": "none"}


def twin_depth(capture: Capture, use_twin: bool, device: str):
    """The robot twin's depth per frame (core/stages/robot_twin.py), or None without a twin (or
    with ``use_twin`` off, the ablation)."""
    if not use_twin:
        return None
    from ...render.device import resolve_device
    from ..robot_twin import twin_depth_for_capture
    return twin_depth_for_capture(capture, resolve_device(device))


def splat_depth(arrays, camera, device: str) -> np.ndarray:
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
