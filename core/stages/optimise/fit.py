"""Fitting an :class:`ArticulatedSplat` to the interaction frames by differentiable rendering.

Each step renders every fixed camera at one random interaction time and descends
``image_loss`` (robust depth) + regularisers with Adam; the first ``coarse`` fraction of the steps
renders at the pyramid's coarsest level, which widens the basin (a wrong start still overlaps its
target at low resolution), the rest at full resolution. Only the joints in ``free`` move.

A step's frames are two halves (:func:`halves`) whose gradients are summed: the second half
can be rendered in another process (``other``, :mod:`.parallel`) with the same result.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
import torch

from ...train.adam import Adam
from ...train.losses import robust_image_loss
from .frames import FrameSet
from .model import ArticulatedSplat

#: ``other(params, level, widen, ids, n)``: starts :func:`half_grads` of a step's second half
#: of frames for the optimiser's ``params``; the function it returns waits for its result.
Other = Callable[[dict[str, torch.Tensor], int, float, list[int], int],
                 Callable[[], tuple[float, dict[str, torch.Tensor]]]]


@dataclass
class FitConfig:
    """Loss weights and learning rates of the articulation fit."""

    lambda_ssim: float = 0.2
    sigma_rgb: float = 0.1             # per-pixel error scales of the robust loss
    sigma_depth: float = 2.0           # x 1 % of the object size
    sigma_alpha: float = 0.5
    noise_sigmas: float = 3.0          # depth scale at least this many of the camera's noise
    exposure: bool = True              # colour compared after the frame's exposure gain
    mask_pixels: int = 2               # masks may be this many pixels too wide or narrow
    lambda_smooth: float = 0.05        # kNN smoothness of the skinning weights
    lambda_entropy: float = 0.02       # low entropy: parts are rigid
    lambda_temporal: float = 0.02      # squared state change between consecutive times
    lambda_prior: float = 0.0          # pull towards the start, x per-joint trust
    lambda_tool: float = 0.1           # the robot's tool path (model.held_loss)
    sigma_tool: float = 1.0            # its scale, x 1 % of the object size
    lever_tool: float = 0.2            # the lever of its hand turns, x the object size
    lr_axes: float = 0.01
    lr_origins: float = 0.004          # x object size
    lr_states: float = 0.01
    lr_logits: float = 0.1
    lr_cameras: float = 0.001          # camera corrections (rad; object sizes)
    lambda_camera: float = 1e-3        # their prior, in units of 1 degree and 1 % of the size
    shading: bool = True               # learn each part's brightness per time (model.shaded)
    lr_gains: float = 0.02             # log brightness
    lambda_gain: float = 0.01          # its prior (mean squared log brightness)
    lr_final: float = 0.05             # learning rates decay exponentially to this fraction
    widen: float = 10.0                # robust sigmas at the start of the coarse phase, x
    coarse: float = 0.4                # fraction of the first fit's steps at the coarsest level
    fine_parts: bool = False           # small parts scored at full resolution (score_level)
    backend: str = "auto"


def frame_loss(model: ArticulatedSplat, frames: FrameSet, level: int, i: int,
               cfg: FitConfig, widen: float = 1.0) -> torch.Tensor:
    """Image loss of frame ``i`` at pyramid ``level``; ``widen`` scales the robust loss's
    sigmas (large: L1-like, every pixel pulls)."""
    v = frames.levels[level][i]
    r = model.render(v, frames.time_index[i], cfg.backend)
    return robust_image_loss(r, v, depth_unit=0.01 * model.size, sigma_rgb=cfg.sigma_rgb * widen,
                             sigma_depth=cfg.sigma_depth * widen,
                             sigma_alpha=cfg.sigma_alpha * widen, lambda_ssim=cfg.lambda_ssim,
                             noise_sigmas=cfg.noise_sigmas * widen, exposure=cfg.exposure)


def frames_loss(model: ArticulatedSplat, frames: FrameSet, cfg: FitConfig, level: int,
                ids: list[int], n: int, widen: float = 1.0) -> torch.Tensor:
    """Sum of :func:`frame_loss` over frames ``ids``, divided by ``n``."""
    return sum(frame_loss(model, frames, level, i, cfg, widen) for i in ids) / max(n, 1)


def halves(ids: list[int]) -> tuple[list[int], list[int]]:
    """A step's frames as the half rendered with the regularisers and the half that can be
    rendered elsewhere (empty for a single frame)."""
    cut = len(ids) // 2 if len(ids) > 1 else len(ids)
    return ids[:cut], ids[cut:]


def half_grads(model: ArticulatedSplat, frames: FrameSet, cfg: FitConfig,
               params: dict[str, torch.Tensor], level: int, widen: float, ids: list[int],
               n: int) -> tuple[float, dict[str, torch.Tensor]]:
    """:func:`frames_loss` of frames ``ids`` with the model at ``params`` (leaves requiring
    gradients) and its gradient for each of them that it reaches."""
    model.load(params)
    loss = frames_loss(model, frames, cfg, level, ids, n, widen)
    names = list(params)
    grads = torch.autograd.grad(loss, [params[k] for k in names], allow_unused=True)
    return float(loss.detach()), {k: g for k, g in zip(names, grads) if g is not None}


def here(model: ArticulatedSplat, frames: FrameSet, cfg: FitConfig) -> Other:
    """:data:`Other` in this process (after this process's half: the same sums as elsewhere)."""
    def start(params, level, widen, ids, n):
        return lambda: half_grads(model, frames, cfg, params, level, widen, ids, n)
    return start


@torch.no_grad()
def evaluate(model: ArticulatedSplat, frames: FrameSet, cfg: FitConfig, level: int = 0,
             subset: list[int] | None = None) -> np.ndarray:
    """Image loss of every frame (or ``subset``) at ``level``, no regularisers."""
    ids = range(len(frames.time_index)) if subset is None else subset
    return np.array([float(frame_loss(model, frames, level, i, cfg)) for i in ids])


def fit(model: ArticulatedSplat, frames: FrameSet, cfg: FitConfig, steps: int,
        rng: np.random.Generator, *, free: list[bool] | None = None,
        times: list[int] | None = None, prior: torch.Tensor | None = None,
        tick: Callable[[int, float], None] | None = None, coarse: float = 0.0,
        lr_scale: float = 1.0, coarse_level: int | None = None, other: Other | None = None,
        hold: tuple[str, ...] = ()) -> float:
    """Run ``steps`` Adam steps; returns the mean loss of the last quarter of them.

    ``free``: joints that move (default all; the camera corrections, when learnt, move only
    then); ``times``: time indices to sample (default all); ``coarse_level``: the pyramid level
    of the coarse phase (default the coarsest);
    ``prior``: per-joint strength of the pull towards the start; ``tick(step, loss)`` is called
    every step (progress and cancel); ``coarse``: fraction of the steps at the coarsest level;
    ``lr_scale``: multiplies the learning rates (refining phases start below the first fit's
    rates: Adam's steps are about the learning rate whatever the gradient, so a converged
    solution restarted at full rate would wander off); ``other``: where each step's second half
    of frames is rendered (default here); ``hold``: parameters (of :meth:`ArticulatedSplat.params`,
    e.g. ``"axes"``) that stay as they are.
    """
    if steps <= 0 or model.k == 0:
        return float("nan")
    dev = model.axes.device
    size = model.size
    lrs = {"axes": cfg.lr_axes * lr_scale, "origins": cfg.lr_origins * size * lr_scale,
           "states": cfg.lr_states * lr_scale, "logits": cfg.lr_logits,
           "cameras": cfg.lr_cameras * lr_scale, "gains": cfg.lr_gains * lr_scale}
    params = model.params()
    opt = Adam(params, {k: lrs[k] for k in params}, eps=1e-12)
    model.load(opt.params)
    mask = torch.ones(model.k, device=dev) if free is None else \
        torch.tensor(free, dtype=torch.float32, device=dev)
    pool = time_pool(frames, times)
    coarse_level = len(frames.levels) - 1 if coarse_level is None else coarse_level
    n_coarse = int(coarse * steps)
    other = other or here(model, frames, cfg)
    losses: list[float] = []
    for step in range(steps):
        decay = cfg.lr_final ** (step / steps)
        for name in opt.lrs:
            opt.lrs[name] = lrs[name] * decay
        in_coarse = step < n_coarse
        level = coarse_level if in_coarse else 0
        # graduated robustness: the coarse phase starts L1-like (wide basin) and tightens
        widen = cfg.widen ** (1 - step / n_coarse) if in_coarse else 1.0
        ti = draw_time(rng, pool)
        ids = frames.at_time(ti)
        mine, theirs = halves(ids)
        pending = other(opt.params, level, widen, theirs, len(ids)) if theirs else None
        loss = frames_loss(model, frames, cfg, level, mine, len(ids), widen)
        smooth, entropy = model.skin_regularisers()
        loss = loss + cfg.lambda_smooth * smooth + cfg.lambda_entropy * entropy \
            + cfg.lambda_temporal * model.temporal()
        if prior is not None and cfg.lambda_prior:
            loss = loss + cfg.lambda_prior * model.prior(prior)
        if model.held and cfg.lambda_tool:
            loss = loss + cfg.lambda_tool * model.held_loss(cfg.sigma_tool * 0.01 * size,
                                                          cfg.lever_tool * size)
        if model.shading:
            loss = loss + cfg.lambda_gain * model.gain_prior()
        if model.refine_cameras:
            loss = loss + cfg.lambda_camera * model.camera_prior(np.radians(1.0), 0.01)
        opt.zero_grad()
        loss.backward()
        value = float(loss.detach())
        if pending is not None:
            their_loss, grads = pending()
            value += their_loss
            for name, g in grads.items():
                p = opt.params[name]
                p.grad = g.clone() if p.grad is None else p.grad.add_(g)
        if free is not None and "cameras" in opt.params:   # one joint's hypothesis: cameras stay
            opt.params["cameras"].grad = None
        for name in hold:
            if name in opt.params:
                opt.params[name].grad = None
        for name in ("axes", "origins", "states", "gains"):
            if name not in opt.params:
                continue
            g = opt.params[name].grad
            if g is not None:
                g.mul_(mask.view(-1, *([1] * (g.ndim - 1))))
        opt.step()
        model.load(opt.params)
        losses.append(value)
        if tick is not None:
            tick(step, losses[-1])
    model.load({k: v.detach() for k, v in opt.params.items()})
    tail = losses[-max(1, steps // 4):]
    return float(np.mean(tail))


def time_pool(frames: FrameSet, times: list[int] | None) -> list[int]:
    """The time indices a fit samples its steps from (``times``, default all)."""
    return list(range(len(frames.times))) if times is None else list(times)


def draw_time(rng: np.random.Generator, pool: list[int]) -> int:
    """A fit step's time index (the fit's only use of ``rng``)."""
    return int(rng.choice(pool))


def skip_draws(rng: np.random.Generator, frames: FrameSet, steps: int,
               times: list[int] | None = None) -> None:
    """Advance ``rng`` as a fit of ``steps`` steps over ``times`` would (:func:`fit` run
    elsewhere, in a helper process, from the same generator state)."""
    pool = time_pool(frames, times)
    for _ in range(steps):
        draw_time(rng, pool)


@torch.no_grad()
def part_level(model: ArticulatedSplat, frames: FrameSet, k: int, min_pixels: int = 64) -> int:
    """The coarsest pyramid level at which joint ``k``'s part still covers ``min_pixels`` pixels
    (median over the frames of the pixels its Gaussians fall in at full resolution, a quarter per
    level): below that a small part's motion is lost in the blur of the coarse phase."""
    pts = model.splat.means[torch.as_tensor(model.labels() == k + 1, device=model.axes.device)]
    counts = []
    for v in frames.levels[0]:
        cam = pts @ v.w2c[:3, :3].T + v.w2c[:3, 3]
        z = cam[:, 2].clamp_min(1e-6)
        u = (cam[:, 0] / z * v.K[0, 0] + v.K[0, 2]).floor().long()
        w = (cam[:, 1] / z * v.K[1, 1] + v.K[1, 2]).floor().long()
        ok = (cam[:, 2] > 0) & (u >= 0) & (w >= 0) & (u < v.width) & (w < v.height)
        counts.append(len(torch.unique(w[ok] * v.width + u[ok])))
    pixels = float(np.median(counts)) if counts else 0.0
    level = 0
    while level + 1 < len(frames.levels) and pixels / 4 ** (level + 1) >= min_pixels:
        level += 1
    return level


def score_level(model: ArticulatedSplat, frames: FrameSet, k: int, cfg: FitConfig) -> int:
    """Pyramid level of joint ``k``'s hypothesis scoring and state search: half resolution (the
    coarsest can be too small to see a part's motion, the finest too sharp to reward a part that
    is nearly in place); with ``cfg.fine_parts``, full resolution where the part covers too few
    pixels at half (:func:`part_level`: a realistic washing machine's door, 10x10 pixels at half
    resolution, scored best there turned 40 deg where it was turned 72; 64 at full)."""
    level = min(1, len(frames.levels) - 1)
    return min(level, part_level(model, frames, k)) if cfg.fine_parts else level


def first_coarse_level(model: ArticulatedSplat, frames: FrameSet, cfg: FitConfig) -> int | None:
    """Pyramid level of the first fit's coarse phase: the coarsest (None), or with
    ``cfg.fine_parts`` the coarsest where the smallest part still covers 64 pixels."""
    if not cfg.fine_parts or model.k == 0:
        return None
    return min(part_level(model, frames, k) for k in range(model.k))


@torch.no_grad()
def search_states(model: ArticulatedSplat, frames: FrameSet, k: int, cfg: FitConfig,
                  candidates: np.ndarray) -> None:
    """Set joint ``k``'s state at every moving time to the candidate value (rad / m) with the
    lowest image loss (others as they are) at :func:`score_level` (at the coarsest level a small
    part is lost in the blur and best moved anywhere: a PartNet dishwasher's front 7.7 cm out
    was searched to 58 cm there), then each value the median of itself and its neighbours in
    time (:func:`median3`)."""
    level = score_level(model, frames, k, cfg)
    unit = model.unit_of(model.types[k])
    states = model.states.clone()
    for ti, t in enumerate(frames.times):
        if t == 0:
            continue
        ids = frames.at_time(ti)

        def loss_at(v: float) -> float:
            model.states[k, ti] = v / unit
            return sum(float(frame_loss(model, frames, level, i, cfg)) for i in ids)

        states[k, ti] = best_value(loss_at, candidates)[1] / unit
        model.states[k, ti] = states[k, ti]
    at_rest = (states[k] * model.moving).cpu().numpy()       # time 0's value is 0
    states[k] = torch.as_tensor(median3(at_rest), device=states.device)
    model.states = states


def best_value(loss_at: Callable[[float], float], candidates: np.ndarray,
               halvings: int = 2) -> tuple[float, float]:
    """The lowest ``loss_at(v)`` over the ``candidates`` grid, refined by ``halvings`` rounds
    of trying half the previous spacing on either side of the best: (loss, value). The grid
    alone resolves a slide to 5 % of the object's size, and at a time a part has moved less
    than that every hypothesis scores as the part at rest (a realistic cabinet's two drawers,
    3 and 6 cm out on a 7.4 cm grid, ranked a sideways slide above their pull direction)."""
    grid = np.unique(np.asarray(candidates, float))
    best = min((loss_at(float(v)), float(v)) for v in grid)
    step = float(np.median(np.diff(grid))) if len(grid) > 1 else 0.0
    for _ in range(halvings if step > 0 else 0):
        step /= 2
        best = min([best] + [(loss_at(best[1] + d), best[1] + d) for d in (-step, step)])
    return best


def median3(values: np.ndarray) -> np.ndarray:
    """Each value the median of itself and its neighbours (the first and last kept): a part
    moves continuously, so a searched state far from both its neighbours is the part moved out
    of sight where the frame explains it poorly (a PartNet dishwasher's front 51 cm out at the
    time it had moved 1.3 cm), not its motion. A monotone run is kept as it is; a peak is cut
    to its larger neighbour, which the fit then recovers."""
    out = values.copy()
    if len(values) >= 3:
        out[1:-1] = np.median(np.stack([values[:-2], values[1:-1], values[2:]]), axis=0)
    return out
