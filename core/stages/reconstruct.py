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
   the mask (keeps the background empty); densify (clone/split on view-space gradient) and prune
   (core/train/densify.py).
3. Stop when the training loss plateaus (relative drop over a window below a tolerance) or at
   the iteration cap; write OUT/splat.ply atomically (a cancel or crash leaves the previous one).

Held-out evaluation (``holdout`` = K evenly spaced static views, never trained on):
- PSNR of the object pixels: the render over a black background vs the captured image, MSE over
  the 3 channels of the pixels inside the mask (values in [0,1]), ``PSNR = -10 log10(MSE)``;
- depth MAE: mean |rendered depth - measured depth| in mm over pixels inside the mask with a
  valid measured depth (rendered depth is 0 where nothing was rendered; those count), of the
  rasterizer's depth (each Gaussian's linearised ray-intersection depth, see core/render/constants.py).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from ..model import layout
from ..train.adam import Adam
from ..model.capture import Capture, Frame
from ..train.densify import DensifyConfig, Densifier
from ..render.device import resolve_device
from ..model.errors import InputError
from ..model.ply import SplatArrays, write_ply
from ..model.progress import Progress
from ..model.registry import ReconstructOptions
from ..render.rasterize import rasterize
from ..render.sh import rgb_to_sh0
from ..train.ssim import ssim

STAGE = "reconstruct"


@dataclass
class ReconstructConfig:
    """Optimisation settings (defaults tuned on the synthetic benchmark, 160x120, 24 views)."""

    max_iterations: int = 1000          # cap when no explicit iteration count is given
    sh_degree: int = 1
    lambda_ssim: float = 0.2
    lambda_depth: float = 0.1           # weight of depth L1 in units of 1% of the object size
    lambda_alpha: float = 0.5
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
    densify_every: int = 100
    densify_from: int = 100
    densify_until: int = 500            # last densification iteration
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


@dataclass
class View:
    """One static view as tensors."""

    index: int              # position in capture.static
    K: torch.Tensor
    w2c: torch.Tensor
    width: int
    height: int
    rgb: torch.Tensor       # (H,W,3) in [0,1], zero outside the mask
    mask: torch.Tensor      # (H,W) float 0/1
    depth: torch.Tensor     # (H,W) metres, 0 = no measurement
    depth_valid: torch.Tensor  # (H,W) bool: measured and inside the mask
    pixels: int             # object pixels (at least 1)


def make_view(index: int, f: Frame, device: torch.device) -> View:
    """Frame ``f`` (static view number ``index``) as tensors on ``device``."""
    def t(a: np.ndarray) -> torch.Tensor:
        return torch.as_tensor(np.ascontiguousarray(a), dtype=torch.float32, device=device)
    h, w = f.rgb.shape[:2]
    mask = np.ones((h, w), bool) if f.mask is None else f.mask.astype(bool)
    depth = np.zeros((h, w), np.float32) if f.depth is None else np.nan_to_num(f.depth)
    rgb = f.rgb.astype(np.float32) / 255.0 * mask[..., None]
    return View(index, t(f.camera.K), t(f.camera.w2c), w, h, t(rgb), t(mask), t(depth),
                 torch.as_tensor(mask & (depth > 0), device=device), max(int(mask.sum()), 1))


def render_params(params: dict[str, torch.Tensor], v: View, backend: str = "auto"):
    """Render the optimiser's parameters (``sh0``/``shN`` split) in view ``v``."""
    return rasterize(params["means"], params["quats"], params["log_scales"],
                     params["opacity_logits"], torch.cat([params["sh0"], params["shN"]], 1),
                     v.K, v.w2c, v.width, v.height, None, backend)


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


def initial_splats(frames: list[Frame], *, sh_degree: int = 1, voxel_pixels: float = 1.0,
                   scale: float = 0.6, flat: float = 0.1, opacity: float = 0.95
                   ) -> tuple[SplatArrays, float]:
    """Gaussians from the frames' back-projected masked depth, voxel-downsampled.

    Returns the splat and the voxel size (metres) = ``voxel_pixels`` median pixel footprints
    (footprint = depth / focal). Each voxel's Gaussian sits at the mean of its points, with their
    mean colour and a standard deviation of ``scale`` times their mean footprint; where the
    voxel's depth normals agree it is a disc in the surface (``flat`` times thinner along the
    normal), elsewhere isotropic with identity rotation.
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
    voxel = float(voxel_pixels * np.median(S))
    cell = np.floor((P - P.min(0)) / voxel).astype(np.int64)
    dims = cell.max(0) + 1
    key = (cell[:, 0] * dims[1] + cell[:, 1]) * dims[2] + cell[:, 2]
    _, inv, counts = np.unique(key, return_inverse=True, return_counts=True)

    def total(a: np.ndarray) -> np.ndarray:
        return np.stack([np.bincount(inv, weights=a[:, i]) for i in range(a.shape[1])], -1)

    n = len(counts)
    means, colour = total(P) / counts[:, None], total(C) / counts[:, None]
    sigma = scale * total(S[:, None])[:, 0] / counts
    normal = total(np.concatenate(nrm))
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


# --- evaluation ----------------------------------------------------------------------------------

@torch.no_grad()
def evaluate(params: dict[str, torch.Tensor], views: list[View], backend: str) -> dict[str, float]:
    """PSNR of the object pixels (dB) and depth MAE (mm) over ``views`` (see the module doc)."""
    se, n_px, ae, n_d = 0.0, 0, 0.0, 0
    for v in views:
        out = render_params(params, v, backend)
        m = v.mask.bool()
        se += float(((out.rgb - v.rgb)[m] ** 2).sum())
        n_px += 3 * int(m.sum())
        ae += float((out.depth - v.depth)[v.depth_valid].abs().sum())
        n_d += int(v.depth_valid.sum())
    mse = se / max(n_px, 1)
    return {"psnr": -10 * math.log10(max(mse, 1e-12)), "depth_mae_mm": 1000 * ae / max(n_d, 1)}


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
        params = {"means": s.means, "quats": s.quats, "log_scales": s.log_scales,
                  "opacity_logits": s.opacity_logits, "sh0": s.sh[:, :1], "shN": s.sh[:, 1:]}
        self.lrs = {"means": cfg.lr_means * self.size, "quats": cfg.lr_quats,
                    "log_scales": cfg.lr_scales, "opacity_logits": cfg.lr_opacity,
                    "sh0": cfg.lr_sh0, "shN": cfg.lr_shN}
        self.opt = Adam({k: torch.as_tensor(v, device=device) for k, v in params.items()},
                        self.lrs)
        self.densifier = Densifier(len(s), cfg.densify, device)
        self.depth_unit = 0.01 * self.size
        self.rng = np.random.default_rng(cfg.seed)
        self.order: list[int] = []
        self.it = 0

    @property
    def params(self) -> dict[str, torch.Tensor]:
        return self.opt.params

    def step(self) -> tuple[torch.Tensor, Any, View]:
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
        l1 = (r.rgb - v.rgb).abs().sum() / (3 * v.pixels)  # per object pixel
        loss = (1 - cfg.lambda_ssim) * l1 + cfg.lambda_ssim * (1 - ssim(r.rgb, v.rgb))
        if cfg.lambda_depth and v.depth_valid.any():
            loss = loss + cfg.lambda_depth / self.depth_unit * \
                (r.depth - v.depth)[v.depth_valid].abs().mean()
        if cfg.lambda_alpha:
            loss = loss + cfg.lambda_alpha * (r.alpha - v.mask).abs().mean()
        self.opt.zero_grad()
        loss.backward()
        densify_now = it <= min(cfg.densify_until, self.cap)
        if densify_now:
            self.densifier.accumulate(p["means"].detach(), p["means"].grad, v.w2c, v.K,
                                      v.width, v.height)
        self.opt.step()
        if densify_now and it >= cfg.densify_from and it % cfg.densify_every == 0:
            self.densifier.step(self.opt)
        return loss.detach(), r, v

    def splat(self) -> SplatArrays:
        """The current Gaussians as numpy arrays."""
        f = {k: v.detach().cpu() for k, v in self.opt.params.items()}
        return SplatArrays(means=f["means"].numpy(), quats=f["quats"].numpy(),
                           log_scales=f["log_scales"].numpy(),
                           opacity_logits=f["opacity_logits"].numpy(),
                           sh=torch.cat([f["sh0"], f["shN"]], 1).numpy())


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

    window: list[float] = []
    prev_window = math.inf
    stopped = "cap"
    while trainer.it < cap:
        loss, r, v = trainer.step()
        it = trainer.it
        window.append(float(loss))
        if it % 25 == 0 or it == cap:
            with torch.no_grad():
                mse = float(((r.rgb - v.rgb) ** 2)[v.mask.bool()].mean())
                mae = float((r.depth - v.depth)[v.depth_valid].abs().mean()) * 1000
            progress.update(STAGE, it / cap, f"iteration {it}/{cap}", loss=float(loss),
                            psnr=-10 * math.log10(max(mse, 1e-12)), depth_mm=mae,
                            gaussians=int(trainer.params["means"].shape[0]))
        else:
            progress.check_cancel()
        if len(window) == cfg.plateau_window:
            cur = float(np.mean(window))
            window = []
            if iterations is None and it > cfg.densify_until \
                    and prev_window - cur < cfg.plateau_tol * prev_window:
                stopped = "converged"
                break
            prev_window = cur

    result = trainer.splat()
    figures: dict[str, Any] = {
        "iterations": trainer.it, "stopped": stopped, "gaussians": len(result),
        "initial_gaussians": len(trainer.init),
        "train_seconds": round(time.perf_counter() - t0, 2),
        "final_loss": float(np.mean(window)) if window else prev_window,
        "holdout_views": [static[i].index for i in held],
    }
    if held:
        ev = evaluate(trainer.params, [make_view(i, static[i], dev) for i in held], backend)
        figures.update(holdout_psnr=ev["psnr"], holdout_depth_mae_mm=ev["depth_mae_mm"])
    write_ply(Path(out) / layout.SPLAT, result)
    figures["seconds"] = round(time.perf_counter() - t0, 2)
    return figures


def check(capture: Capture, options: ReconstructOptions) -> None:
    """Refuse options the capture cannot serve, before any work."""
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


def run(out: Path, capture: Capture, options: ReconstructOptions,
        progress: Progress) -> dict[str, Any]:
    """The reconstruct stage (registry entry): OUT/splat.ply and its figures."""
    return reconstruct(capture, out, progress, iterations=options.iterations,
                       holdout=options.holdout, device=options.device)
