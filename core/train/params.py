"""A splat as the optimiser's named parameter tensors, and rendering them.

The SH coefficients are split into ``sh0`` (the DC term) and ``shN`` (the rest) because they take
different learning rates (as in 3DGS); every other name is the :class:`SplatArrays` field.
"""

from __future__ import annotations

import torch

from ..model.ply import SplatArrays
from ..render.rasterize import RenderOutput, rasterize
from .views import View


def splat_params(s: SplatArrays, device: torch.device | str = "cpu") -> dict[str, torch.Tensor]:
    """The splat's arrays as float tensors on ``device`` (not requiring gradients)."""
    arrays = {"means": s.means, "quats": s.quats, "log_scales": s.log_scales,
              "opacity_logits": s.opacity_logits, "sh0": s.sh[:, :1], "shN": s.sh[:, 1:]}
    return {k: torch.as_tensor(v, device=device) for k, v in arrays.items()}


def params_splat(params: dict[str, torch.Tensor]) -> SplatArrays:
    """The parameters back as numpy arrays."""
    f = {k: v.detach().cpu() for k, v in params.items()}
    return SplatArrays(means=f["means"].numpy(), quats=f["quats"].numpy(),
                       log_scales=f["log_scales"].numpy(),
                       opacity_logits=f["opacity_logits"].numpy(),
                       sh=torch.cat([f["sh0"], f["shN"]], 1).numpy())


def render_params(params: dict[str, torch.Tensor], v: View, backend: str = "auto"
                  ) -> RenderOutput:
    """Render the parameters in view ``v`` (black background)."""
    return rasterize(params["means"], params["quats"], params["log_scales"],
                     params["opacity_logits"], torch.cat([params["sh0"], params["shN"]], 1),
                     v.K, v.w2c, v.width, v.height, None, backend)
