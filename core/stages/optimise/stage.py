"""``artgs optimise OUT``: joints, states and part assignment fitted to the interaction frames.

Reads OUT/splat.ply, OUT/proposals.json (any source, user-edited or not) and the capture's
interaction frames; writes OUT/part_labels.npy (the part of every Gaussian of splat.ply: 0 = base,
k = the k-th joint of articulation.json) and OUT/articulation.json (``"optimised": true``; per joint
``states`` per time, ``limit`` = the observed range, ``residual``, ``confidence`` and the evidence
behind them). Nothing is written before the end: a cancel or a failure leaves OUT as it was.

Steps (each fit is :func:`.fit.fit`):
1. start from the proposals: part of each Gaussian from the joints' ``extent`` boxes; states
   from the proposal or, where it has none, a search per time; each part trimmed to the
   Gaussians where the frames show it changing (:func:`.seen.trim_parts`);
2. fit axes, points and states with those parts (coarse-to-fine, graduated robustness); with
   the robot's tool path, the parts it opened (:func:`.missed.add_tool_parts`);
3. one joint for parts that move alike (:func:`.hypotheses.merge_duplicates`; again after
   the type choice and before the last steps), type by evidence, then spurious parts
   (:mod:`.hypotheses`);
4. fit joints, states and soft skinning together; harden the assignment (argmax), fine-tune;
   runs of the tool path that a joint now carries held by it (:func:`.missed.hold_carried`);
   each Gaussian to the part the frames' depth supports, kept if it lowers the loss
   (:mod:`.assign`); missed parts where the frames change and the model does not
   (:func:`.missed.add_missed`),
   then, if any was added, step 4's fits again (at half length), the spurious-part test and,
   for the added parts, the into-body test (:func:`.missed.drop_into_body`);
   duplicates merged once more, then every joint tested once more against its part at rest,
   gone, and moving with each other joint (:func:`.hypotheses.remove_spurious`, ``join``),
   after the last fits: the earlier tests ran before them;
   a joint whose start explains its frames better than the fit keeps the start's axis and point;
   each hinge tried on its part's edges (:mod:`.edge_hinge`);
   each joint refined last on the frames' depth (:mod:`.depth_fit`), then along the body's box
   (:mod:`.square`);
5. steps 1-4 run once per route (:data:`ROUTES`), side by side where the threads allow
   (:mod:`.routes`); the route whose final model has the lower image loss is kept;
6. report per joint residual, observed range and confidence.
"""

from __future__ import annotations

import io
import math
import time
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path
from typing import Any, Iterator

import numpy as np
import torch

from ...geometry.parts import assign_parts, handle_point
from ...model import atomic, layout, registry
from ...model.capture import TRANSFORMS, Capture
from ...model.errors import InputError, NothingFound
from ...model.joints import (Articulation, Joint, opening_approach, read_articulation,
                             write_articulation)
from ...model.ply import read_ply
from ...model.progress import Progress
from ...model.registry import OptimiseOptions
from ...render.device import resolve_device
from . import parallel
from .depth_fit import refine_on_depth
from .fit import FitConfig, first_coarse_level, fit, search_states
from .frames import FrameSet, interaction_frames
from ..robot_twin import tool_path
from .occluders import known_occluders
from .square import square_to_body
from .edge_hinge import edge_hinges
from .routes import run_routes
from .plausible import HIDDEN_SHARE, OpenSpace, into_body, little_motion, open_space
from .model import ArticulatedSplat, Splat
from .kinematics import REVOLUTE

STAGE = "optimise"
USER_TRUST = 1.0     # prior strength of ``source: user`` joints (others 0)


def object_size(means: np.ndarray) -> float:
    """Diagonal of the splat's 1–99 % percentile box (metres)."""
    lo, hi = np.percentile(means, 1, axis=0), np.percentile(means, 99, axis=0)
    return float(max(np.linalg.norm(hi - lo), 1e-3))


def is_locked(j: Joint) -> bool:
    """A joint the user locked (``"locked": true``): its type, axis and point stay fixed."""
    return bool(j.extra.get("locked", False))


def check(capture: Capture, options: OptimiseOptions) -> None:
    """Refuse a capture or options the optimisation cannot serve, before any work."""
    if options.iterations < 1:
        raise InputError("--iterations", f"must be positive, not {options.iterations}")
    frames = [f for f in capture.interaction if f.time is not None]
    if not frames:
        raise InputError(Path(capture.root) / TRANSFORMS, "optimisation needs interaction frames "
                         "(\"phase\": \"interaction\" with an integer \"time\")", field="frames")
    missing = [f for f in frames if f.depth is None]
    if missing:
        raise InputError(Path(capture.root) / TRANSFORMS, "optimisation needs depth on every "
                         "interaction frame", frame=missing[0].index, field="depth_file_path")


class Runner:
    """Shared state of one optimisation: frames, model, config, progress."""

    def __init__(self, model: ArticulatedSplat, frames: FrameSet, cfg: FitConfig,
                 progress: Progress, options: OptimiseOptions, trust: torch.Tensor) -> None:
        self.model, self.frames, self.cfg = model, frames, cfg
        self.progress, self.options, self.trust = progress, options, trust
        self.rng = np.random.default_rng(options.seed)
        self.phase = ""
        #: this route's part of the stage's progress (start, width) and its name in messages
        self.span = (0.0, 1.0)
        self.route = ""
        self.done = 0.0
        self.share = 0.0
        #: per joint name, the proposal's joint of the other type (hypotheses.alternative_of)
        self.alternatives: dict[str, list] = {}
        #: where the static views measured the body (plausible.open_space), None without depth
        self.space: OpenSpace | None = None
        #: the helper process (core/stages/optimise/parallel.py)
        self.helper = None
        self.processes = 1     # 2 once the helper worked
        #: joints the last spurious-part test kept only as the only joint (hypotheses.remove_spurious)
        self.weak: set[str] = set()

    def run_fit(self, steps: int, phase: str, share: float, **kw: Any) -> float:
        """A fit that reports progress for ``share`` of the stage."""
        self.phase = phase

        def tick(step: int, loss: float) -> None:
            if step % 10 == 0 or step == steps - 1:
                start, width = self.span
                route = f"route {self.route}, " if self.route else ""
                fraction = start + width * (self.done + share * (step + 1) / steps)
                self.progress.update(STAGE, fraction, f"{route}{phase}: step {step + 1}/{steps}",
                                     loss=loss, **self.joint_figures())
            else:
                self.progress.check_cancel()

        with parallel.threads(torch.get_num_threads()):   # as they were, after the halves
            loss = fit(self.model, self.frames, self.cfg, steps, self.rng, prior=self.trust,
                       tick=tick, other=parallel.other(self), **kw)
        self.done += share
        return loss

    def add_joint(self, kind: str, axis: np.ndarray, origin: np.ndarray,
                  members: np.ndarray) -> int:
        """A new joint ``part_<n>`` (the first free name) whose part is the Gaussians
        ``members``, untrusted (:meth:`.model.ArticulatedSplat.add`); returns its index."""
        name = f"part_{len(self.model.names) + 1}"
        while name in self.model.names:
            name += "_"
        self.trust = torch.cat([self.trust, torch.zeros(1, device=self.trust.device)])
        return self.model.add(name, kind, axis, origin, members)

    def drop_joint(self, k: int) -> None:
        """Remove joint ``k`` and its trust; its Gaussians join the base
        (:meth:`.model.ArticulatedSplat.drop`)."""
        self.model.drop(k)
        self.trust = torch.cat([self.trust[:k], self.trust[k + 1:]])

    def evaluate(self, level: int = 0, subset: list[int] | None = None) -> np.ndarray:
        """:func:`.fit.evaluate` of the model, its frames split with the helper process when
        there is one (:func:`.parallel.evaluate`)."""
        return parallel.evaluate(self, level, subset)

    def joint_figures(self) -> dict[str, Any]:
        """Current joints (streamed to the add-on so bones can move live)."""
        m = self.model
        axes, origins = m.joint_axes().detach().cpu().numpy(), m.joint_origins().detach().cpu().numpy()
        return {"joints": [{"name": n, "type": t, "axis": [round(float(x), 5) for x in a],
                            "origin": [round(float(x), 5) for x in o]}
                           for n, t, a, o in zip(m.names, m.types, axes, origins)]}


@contextmanager
def deterministic() -> Iterator[None]:
    """torch's deterministic kernels for the duration (restored after). Without them the soft
    skinning's kNN gather accumulates its gradient in a varying order: logits 3e-8 apart after
    40 steps, which later type and part decisions with margins of 1e-5 turned into joints 8 deg
    apart between two runs on the same inputs. ``warn_only``: an op with no deterministic
    kernel (on some GPUs) warns instead of failing the stage."""
    before = torch.are_deterministic_algorithms_enabled()
    torch.use_deterministic_algorithms(True, warn_only=True)
    try:
        yield
    finally:
        torch.use_deterministic_algorithms(before)


def optimise(out: str | Path, capture: Capture, progress: Progress,
             options: OptimiseOptions | None = None,
             config: FitConfig | None = None) -> dict[str, Any]:
    """Optimise the proposals of ``out`` against ``capture``; writes the outputs (module doc).
    The same inputs and seed give the same outputs (:func:`deterministic`)."""
    with deterministic():
        return _optimise(out, capture, progress, options, config)


#: The optimisation's routes: (name, changes to the FitConfig). Each runs the whole
#: optimisation from the proposals; the route whose final model explains the interaction frames
#: best (image loss, full resolution, every frame) is kept. "half" scores hypotheses and searches
#: states at half resolution; "fine" does so at full resolution for parts under 64 pixels at
#: half, and runs the first fit's coarse phase no coarser than the smallest part shows (a
#: realistic washing machine's door, 5x5 pixels at the coarsest level, was fitted there to
#: 60-70 % of its opening). Neither route is better on every capture; their final losses pick
#: the better on most (docs/benchmark-log.md, "Two routes").
ROUTES: tuple[tuple[str, dict[str, Any]], ...] = (("half", {}), ("fine", {"fine_parts": True}))


@dataclass
class Route:
    """One route's finished optimisation: its model and config, the final loss of every frame,
    what its steps report, and how many processes it used (2 with a helper)."""

    name: str
    model: ArticulatedSplat
    cfg: FitConfig
    losses: np.ndarray
    evidence: dict[str, dict[str, Any]]
    figures: dict[str, Any]
    processes: int

    @property
    def loss(self) -> float:
        return float(self.losses.mean())


def _optimise(out: Path | str, capture: Capture, progress: Progress,
              options: OptimiseOptions | None, config: FitConfig | None) -> dict[str, Any]:
    options = options or OptimiseOptions()
    cfg = config or FitConfig()
    out = Path(out)
    check(capture, options)
    arrays = read_ply(registry.require(out, layout.SPLAT))
    proposals = read_articulation(registry.require(out, layout.PROPOSALS))
    if not proposals.joints and not options.parts:
        raise InputError(out / layout.PROPOSALS, "holds no joints, and --no-parts keeps the "
                         "optimisation from adding the parts the frames show moving",
                         field="joints")
    t0 = time.perf_counter()
    dev = resolve_device(options.device)
    size = object_size(arrays.means)
    space = open_space(capture.static, size)
    frames = interaction_frames(capture, dev, occluders=known_occluders(capture, dev,
                                                                       options.robot_twin, space),
                                mask_pixels=cfg.mask_pixels)
    if options.robot_twin:
        frames.tool = tool_path(capture)
    joints = list(proposals.joints)
    progress.log(f"optimise: {len(joints)} joint(s), {len(arrays.means)} Gaussians, "
                 f"{len(frames.time_index)} frames at {len(frames.times)} times, "
                 f"size {size:.3f} m")
    routes = [(name, replace(cfg, **changes))
              for name, changes in (ROUTES if options.routes else ROUTES[:1])]
    work = partial(_route, arrays=arrays, joints=joints, frames=frames, space=space,
                   capture=capture, options=options, dev=dev, size=size)
    done, at_once = run_routes(work, routes, progress,
                               concurrent=options.helper and dev.type == "cpu")
    if len(routes) > 1:
        for r in done:
            progress.log(f"route {r.name}: {r.model.k} joint(s), final loss {r.loss:.5f}")
    best = min(done, key=lambda r: r.loss)
    model, losses = best.model, best.losses
    result = export(model, frames, joints, losses, best.evidence, best.cfg, space,
                    {key: best.figures[key] for key in ("edge", "square", "depth_fit")})
    if not result:
        raise NothingFound(f"no moving part found: no proposed joint explains the interaction "
                           f"frames and the frames show no part moving that the model does not "
                           f"explain; {layout.ARTICULATION} is left as it was. Check that the "
                           f"interaction frames show a part moving, or add one by hand "
                           f"(Bones panel: Add Joint, Save Joints) and optimise again")
    f = best.figures
    meta = {k: v for k, v in proposals.meta.items() if k != "optimised"}
    articulation = Articulation(result, {**meta, "optimised": True,
                                         "loss": best.loss, "route": best.name,
                                         "removed": f["removed"], "merged": f["merged"],
                                         "added": f["added"], "rejected": f["rejected"]})
    figures = {"joints": len(result), "loss": best.loss,
               "route": best.name, "routes": {r.name: round(r.loss, 6) for r in done},
               "removed": f["removed"], "merged": f["merged"],
               "trimmed": f["trimmed"], "assigned": f["assigned"],
               "cameras": camera_corrections(model),
               "kept_start": f["kept_start"], "edged": f["edge"], "squared": f["square"],
               "added": f["added"],
               "rejected": f["rejected"],
               "depth": f["depth_fit"],
               "types": [j.type for j in result],
               "processes": at_once if at_once > 1 else best.processes,
               "seconds": round(time.perf_counter() - t0, 2)}
    write_labels(out / layout.PART_LABELS, model.labels())
    write_articulation(out / layout.ARTICULATION, articulation)
    return figures


def _route(name: str, cfg: FitConfig, progress: Progress, closing: ExitStack,
           span: tuple[float, float], label: str, *, arrays: Any, joints: list[Joint],
           frames: FrameSet, space: OpenSpace | None, capture: Capture,
           options: OptimiseOptions, dev: torch.device, size: float) -> Route:
    """One route of the optimisation (:data:`ROUTES`): steps 1-4 of the module doc from the
    proposals ``joints``, with ``cfg``; its progress reported in ``span`` (start, width) of the
    stage, its messages named by ``label`` (none: empty); its helper ended by ``closing``
    (:func:`.routes.run_routes` runs it here or in a process of its own)."""
    from . import assign, hypotheses, missed, seen

    torch.manual_seed(options.seed)
    splat = Splat.from_arrays(arrays, dev)
    labels = assign_parts(arrays.means, joints)
    model = ArticulatedSplat(splat, joints, frames.times, labels, size,
                             [is_locked(j) for j in joints])
    trust = torch.tensor([USER_TRUST if j.source == "user" else 0.0 for j in joints],
                         dtype=torch.float32, device=dev)
    model.shading = cfg.shading
    if options.cameras:
        model.use_cameras(frames.camera)
    run = Runner(model, frames, cfg, progress, options, trust)
    run.space = space
    run.span = span
    run.route = label
    run.alternatives = {j.name: hypotheses.alternative_of(j, frames.times) for j in joints}
    if options.types and joints:
        parallel.start(run)
        closing.callback(parallel.stop, run)
    n = options.iterations

    model.hard = torch.as_tensor(labels, device=dev)       # the boxes' parts, until step 4
    user = {j.name for j in joints if j.source == "user"}
    start = (model.axes.cpu().numpy().copy(), model.origins.cpu().numpy().copy(),
             list(model.types), list(model.names))
    for k, j in enumerate(joints):
        if not j.states:
            search_states(model, frames, k, cfg, hypotheses.state_candidates(model, k))
    trimmed = seen.trim_parts(run, locked=model.locked.tolist()) if options.parts else {}
    run.run_fit(n, "joints", 0.25, coarse=cfg.coarse,
                coarse_level=first_coarse_level(model, frames, cfg))
    # the robot's record of what it opened is evidence as a user's joint is: trusted alike
    tooled = missed.add_tool_parts(run, share=0.0) if options.parts else []
    for name in tooled:
        user.add(name)
        run.trust[model.names.index(name)] = USER_TRUST

    def fixed() -> list[bool]:
        """Per current joint: a trusted user joint or a locked one."""
        return [name in user or bool(lk) for name, lk in zip(model.names, model.locked.tolist())]

    merged: list[list[str]] = []
    if options.parts and model.k:   # pieces fitted alike before their types are chosen ...
        merged = hypotheses.merge_duplicates(run, fixed())
    evidence: dict[str, dict[str, Any]] = {}
    if options.types and model.k:
        evidence = hypotheses.select_types(run, share=0.35, fixed=fixed())
    removed: list[str] = []
    if options.parts and model.k:   # ... and after (a piece proposed as a slide, now a hinge)
        removed = hypotheses.remove_spurious(run, locked=model.locked.tolist())
        merged += hypotheses.merge_duplicates(run, fixed())
    run.done = 0.6
    refine(run, n, share=0.24)
    if options.parts:     # runs of the tool path that the fits have brought a joint onto
        missed.hold_carried(run)
    assigned = assign.reassign(run, max(n // 4, 1), 0.04, model.locked.tolist()) \
        if options.assign and model.k else {}
    added: list[str] = []
    rejected: list[str] = []      # invented, then dropped by the final tests
    if options.parts:
        added = missed.add_missed(run, share=0.05)
    if added and options.types:   # the new parts' types by the same evidence
        evidence.update(hypotheses.select_types(run, share=0.0,
                                                fixed=[name not in added for name in model.names]))
    added = [a for a in tooled if a in model.names and a not in start[3]] + added
    if added:                     # the new parts refined with the others, then tested again
        refine(run, n // 2, share=0.07)
        again = hypotheses.remove_spurious(run, locked=model.locked.tolist())
        again += missed.drop_into_body(run, [a for a in added if a not in again])
        sort_out(again, added, removed, rejected)
    if options.parts and model.k:   # ... and once more, fitted with their final parts
        merged += hypotheses.merge_duplicates(run, fixed())
        # each joint against the others after the last fits: a piece their joint explains
        # as well joins it, a motion no better than rest or gone is dropped
        sort_out(hypotheses.remove_spurious(run, locked=model.locked.tolist(), join=True),
                 added, removed, rejected)
    kept_start = hypotheses.keep_better_start(run, *start) if model.k else []
    edged = edge_hinges(run, fixed(), max(n // 4, 1)) if options.edges and model.k else {}
    depth = refine_on_depth(run, capture, arrays) if options.depth and model.k else {}
    # last: the body's box breaks the ties the image loss leaves, after every step that
    # decides by that loss (a depth refinement after it turned a squared safe door 4.4 deg away)
    squared = square_to_body(run, capture, fixed(), max(n // 6, 1)) \
        if options.square and model.k else {}
    losses = run.evaluate()
    for weak in run.weak & set(model.names):
        evidence.setdefault(weak, {})["weak"] = True
    return Route(name, model, cfg, losses, evidence,
                 {"edge": edged, "square": squared, "depth_fit": depth, "removed": removed,
                  "merged": merged, "added": added, "rejected": rejected, "trimmed": trimmed,
                  "assigned": assigned, "kept_start": kept_start}, run.processes)


def sort_out(dropped: list[str], added: list[str], removed: list[str],
             rejected: list[str]) -> None:
    """Joints ``dropped`` by a test: those the optimisation invented (``added``) leave it for
    ``rejected``, the others go to ``removed`` (the lists are changed in place)."""
    removed += [name for name in dropped if name not in added]
    rejected += [name for name in dropped if name in added]
    added[:] = [name for name in added if name not in dropped]


def refine(run: Runner, n: int, share: float) -> None:
    """Joints, states and soft skinning together (``n/2`` steps, from the current parts), then
    the assignment hardened (argmax) and a fine-tune (``n/4`` steps) at lower rates."""
    run.model.hard = None
    run.run_fit(max(n // 2, 1), "joints and skinning", share * 0.7, lr_scale=0.3)
    run.model.harden()
    run.run_fit(max(n // 4, 1), "hardened", share * 0.3, lr_scale=0.1)


def camera_corrections(model: ArticulatedSplat) -> list[dict[str, float]]:
    """The learnt correction of each fixed interaction camera: rotation (degrees) and
    translation (cm); empty when the cameras were taken as registered."""
    if not model.refine_cameras:
        return []
    c = model.cameras.detach().cpu().numpy().astype(float)
    return [{"rotation_deg": round(math.degrees(float(np.linalg.norm(r[:3]))), 4),
             "translation_cm": round(100 * model.size * float(np.linalg.norm(r[3:])), 4)}
            for r in c]


def write_labels(path: Path, labels: np.ndarray) -> None:
    """The part label of every Gaussian of splat.ply as an int32 .npy, atomically."""
    buf = io.BytesIO()
    np.save(buf, labels.astype(np.int32))
    atomic.write_bytes(path, buf.getvalue())


def export(model: ArticulatedSplat, frames: FrameSet, joints: list[Joint], losses: np.ndarray,
           evidence: dict[str, dict[str, Any]], cfg: FitConfig,
           space: OpenSpace | None, reports: dict[str, dict[str, dict[str, Any]]] | None = None
           ) -> list[Joint]:
    """The fitted joints with states, observed range as limit, residual and confidence.

    confidence = 1 / (1 + residual), times min(1, 0.5 + 5 × type margin) when both types were
    fitted (a 10 % lower loss than the other type counts as decisive), halved when the evidence
    is weak (the part displaced by under 5 % of its size, or under 50 Gaussians) or the
    part opens into the body (:func:`.plausible.into_body` in ``space``, the static views).
    ``reports``: per key, per joint the report of a late step (``edge``: :mod:`.edge_hinge`,
    ``square``: :mod:`.square`, ``depth_fit``: :mod:`.depth_fit`), kept in the joint's
    ``extra[key]``.
    """
    labels = model.labels()
    means = model.splat.means.cpu().numpy()
    axes = model.joint_axes().detach().cpu().numpy()
    origins = model.joint_origins().detach().cpu().numpy()
    result = []
    by_name = {j.name: j for j in joints}
    for k, name in enumerate(model.names):
        src = by_name.get(name)
        kind = model.types[k]
        pts = means[labels == k + 1]
        centre = pts.mean(0) if len(pts) else origins[k]
        axis = axes[k]
        if kind == REVOLUTE:  # the point on the axis line nearest the part
            origin = origins[k] + ((centre - origins[k]) @ axis) * axis
        else:
            origin = centre
        states = model.joint_values(k)
        values = np.array(list(states.values()))
        if values[np.argmax(np.abs(values))] < 0:   # opening is positive: flip the axis
            axis, values = -axis, -values
            states = {t: -v for t, v in states.items()}
        lo, hi = float(min(0.0, values.min())), float(max(0.0, values.max()))
        moving = [i for i, ti in enumerate(frames.time_index)
                  if abs(states[frames.times[ti]]) > 0.1 * max(hi - lo, 1e-9)]
        residual = float(losses[moving].mean()) if moving else float(losses.mean())
        ev = evidence.get(name, {})
        warnings = []
        if little_motion(kind, hi - lo, pts, axis, origin):
            warnings.append("little motion seen")
        if len(pts) < 50:
            warnings.append("part has few Gaussians")
        if ev.get("weak"):
            warnings.append("the frames do not clearly show it moving (kept as the only joint): "
                            "check it, or remove it (Bones panel: Remove Joint)")
        inside = into_body(space, kind, axis, origin, values, pts)
        if inside > HIDDEN_SHARE:
            warnings.append(f"opens into the body ({100 * inside:.0f} % of its surface goes "
                            f"behind what the static views measured): check the joint's "
                            f"direction and line")
        margin = ev.get("margin")
        confidence = 1.0 / (1.0 + residual)
        if margin is not None:
            confidence *= min(1.0, 0.5 + 5.0 * max(margin, 0.0))
        if warnings:
            confidence *= 0.5
        handle = src.handle if handle_holds(src, kind, pts, model.size) else \
            grasp(model, k, pts, axis, origin, means)
        approach = opening_approach(kind, axis, origin, handle["point"], hi) if handle else None
        if approach is not None:
            handle = {**handle, "approach": [float(x) for x in approach]}
        extra = {key: v for key, v in src.extra.items() if key != "alternative"} if src else {}
        extra.update(residual=residual, observed_range=[lo, hi], gaussians=int(len(pts)),
                     evidence=ev, warnings=warnings, into_body=round(inside, 4))
        extra.update({key: r[name] for key, r in (reports or {}).items() if name in r})
        held = model.held_residual(k)
        if held is not None:       # how closely the joint follows the robot's tool (m)
            extra["tool_path_rms"] = round(held, 6)
        result.append(Joint(
            name=name, type=kind, axis=axis, origin=origin, limit=(lo, hi),
            parent=src.parent if src else "base", child=src.child if src else f"{name}_link",
            states=states, source=src.source if src else "optimise",
            confidence=round(float(confidence), 4), bbox=src.bbox if src else None,
            handle=handle, extent=part_box(pts) if len(pts) else
            (src.extent if src else None), extra=extra))
    return result


def handle_holds(src: Joint | None, kind: str, pts: np.ndarray, size: float) -> bool:
    """Whether the start's handle still serves the fitted joint: the start had one, of the same
    type (a slide's front handle is no grip on a hinge's free edge), and it lies on the fitted
    part (a Gaussian of the part within 3 % of the object's size: the part the handle was
    drawn on may have been another one, or trimmed away)."""
    if src is None or not src.handle or src.type != kind or not len(pts):
        return False
    point = np.asarray(src.handle["point"], float)
    return bool(np.linalg.norm(pts - point, axis=1).min() <= 0.03 * size)


def grasp(model: ArticulatedSplat, k: int, pts: np.ndarray, axis: np.ndarray,
          origin: np.ndarray, means: np.ndarray) -> dict[str, Any] | None:
    """A handle for a joint whose start gave none that holds (:func:`handle_holds`; a part the
    optimisation added, a type changed): the grasp point of :func:`handle_point` on the part's
    front (its mean normal, turned away from the object's centre), approached against that
    normal (:func:`export` then turns every handle's approach against its opening motion, which
    a part's mixed normals can miss by 90 degrees). None for a part without Gaussians."""
    from .hypotheses import part_normal
    if len(pts) < 3:
        return None
    n = part_normal(model, k)
    if (pts.mean(0) - means.mean(0)) @ n < 0:
        n = -n
    joint = Joint(name=model.names[k], type=model.types[k], axis=axis, origin=origin)
    return {"point": [float(x) for x in handle_point(pts, joint, n)],
            "approach": [float(x) for x in -n]}


def part_box(points: np.ndarray) -> dict[str, Any]:
    """Oriented box (PCA axes) of a part's points, 1–99 % percentiles."""
    c = points.mean(0)
    _, _, vt = np.linalg.svd(points - c, full_matrices=False) if len(points) > 2 else \
        (None, None, np.eye(3))
    local = (points - c) @ vt.T
    lo, hi = np.percentile(local, 1, axis=0), np.percentile(local, 99, axis=0)
    centre = c + ((lo + hi) / 2) @ vt
    return {"center": [float(v) for v in centre], "axes": [[float(v) for v in r] for r in vt],
            "half_size": [float(v) for v in (hi - lo) / 2]}


def run(out: Path, capture: Capture | None, options: OptimiseOptions,
        progress: Progress) -> dict[str, Any]:
    """The optimise stage (registry entry): OUT/articulation.json, OUT/part_labels.npy."""
    if capture is None:
        raise InputError(Path(out) / layout.REPORT, "optimisation needs the capture",
                         field="capture")
    return optimise(out, capture, progress, options)
