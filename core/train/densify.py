"""Adaptive density control of a splat during optimisation, as in 3DGS.

Gaussians whose mean view-space positional gradient is large are cloned (small ones) or split
into two smaller ones (large ones); nearly transparent or too large Gaussians are pruned.
The 3DGS threshold depends on the loss and the image size, so here it is only a floor: each
step densifies at most the ``top_fraction`` of Gaussians with the largest gradients.
Schedule: gradients are accumulated from the first iteration to ``until``; every ``every``
iterations from ``start`` on, the Gaussians are densified and pruned (:meth:`Densifier.after_step`).

The view-space (NDC) gradient is recovered from the gradient of the 3D means: for a camera-frame
mean (x, y, z), moving the projected pixel by du at fixed depth moves x by du z / fx, so
dL/du = dL/dx z / fx, and NDC coordinates are u 2 / W. This equals the screen-space mean gradient
3DGS thresholds (its default threshold 2e-4 applies).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from .adam import Adam
from ..render.cpu.project import quat_to_rotmat
from .views import View


@dataclass
class DensifyConfig:
    every: int = 100               # iterations between densification steps ...
    start: int = 100               # ... from this iteration ...
    until: int = 500               # ... to this one (gradients are accumulated up to it)
    grad_threshold: float = 2e-4   # mean NDC gradient norm that triggers clone/split
    top_fraction: float = 0.02     # ... and only for this top share of the Gaussians per step
    dense_size: float = 0.01       # metres: larger Gaussians are split, smaller ones cloned
    max_size: float = 0.1          # metres: larger Gaussians are pruned
    min_opacity: float = 0.005
    max_gaussians: int = 60000     # hard cap (time budget): densify only the top candidates


class Densifier:
    """Accumulates view-space gradients per Gaussian and applies clone/split/prune."""

    def __init__(self, n: int, config: DensifyConfig, device: torch.device | str = "cpu") -> None:
        self.config = config
        self.device = device
        self._reset(n)

    def _reset(self, n: int) -> None:
        self.grad_sum = torch.zeros(n, device=self.device)
        self.count = torch.zeros(n, device=self.device)

    @torch.no_grad()
    def accumulate(self, means: torch.Tensor, grad: torch.Tensor, w2c: torch.Tensor,
                   K: torch.Tensor, width: int, height: int) -> None:
        """Add one view's NDC positional gradient (from ``grad`` = dL/d means) where visible."""
        R, t = w2c[:3, :3], w2c[:3, 3]
        g = grad @ R.T
        z = (means @ R[2] + t[2]).clamp_min(1e-6)
        gx = g[:, 0] * z / K[0, 0] * (0.5 * width)
        gy = g[:, 1] * z / K[1, 1] * (0.5 * height)
        seen = (grad != 0).any(-1)
        self.grad_sum += torch.where(seen, torch.hypot(gx, gy), torch.zeros_like(gx))
        self.count += seen.float()

    def active(self, it: int, cap: int) -> bool:
        """Whether iteration ``it`` of at most ``cap`` is within the densification period."""
        return it <= min(self.config.until, cap)

    def after_backward(self, it: int, cap: int, means: torch.Tensor, view: View) -> None:
        """Accumulate iteration ``it``'s positional gradient (``means.grad``, rendered in
        ``view``) while densification is active."""
        if self.active(it, cap):
            self.accumulate(means.detach(), means.grad, view.w2c, view.K, view.width, view.height)

    def after_step(self, it: int, cap: int, opt: Adam) -> dict[str, int] | None:
        """Densify and prune after the optimiser step of iteration ``it`` when the schedule says
        so; returns the counts then."""
        cfg = self.config
        if self.active(it, cap) and it >= cfg.start and it % cfg.every == 0:
            return self.step(opt)
        return None

    @torch.no_grad()
    def step(self, opt: Adam) -> dict[str, int]:
        """Clone, split and prune the optimiser's Gaussians; returns the counts."""
        cfg = self.config
        p = opt.params
        n = p["means"].shape[0]
        avg = self.grad_sum / self.count.clamp_min(1)
        size = p["log_scales"].exp().amax(-1)
        seen = self.count > 0
        cutoff = cfg.grad_threshold
        if cfg.top_fraction < 1 and bool(seen.any()):
            cutoff = max(cutoff, float(torch.quantile(avg[seen], 1 - cfg.top_fraction)))
        cand = seen & (avg >= cutoff)
        room = max(cfg.max_gaussians - n, 0)
        if int(cand.sum()) > room:  # keep the strongest candidates only
            cand = torch.zeros_like(cand)
            if room:
                cand[avg.topk(room).indices] = True
        clone = cand & (size <= cfg.dense_size)
        split = cand & (size > cfg.dense_size)
        prune = (torch.sigmoid(p["opacity_logits"]) < cfg.min_opacity) | (size > cfg.max_size)

        rows = {k: [v[clone]] for k, v in p.items()}
        if split.any():
            scales = p["log_scales"][split].exp()
            R = quat_to_rotmat(p["quats"][split])
            for _ in range(2):
                offset = (R @ (torch.randn_like(scales) * scales).unsqueeze(-1)).squeeze(-1)
                for k, v in p.items():
                    rows[k].append(v[split])
                rows["means"][-1] = rows["means"][-1] + offset
                rows["log_scales"][-1] = rows["log_scales"][-1] - torch.log(torch.tensor(1.6))
        opt.keep(~(split | prune))
        opt.append({k: torch.cat(v) for k, v in rows.items()})
        self._reset(opt.params["means"].shape[0])
        return {"cloned": int(clone.sum()), "split": int(split.sum()),
                "pruned": int((prune & ~split).sum())}
