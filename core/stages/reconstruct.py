"""Static reconstruction: a Gaussian splat from the capture's static RGB-D views -> OUT/splat.ply.

1. Initialise from the back-projected masked depth of every training view, voxel-downsampled
   (:func:`initial_splats`): colour from the pixels (SH DC), scale from the pixel footprint
   (depth / focal), a disc in the surface where the depth normals agree (else isotropic),
   opacity 0.95.
2. Optimise with Adam (per-parameter learning rates like 3DGS but lower: the depth-initialised
   splat is already close, and faster opacity/geometry rates made held-out depth drift), one random
   training view per step: ``0.8 L1 + 0.2 (1 - SSIM)`` of the render (black background) against
   the masked image (L1 summed over the image, divided by the object pixels), ``+ depth L1``
   (the rasterizer's alpha-normalised expected depth, planar per Gaussian, vs the measured depth
   where measured and inside the mask, in units of 1% of the object size), ``+ alpha L1`` against
   the mask (keeps the background empty) (core/train/losses.py); densify (clone/split on
   view-space gradient) and prune (core/train/densify.py).
3. Stop when the training loss plateaus (relative drop over a window below a tolerance) or at
   the iteration cap (core/train/loop.py); write OUT/splat.ply atomically (a cancel or crash
   leaves the previous one).

Held-out evaluation (``holdout`` = K evenly spaced static views, never trained on): PSNR of the
object pixels and depth MAE (core/train/evaluate.py) of the rasterizer's depth (each Gaussian's
linearised ray-intersection depth, see core/render/constants.py).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from ..geometry.consistency import unsupported
from ..geometry.crop_capture import SEPARATION, crop_capture, needs_separation, separation_crop
from ..model import layout
from ..model.capture import Capture, Frame
from ..model.crop import read_crop, write_crop
from ..model.errors import ArtgsError, InputError, NothingFound
from ..model.memory import available_bytes, gigabytes
from ..model.ply import SplatArrays, write_ply
from ..model.progress import Progress
from ..model.registry import ReconstructOptions
from ..render.device import resolve_device
from ..render.rasterize import RenderOutput
from ..render.sh import rgb_to_sh0
from ..train.adam import Adam
from ..train.densify import DensifyConfig, Densifier
from ..train.evaluate import evaluate, view_figures
from ..train.loop import Plateau, run_loop
from ..train.losses import LossWeights, view_loss
from ..train.params import params_splat, render_params, splat_params
from ..train.views import View, make_view

STAGE = "reconstruct"
_BYTES_PER_GAUSSIAN = 2500   # measured, see memory_estimate
_BYTES_PER_PIXEL = 30


@dataclass
class ReconstructConfig:
    """Optimisation settings (defaults tuned on the synthetic benchmark, 160x120, 24 views)."""

    max_iterations: int = 1000          # cap when no explicit iteration count is given
    sh_degree: int = 1
    loss: LossWeights = field(default_factory=LossWeights)  # depth in units of 1% of the size
    init_opacity: float = 0.95
    voxel_pixels: float = 1.0           # init voxel = this many median pixel footprints
    init_scale: float = 0.6             # init standard deviation, in pixel footprints
    init_flat: float = 0.1              # init thickness along the depth normal, x init_scale
    lr_means: float = 1.6e-5            # x object size, decaying to 1% of it
    lr_sh0: float = 2.5e-3
    lr_shN: float = 2.5e-3 / 20
    lr_opacity: float = 0.01
    lr_scales: float = 2e-3
    lr_quats: float = 1e-3
    densify: DensifyConfig = field(default_factory=DensifyConfig)
    plateau_window: int = 200           # iterations per convergence check
    plateau_tol: float = 0.02           # stop when the window mean loss drops by less than this
    seed: int = 0


# --- views ---------------------------------------------------------------------------------------

def holdout_indices(n: int, k: int) -> list[int]:
    """``k`` evenly spaced view indices out of ``n`` (the held-out views)."""
    if k <= 0:
        return []
    return sorted({min(n - 1, int((i + 0.5) * n / k)) for i in range(k)})


# --- initialisation ------------------------------------------------------------------------------

def pixel_normals(frame: Frame) -> np.ndarray:
    """World unit normals (H*W, 3) from the depth map by central differences, facing the camera;
    zero where a neighbour has no depth or lies across a depth jump (> 10 % of the depth)."""
    d = np.nan_to_num(frame.depth).astype(np.float64)
    X = frame.camera.pixel_rays() * d[..., None]
    out = np.zeros(d.shape + (3,))
    n = np.cross(X[1:-1, 2:] - X[1:-1, :-2], X[2:, 1:-1] - X[:-2, 1:-1])
    c = d[1:-1, 1:-1]
    ok = c > 0
    for nb in (d[1:-1, 2:], d[1:-1, :-2], d[2:, 1:-1], d[:-2, 1:-1]):
        ok &= (nb > 0) & (np.abs(nb - c) < 0.1 * c)
    norm = np.linalg.norm(n, axis=-1, keepdims=True)
    n = np.where(ok[..., None] & (norm > 0), n / np.maximum(norm, 1e-30), 0.0)
    n *= -np.sign(np.sum(n * X[1:-1, 1:-1], -1, keepdims=True))  # towards the camera
    c2w = np.linalg.inv(frame.camera.w2c)
    out[1:-1, 1:-1] = n @ c2w[:3, :3].T
    return out.reshape(-1, 3)


def normal_quats(normals: np.ndarray) -> np.ndarray:
    """Quaternions (w x y z) rotating the local z axis onto unit ``normals`` (sign-free)."""
    n = normals * np.where(normals[:, 2:3] < 0, -1.0, 1.0)
    q = np.stack([1 + n[:, 2], -n[:, 1], n[:, 0], np.zeros(len(n))], 1)
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def voxelize(points: np.ndarray, footprints: np.ndarray, voxel_pixels: float
             ) -> tuple[float, np.ndarray, np.ndarray]:
    """Voxel size (``voxel_pixels`` median footprints), each point's voxel number and the points
    per voxel (one initial Gaussian per voxel)."""
    voxel = float(voxel_pixels * np.median(footprints))
    cell = np.floor((points - points.min(0)) / voxel).astype(np.int64)
    dims = cell.max(0) + 1
    key = (cell[:, 0] * dims[1] + cell[:, 1]) * dims[2] + cell[:, 2]
    _, inv, counts = np.unique(key, return_inverse=True, return_counts=True)
    return voxel, inv, counts


def initial_count(frames: list[Frame], voxel_pixels: float = 1.0) -> int:
    """How many Gaussians :func:`initial_splats` would start from (points only: cheap)."""
    pts, foot = [], []
    for f in frames:
        if f.depth is None:
            continue
        world, idx = f.camera.backproject(f.depth, f.mask)
        pts.append(world)
        foot.append(f.depth.reshape(-1)[idx] / math.sqrt(f.camera.K[0, 0] * f.camera.K[1, 1]))
    if not pts or sum(len(p) for p in pts) == 0:
        return 0
    return len(voxelize(np.concatenate(pts), np.concatenate(foot), voxel_pixels)[2])


def memory_estimate(frames: list[Frame], gaussians: int) -> int:
    """Peak bytes the optimisation adds for ``gaussians`` Gaussians over ``frames``'s views.

    Measured (``artgs reconstruct`` on synthetic captures at 160x120, 320x240 and 640x480, 24
    views, peak RSS less the RSS after loading): about 2.5 KB per Gaussian (parameters, gradients,
    Adam moments, rasterizer buffers, autograd intermediates) and 30 bytes per view pixel (the
    views as tensors: RGB, mask, depth, validity), with a 1.5x margin.
    """
    pixels = sum(f.camera.width * f.camera.height for f in frames)
    return int(1.5 * (_BYTES_PER_GAUSSIAN * gaussians + _BYTES_PER_PIXEL * pixels))


def check_memory(frames: list[Frame], cfg: ReconstructConfig, max_side: int) -> None:
    """Refuse a reconstruction that would not fit in the memory this process can still use."""
    available = available_bytes()
    if available is None:
        return
    n = max(initial_count(frames, cfg.voxel_pixels), cfg.densify.max_gaussians)
    need = memory_estimate(frames, n)
    if need > available:
        w = max(f.camera.width for f in frames)
        h = max(f.camera.height for f in frames)
        raise InputError("--max-side", f"reconstructing {len(frames)} views of {w}x{h} pixels "
                         f"from about {n:,} Gaussians needs about {gigabytes(need)} of memory, but "
                         f"only {gigabytes(available)} is available; lower --max-side (now "
                         f"{max_side or 'off'}) or free memory")


def initial_splats(frames: list[Frame], *, sh_degree: int = 1, voxel_pixels: float = 1.0,
                   scale: float = 0.6, flat: float = 0.1, opacity: float = 0.95
                   ) -> tuple[SplatArrays, float]:
    """Gaussians from the frames' back-projected masked depth, voxel-downsampled.

    Returns the splat and the voxel size (metres) = ``voxel_pixels`` median pixel footprints
    (footprint = depth / focal). Each voxel's Gaussian sits at the mean of its points, with their
    mean colour and a standard deviation of ``scale`` times their mean footprint; where the
    voxel's depth normals agree it is a disc in the surface (``flat`` times thinner along the
    normal), elsewhere isotropic with identity rotation. Voxels that two or more views
    contradict (flying depth pixels, dilated masks, the noise of far views:
    :func:`unsupported`, with a margin of two voxels) are left out.
    """
    pts, cols, foot, nrm = [], [], [], []
    for f in frames:
        if f.depth is None:
            continue
        world, idx = f.camera.backproject(f.depth, f.mask)
        focal = math.sqrt(f.camera.K[0, 0] * f.camera.K[1, 1])
        pts.append(world)
        cols.append(f.rgb.reshape(-1, 3)[idx].astype(np.float64) / 255.0)
        foot.append(f.depth.reshape(-1)[idx].astype(np.float64) / focal)
        nrm.append(pixel_normals(f)[idx])
    if not pts or sum(len(p) for p in pts) == 0:
        raise InputError("capture", "no masked depth pixels in the static views to start from",
                         field="depth_file_path")
    P, C, S = np.concatenate(pts), np.concatenate(cols), np.concatenate(foot)
    voxel, inv, counts = voxelize(P, S, voxel_pixels)

    def total(a: np.ndarray) -> np.ndarray:
        return np.stack([np.bincount(inv, weights=a[:, i]) for i in range(a.shape[1])], -1)

    means, colour = total(P) / counts[:, None], total(C) / counts[:, None]
    sigma = scale * total(S[:, None])[:, 0] / counts
    normal = total(np.concatenate(nrm))
    keep = ~unsupported(means, frames, 2 * voxel)
    if keep.sum() >= 0.5 * len(keep):   # a capture the test cannot serve keeps every voxel
        means, colour, sigma, normal, counts = (a[keep] for a in (means, colour, sigma, normal,
                                                                  counts))
    n = len(counts)
    length = np.linalg.norm(normal, axis=1)
    disc = length > 0.5 * counts  # normals present and agreeing
    quats = np.tile(np.array([1.0, 0, 0, 0]), (n, 1))
    quats[disc] = normal_quats(normal[disc] / length[disc, None])
    log_scales = np.repeat(np.log(sigma)[:, None], 3, 1)
    log_scales[disc, 2] += math.log(flat)
    k = (sh_degree + 1) ** 2
    sh = np.zeros((n, k, 3), np.float32)
    sh[:, 0] = rgb_to_sh0(torch.as_tensor(colour)).numpy()
    splats = SplatArrays(
        means=means.astype(np.float32), quats=quats.astype(np.float32),
        log_scales=log_scales.astype(np.float32),
        opacity_logits=np.full(n, math.log(opacity / (1 - opacity)), np.float32),
        sh=sh)
    return splats, voxel


# --- optimisation --------------------------------------------------------------------------------

class Trainer:
    """The optimisation state: training views, Gaussians in an :class:`Adam`, densifier."""

    def __init__(self, frames: list[Frame], train_idx: list[int], cap: int,
                 cfg: ReconstructConfig, device: torch.device, backend: str = "auto") -> None:
        self.cfg, self.cap, self.backend = cfg, cap, backend
        self.train_idx = list(train_idx)
        self.init, self.voxel = initial_splats(
            [frames[i] for i in train_idx], sh_degree=cfg.sh_degree,
            voxel_pixels=cfg.voxel_pixels, scale=cfg.init_scale, flat=cfg.init_flat,
            opacity=cfg.init_opacity)
        self.views = [make_view(i, frames[i], device) for i in train_idx]
        s = self.init
        self.size = float(np.linalg.norm(s.means.max(0) - s.means.min(0)))
        self.lrs = {"means": cfg.lr_means * self.size, "quats": cfg.lr_quats,
                    "log_scales": cfg.lr_scales, "opacity_logits": cfg.lr_opacity,
                    "sh0": cfg.lr_sh0, "shN": cfg.lr_shN}
        self.opt = Adam(splat_params(s, device), self.lrs)
        self.densifier = Densifier(len(s), cfg.densify, device)
        self.depth_unit = 0.01 * self.size
        self.rng = np.random.default_rng(cfg.seed)
        self.order: list[int] = []
        self.it = 0
        self.last: tuple[RenderOutput, View] | None = None   # the latest render and its view

    @property
    def params(self) -> dict[str, torch.Tensor]:
        return self.opt.params

    def step(self) -> tuple[torch.Tensor, RenderOutput, View]:
        """One iteration on the next training view; returns (loss, render, view)."""
        cfg = self.cfg
        self.it += 1
        it = self.it
        if not self.order:
            self.order = list(self.rng.permutation(len(self.views)))
        v = self.views[self.order.pop()]
        self.opt.lrs["means"] = self.lrs["means"] * 0.01 ** min(it / self.cap, 1.0)
        p = self.opt.params
        r = render_params(p, v, self.backend)
        loss = view_loss(r, v, cfg.loss, self.depth_unit)
        self.opt.zero_grad()
        loss.backward()
        self.densifier.after_backward(it, self.cap, p["means"], v)
        self.opt.step()
        self.densifier.after_step(it, self.cap, self.opt)
        self.last = (r, v)
        return loss.detach(), r, v

    def splat(self) -> SplatArrays:
        """The current Gaussians as numpy arrays."""
        return params_splat(self.opt.params)

    def figures(self) -> dict[str, float]:
        """Progress figures of the latest step: its view's PSNR and depth MAE, Gaussian count."""
        assert self.last is not None
        return {**view_figures(*self.last), "gaussians": int(self.params["means"].shape[0])}


def reconstruct(capture: Capture, out: str | Path, progress: Progress, *,
                iterations: int | None = None, holdout: int = 0, device: str = "auto",
                backend: str = "auto", config: ReconstructConfig | None = None) -> dict[str, Any]:
    """Optimise a splat from ``capture``'s static views and write OUT/splat.ply.

    ``iterations``: fixed iteration count (no early stop); None = until converged (at most
    ``config.max_iterations``). ``holdout``: number of evenly spaced static views held out and
    evaluated. Returns the figures (also the ones recorded in report.json).
    """
    cfg = config or ReconstructConfig()
    check(capture, ReconstructOptions(iterations=iterations, holdout=holdout, device=device))
    static = capture.static
    t0 = time.perf_counter()
    dev = resolve_device(device)
    torch.manual_seed(cfg.seed)
    held = holdout_indices(len(static), holdout)
    cap = iterations or cfg.max_iterations
    trainer = Trainer(static, [i for i in range(len(static)) if i not in held], cap, cfg, dev,
                      backend)
    progress.log(f"reconstruct: {len(trainer.views)} training views, held out {held}, "
                 f"{len(trainer.init)} initial Gaussians (voxel {1000 * trainer.voxel:.1f} mm)")

    plateau = Plateau(cfg.plateau_window, cfg.plateau_tol, after=cfg.densify.until,
                      enabled=iterations is None)
    run = run_loop(lambda: float(trainer.step()[0]), trainer.it, cap, progress, STAGE,
                   plateau=plateau, figures=trainer.figures)

    result = trainer.splat()
    _refuse_unusable(result, run.iterations)
    figures: dict[str, Any] = {
        "iterations": run.iterations, "stopped": run.stopped, "gaussians": len(result),
        "initial_gaussians": len(trainer.init),
        "train_seconds": round(time.perf_counter() - t0, 2),
        "final_loss": run.final_loss,
        "holdout_views": [static[i].index for i in held],
    }
    if held:
        ev = evaluate(trainer.params, [make_view(i, static[i], dev) for i in held], backend)
        figures.update(holdout_psnr=ev["psnr"], holdout_depth_mae_mm=ev["depth_mae_mm"])
    write_ply(Path(out) / layout.SPLAT, result)
    figures["seconds"] = round(time.perf_counter() - t0, 2)
    return figures


def _refuse_unusable(result: SplatArrays, iterations: int) -> None:
    """A splat with no Gaussians or with values no splat can hold is not written over the last
    good splat.ply: the stage fails, saying what happened."""
    kept = f"{layout.SPLAT} is left as it was"
    if len(result) == 0:
        raise NothingFound(f"reconstruction ended with no Gaussians after {iterations} "
                           f"iterations (all pruned); {kept}. Check the masks and depth units")
    invalid = result.first_invalid()
    if invalid is not None:
        name, row, _, why = invalid
        raise ArtgsError(f"reconstruction diverged after {iterations} iterations (Gaussian "
                         f"{row}'s {name} {why}); {kept}")


def check(capture: Capture, options: ReconstructOptions) -> None:
    """Refuse options the capture cannot serve, or a reconstruction that would not fit in
    memory, before any work."""
    static = capture.static
    if not static:
        raise InputError(capture.root, "no static frames to reconstruct from", field="phase")
    if options.holdout < 0 or options.holdout > len(static) - 1:
        raise InputError(capture.root, f"--holdout must be 0..{len(static) - 1} "
                         f"(there are {len(static)} static views), not {options.holdout}",
                         field="holdout")
    if options.iterations is not None and options.iterations < 1:
        raise InputError(capture.root, f"--iterations must be positive, not {options.iterations}",
                         field="iterations")
    held = holdout_indices(len(static), options.holdout)
    check_memory([f for i, f in enumerate(static) if i not in held], ReconstructConfig(),
                 options.max_side)


def run(out: Path, capture: Capture, options: ReconstructOptions,
        progress: Progress) -> dict[str, Any]:
    """The reconstruct stage (registry entry): OUT/splat.ply and its figures. A capture without
    masks is first cropped to the object (:func:`separate_room`)."""
    capture, figures = separated(capture, out, progress, options.separate)
    return {**reconstruct(capture, out, progress, iterations=options.iterations,
                          holdout=options.holdout, device=options.device), **figures}


def separated(capture: Capture, out: Path, progress: Progress,
              separate: bool = True) -> tuple[Capture, dict]:
    """The capture as the stages after reconstruct see it, and the separation's figures.

    ``capture`` is already cropped by a user's box, if OUT has one (the pipeline does that); a box
    an earlier separation wrote is removed and, when ``separate`` and the static views have no
    masks, made anew (:func:`separate_room`)."""
    box = read_crop(out)
    ours = box is not None and box.source == SEPARATION     # made by an earlier run: made anew
    if ours:
        (out / layout.CROP).unlink()
    if separate and (box is None or ours) and needs_separation(capture):
        return separate_room(capture, out, progress)
    return capture, {}


def separate_room(capture: Capture, out: Path, progress: Progress) -> tuple[Capture, dict]:
    """Separate the object from the room in the static views' depth, write its box to
    OUT/crop.json and return the capture as the stages will see it (core/geometry/crop_capture.py)."""
    found = separation_crop(capture)
    if found is None:
        progress.log("reconstruct: no object separated from the room; the splat holds everything")
        return capture, {"separation": "nothing separated, the room kept"}
    box, how = found
    write_crop(out, box)
    cropped = crop_capture(capture, box)
    kept = float(np.mean([f.mask.mean() for f in cropped.static]))
    size = np.round(2 * box.half_size, 3).tolist()
    progress.log(f"reconstruct: no masks; the object separated from the room (floor by RANSAC, "
                 f"walls, the piece where the interaction cameras look): box {size} m written to "
                 f"{layout.CROP}, {100 * kept:.0f} % of the static pixels kept")
    return cropped, {"separation": {**how, "crop": layout.CROP, "box_size": size,
                                    "static_pixels_kept": round(kept, 4)}}
