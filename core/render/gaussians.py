"""The ``Gaussians`` container: a 3D Gaussian splat as torch tensors (worker side)."""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

import numpy as np
import torch

from .sh import sh_degree


@dataclass
class Gaussians:
    """N Gaussians: ``means`` (N,3) world metres; ``quats`` (N,4) w x y z (normalised when used);
    ``log_scales`` (N,3); ``opacity_logits`` (N,); ``sh`` (N,K,3), K = (degree+1)^2, ``sh[:, 0]`` DC.
    """

    means: torch.Tensor
    quats: torch.Tensor
    log_scales: torch.Tensor
    opacity_logits: torch.Tensor
    sh: torch.Tensor

    def __post_init__(self) -> None:
        n = self.means.shape[0]
        shapes = {"means": (n, 3), "quats": (n, 4), "log_scales": (n, 3), "opacity_logits": (n,)}
        for name, shape in shapes.items():
            if tuple(getattr(self, name).shape) != shape:
                raise ValueError(f"Gaussians.{name} must have shape {shape}, "
                                 f"not {tuple(getattr(self, name).shape)}")
        if self.sh.ndim != 3 or self.sh.shape[0] != n or self.sh.shape[2] != 3:
            raise ValueError(f"Gaussians.sh must have shape (N, K, 3), not {tuple(self.sh.shape)}")
        sh_degree(self.sh.shape[1])

    @property
    def n(self) -> int:
        """Number of Gaussians."""
        return int(self.means.shape[0])

    @property
    def sh_degree(self) -> int:
        """SH degree (0..3)."""
        return sh_degree(self.sh.shape[1])

    def _map(self, fn) -> "Gaussians":
        return Gaussians(**{f.name: fn(getattr(self, f.name)) for f in fields(self)})

    def detach(self) -> "Gaussians":
        """A copy sharing storage but cut from the autograd graph."""
        return self._map(lambda t: t.detach())

    def to(self, device: torch.device | str, dtype: torch.dtype | None = None) -> "Gaussians":
        """The same Gaussians on ``device`` (and ``dtype`` if given)."""
        return self._map(lambda t: t.to(device=device, dtype=dtype))

    def tensors(self) -> list[torch.Tensor]:
        """The five parameter tensors (e.g. for an optimiser)."""
        return [getattr(self, f.name) for f in fields(self)]

    @classmethod
    def from_arrays(cls, arrays: Any, device: torch.device | str = "cpu",
                    dtype: torch.dtype = torch.float32) -> "Gaussians":
        """From a ``core.model.ply.SplatArrays`` (or any object with the same numpy attributes)."""
        def t(name: str) -> torch.Tensor:
            return torch.as_tensor(np.asarray(getattr(arrays, name)), dtype=dtype, device=device)
        return cls(**{f.name: t(f.name) for f in fields(cls)})

    def to_arrays(self):
        """As a ``core.model.ply.SplatArrays`` of float32 numpy arrays."""
        from ..model.ply import SplatArrays
        return SplatArrays(**{f.name: getattr(self, f.name).detach().cpu().numpy()
                              .astype(np.float32) for f in fields(self)})
