"""Splat preview: a point cloud of the Gaussians' centres, coloured by their SH DC term.

Each point keeps the Gaussian's size (``radius``: twice the geometric mean of the three scales,
its 2-sigma extent, grown by the square root of the thinning when the preview is capped) and ``opacity`` (sigmoid of the logit).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

import bpy
import numpy as np

from ..core.model.ply import SplatArrays, read_ply
from ..core.model.sampling import subsample
from .pointcloud import point_cloud_object

SPLAT_KEY = "artgs_splat"  # on a splat preview object: the PLY it shows (absolute path)
#: Point attribute of a splat preview: the index of each point's Gaussian in the PLY (float, exact
#: below 2^24 Gaussians), so per-Gaussian results (part labels) map onto a capped preview.
GAUSSIAN_ATTRIBUTE = "gaussian"
#: Degree-0 real spherical harmonic Y_0^0 (core.sh.C0): colour = 0.5 + C0 * dc.
SH_C0 = 0.5 / math.sqrt(math.pi)


@dataclass
class SplatPreview:
    obj: bpy.types.Object
    gaussians: int
    points: int
    seconds: float


def splat_colors(splats: SplatArrays) -> np.ndarray:
    """View-independent colour (N,3) in 0..1 (sRGB-encoded, as the capture images are)."""
    return np.clip(0.5 + SH_C0 * splats.sh[:, 0, :], 0.0, 1.0)


def build_splat_preview(context: bpy.types.Context, path: str | Path, cap: int,
                        collection: bpy.types.Collection | None = None) -> SplatPreview:
    """Read a 3DGS PLY (errors name the file) and add its preview, at most ``cap`` points."""
    path = Path(path)
    splats = read_ply(path)
    t0 = time.perf_counter()
    total = len(splats)
    keep = subsample(total, cap)
    sel = slice(None) if keep is None else keep
    thinning = 1.0 if keep is None else math.sqrt(total / len(keep))
    radius = 2.0 * np.exp(splats.log_scales[sel].astype(np.float64).mean(axis=1)) * thinning
    opacity = 1.0 / (1.0 + np.exp(-splats.opacity_logits[sel].astype(np.float64)))
    collection = collection or context.scene.collection
    name = f"{path.parent.name} splat" if path.parent.name else "splat"
    obj = point_cloud_object(name, splats.means[sel], splat_colors(splats)[sel], radius,
                             collection, extra={"opacity": opacity,
                                                GAUSSIAN_ATTRIBUTE: _indices(total, sel)})
    obj[SPLAT_KEY] = str(path.resolve())
    obj["artgs_gaussians"] = total
    return SplatPreview(obj, total, len(obj.data.vertices), time.perf_counter() - t0)


def _indices(total: int, sel) -> np.ndarray:
    return np.arange(total, dtype=np.float64)[sel]


def gaussian_indices(obj: bpy.types.Object) -> np.ndarray | None:
    """The PLY index of each vertex of a splat preview (None for other meshes)."""
    attr = obj.data.attributes.get(GAUSSIAN_ATTRIBUTE)
    if attr is None:
        return None
    values = np.empty(len(obj.data.vertices), np.float32)
    attr.data.foreach_get("value", values)
    return np.rint(values).astype(np.int64)


def splat_preview_in(folder: Path, preferred: bpy.types.Object | None = None
                     ) -> bpy.types.Object | None:
    """The splat preview of a PLY in ``folder`` (an output folder): ``preferred`` if it is one,
    else the first such object, else None."""
    folder = Path(folder).resolve()

    def shows(obj: bpy.types.Object | None) -> bool:
        return obj is not None and SPLAT_KEY in obj and Path(obj[SPLAT_KEY]).parent == folder

    if shows(preferred):
        return preferred
    return next((o for o in bpy.data.objects if shows(o)), None)
