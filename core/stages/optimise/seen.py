"""What the frames show moving and staying put, Gaussian by Gaussian, against the closed render.

A pixel whose measurement differs from its camera's closed state (:func:`.changes.frame_changes`)
has changed; a Gaussian in front in the closed render at such a pixel was there and has moved.
Used to trim a proposal's box to what moves (:func:`trim_parts`), to draw hypotheses from the
Gaussians seen moving (:func:`seen_moving`) and to find missed parts (:func:`unexplained`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from .model import ArticulatedSplat, restore, snapshot


@torch.no_grad()
def seen_static(model: ArticulatedSplat, frames, cfg, k: int, pixels: float = 2.0) -> np.ndarray:
    """Gaussians of joint ``k``'s part that the frames show staying put: in front in the closed
    render, moved by the joint by ``pixels`` or more on the image at a time, yet their pixel is
    unchanged from the camera's closed state (:func:`.changes.frame_changes`) at two or more
    such times and never changed. Gaussians no camera sees give no evidence and are not
    listed. Bool (N,)."""
    means = model.splat.means
    part = torch.as_tensor(model.labels() == k + 1, device=means.device)
    still = torch.zeros(model.splat.n, dtype=torch.long, device=means.device)
    moved = torch.zeros(model.splat.n, dtype=torch.bool, device=means.device)
    for ti, v, _, change, (px, py), front, _ in closed_views(model, frames, cfg):
        (qx, qy), _, _ = project(v, model.posed(ti)[0])
        shift = ((qx - px) ** 2 + (qy - py) ** 2).float().sqrt() >= pixels
        here = change[py, px]
        still += (part & front & shift & ~here).long()
        moved |= part & front & here
    return ((still >= 2) & ~moved).cpu().numpy()

def closed_views(model: ArticulatedSplat, frames, cfg):
    """Per frame that has a change map (:func:`.changes.frame_changes`): its time index, view,
    its camera's closed render, the change map, every Gaussian's pixel (column, row) and whether
    the Gaussian is in front in the closed render: widely (within the splat's own spread about
    its surfaces, :func:`layer_spread`, plus the surface's depth step to the next pixel,
    :func:`surface_slope`: any evidence that a part's Gaussian stays put) and narrowly (within
    the depth scale of the loss: the surface itself, whose change marks a missed part)."""
    from .changes import frame_changes
    changed = frame_changes(frames)
    means = model.splat.means
    tol = cfg.sigma_depth * 0.01 * model.size
    closed: dict[int, Any] = {}
    for i, ti in enumerate(frames.time_index):
        if i not in changed:
            continue
        v = frames.levels[0][i]
        cam = frames.camera[i]
        if cam not in closed:
            closed[cam] = model.render(v, frames.times.index(0), cfg.backend)
        r0 = closed[cam]
        (px, py), z, inside = project(v, means)
        gap = z - r0.depth[py, px]
        band = max(tol, 3 * layer_spread(gap[inside & (gap < 0)])) + surface_slope(r0.depth)
        yield ti, v, r0, changed[i], (px, py), inside & (gap.abs() < band[py, px]), \
            inside & (gap.abs() < tol)

def project(v, pts: torch.Tensor) -> tuple[tuple[torch.Tensor, torch.Tensor], torch.Tensor,
                                            torch.Tensor]:
    """Pixel (column, row) of world points in view ``v`` (clamped into the image), their depth,
    and whether they fall inside the image in front of the camera."""
    cam = pts @ v.w2c[:3, :3].T + v.w2c[:3, 3]
    z = cam[:, 2]
    uv = cam[:, :2] / z.clamp_min(1e-6)[:, None] * v.K[[0, 1], [0, 1]] + v.K[:2, 2]
    px, py = uv[:, 0].floor().long(), uv[:, 1].floor().long()
    inside = (z > 0) & (px >= 0) & (py >= 0) & (px < v.width) & (py < v.height)
    return (px.clamp(0, v.width - 1), py.clamp(0, v.height - 1)), z, inside

def seen_moving(model: ArticulatedSplat, frames, cfg, k: int, share: float = 0.1
                ) -> np.ndarray | None:
    """Gaussians of joint ``k``'s part where the frames show a change that the model with this
    joint at rest does not (:func:`unexplained`): the part's Gaussians seen moving, the ones to
    draw its hypotheses from (a part's box also holds what no camera sees). None when fewer
    than ``share`` of the part (no evidence)."""
    part = model.labels() == k + 1
    snap = snapshot(model)
    with torch.no_grad():
        model.states = model.states.clone()
        model.states[k] = 0.0
    core = unexplained(model, frames, cfg, part).any(0) & part
    restore(model, snap)
    return core if core.sum() >= max(10, share * part.sum()) else None

def trim_parts(run, locked: list[bool]) -> dict[str, int]:
    """Each unlocked joint's part (its proposal's box) gives to the base the Gaussians the frames
    show staying put where the joint would move them (:func:`seen_static`): a box drawn around
    a door also holds the cabinet's front beside it, and hypotheses made from such a part hinge
    on the wrong edges. Gaussians no camera sees stay. The soft skinning later gives back to a
    part what moves with it. Returns per joint the Gaussians moved to the base."""
    model, frames, cfg = run.model, run.frames, run.cfg
    moved: dict[str, int] = {}
    for k in range(model.k):
        if locked[k]:
            continue
        part = model.labels() == k + 1
        drop = seen_static(model, frames, cfg, k) & part
        if not drop.any() or drop.sum() > 0.9 * part.sum():   # nothing, or the joint is wrong
            continue
        model.reassign(drop, 0)
        moved[model.names[k]] = int(drop.sum())
        run.progress.log(f"{model.names[k]}: {int(drop.sum())} of {int(part.sum())} Gaussians of "
                         f"its box stay put in the frames; given to the base")
    return moved

def surface_slope(depth: torch.Tensor) -> torch.Tensor:
    """Per pixel, the largest depth step to a 4-neighbour where both are rendered (0 = nothing):
    how deep a surface seen at a grazing angle reaches within one pixel."""
    d = torch.nn.functional.pad(depth[None, None], (1, 1, 1, 1), mode="replicate")[0, 0]
    c = d[1:-1, 1:-1]
    steps = [(n - c).abs() * ((n > 0) & (c > 0)) for n in (d[:-2, 1:-1], d[2:, 1:-1],
                                                              d[1:-1, :-2], d[1:-1, 2:])]
    return torch.stack(steps).amax(0)

def layer_spread(ahead: torch.Tensor) -> float:
    """Spread (one sigma, m) of a splat's Gaussians about the surface it renders, from the
    distances by which Gaussians lie in front of the rendered depth (``ahead``, negative; nothing
    but the front layer itself is in front of it); a splat made from noisy depth is centimetres
    thick. 0 without any."""
    return 1.4826 * float(ahead.abs().median()) if len(ahead) else 0.0

@torch.no_grad()
def unexplained(model: ArticulatedSplat, frames, cfg, candidates: np.ndarray | None = None
                ) -> np.ndarray:
    """Base Gaussians (or ``candidates``, bool (N,)) where the frames show a change the model
    does not, at two consecutive times: bool (T-1, N), row ``t`` for times ``t`` and ``t+1``.

    A change is a pixel whose measurement differs from its camera's closed state
    (:func:`.changes.frame_changes`); the model explains it where its own render at that time
    differs from its closed render there (alpha, depth or colour). A base Gaussian is hit when
    it is in front in the closed render at such a pixel (:func:`closed_views`): something that
    was there has moved.
    """
    means = model.splat.means
    base = torch.as_tensor(model.labels() == 0 if candidates is None else candidates,
                           device=means.device)
    tol = cfg.sigma_depth * 0.01 * model.size
    hits = torch.zeros(len(frames.times), model.splat.n, dtype=torch.bool, device=means.device)
    for ti, v, r0, change, (px, py), _, front in closed_views(model, frames, cfg):
        r = model.render(v, ti, cfg.backend)
        moved = ((r.alpha - r0.alpha).abs() > 0.5) | ((r.depth - r0.depth).abs() > tol) | \
            ((r.rgb - r0.rgb).abs().mean(-1) > 0.1)
        hits[ti] |= base & front & (change & ~moved)[py, px]
    return (hits[1:] & hits[:-1]).cpu().numpy()
