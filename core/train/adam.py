"""Adam over named per-Gaussian tensors whose rows can be dropped or appended (densification).

``torch.optim.Adam`` keeps its state keyed by tensor identity, which densification breaks every
time rows change; this keeps it keyed by name, so pruning and cloning are one index or concatenate.
"""

from __future__ import annotations

import torch


class Adam:
    """Adam (Kingma & Ba) with one learning rate per named parameter tensor (rows = Gaussians)."""

    def __init__(self, params: dict[str, torch.Tensor], lrs: dict[str, float],
                 betas: tuple[float, float] = (0.9, 0.999), eps: float = 1e-15) -> None:
        self.params = {k: v.detach().clone().requires_grad_(True) for k, v in params.items()}
        self.lrs = dict(lrs)
        self.betas = betas
        self.eps = eps
        self.t = 0
        self.m = {k: torch.zeros_like(v) for k, v in self.params.items()}
        self.v = {k: torch.zeros_like(v) for k, v in self.params.items()}

    def zero_grad(self) -> None:
        for p in self.params.values():
            p.grad = None

    @torch.no_grad()
    def step(self) -> None:
        """One Adam update of every parameter that has a gradient."""
        self.t += 1
        b1, b2 = self.betas
        c1, c2 = 1 - b1 ** self.t, 1 - b2 ** self.t
        for k, p in self.params.items():
            if p.grad is None:
                continue
            m, v = self.m[k], self.v[k]
            m.mul_(b1).add_(p.grad, alpha=1 - b1)
            v.mul_(b2).addcmul_(p.grad, p.grad, value=1 - b2)
            denom = (v / c2).sqrt_().add_(self.eps)
            p.addcdiv_(m, denom, value=-self.lrs[k] / c1)

    @torch.no_grad()
    def keep(self, mask: torch.Tensor) -> None:
        """Keep only the rows where ``mask`` (N,) is True (parameters and moments)."""
        for k in self.params:
            self.params[k] = self.params[k][mask].detach().requires_grad_(True)
            self.m[k] = self.m[k][mask]
            self.v[k] = self.v[k][mask]

    @torch.no_grad()
    def append(self, rows: dict[str, torch.Tensor]) -> None:
        """Append new rows (one tensor per parameter name) with zero moments."""
        for k, new in rows.items():
            self.params[k] = torch.cat([self.params[k].detach(), new]).requires_grad_(True)
            self.m[k] = torch.cat([self.m[k], torch.zeros_like(new)])
            self.v[k] = torch.cat([self.v[k], torch.zeros_like(new)])

    @torch.no_grad()
    def reset_moments(self, name: str) -> None:
        """Zero the moments of one parameter (after its values were reset)."""
        self.m[name].zero_()
        self.v[name].zero_()
