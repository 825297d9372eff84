"""``artgs capture-preview``: a validated capture as one compact ``.npz`` for Blender's Import Capture.

The engine decodes the images (OpenCV) and back-projects the depth; Blender only reads the file
with numpy. The file (written atomically) holds, per frame in file order: ``K`` (F,3,3),
``c2w`` (F,4,4, OpenGL axes), ``width``/``height`` (F,), ``phase`` (F,) text, ``time`` (F,)
(-1 where there is none) and ``file_path`` (F,) text; the point preview: ``points`` (N,3) float32
world metres, ``colors`` (N,3) uint8 sRGB, ``radius`` (N,) float32 metres, ``points_total`` (the
points available before the cap); and ``summary`` (the JSON text of ``model.capture.summarize``).
No pickled objects: ``np.load(..., allow_pickle=False)`` reads it.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .atomic import atomic_path
from .capture import Capture, summarize
from .errors import InputError
from .sampling import subsample

#: Arrays a preview file must hold (a file without one was written by another engine version).
KEYS = ("K", "c2w", "width", "height", "phase", "time", "file_path", "points", "colors",
        "radius", "points_total", "summary")


@dataclass
class CapturePreview:
    """What Import Capture builds: per-frame cameras and a capped coloured point cloud."""

    K: np.ndarray          # (F,3,3)
    c2w: np.ndarray        # (F,4,4) OpenGL camera axes
    width: np.ndarray      # (F,) int
    height: np.ndarray     # (F,) int
    phase: np.ndarray      # (F,) str: "static" | "interaction"
    time: np.ndarray       # (F,) int, -1 = none
    file_path: np.ndarray  # (F,) str
    points: np.ndarray     # (N,3) float32
    colors: np.ndarray     # (N,3) uint8 sRGB
    radius: np.ndarray     # (N,) float32
    points_total: int
    summary: dict[str, Any]


def capture_points(capture: Capture, cap: int, seed: int = 0
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """Static frames' masked depth back-projected, at most ``cap`` points (a deterministic random
    subset, chosen before back-projecting so memory stays bounded): world points (N,3) float32,
    sRGB colours (N,3) uint8, radius (N,) float32 metres (half a pixel's footprint, grown by the
    square root of the thinning) and the number of points available before the cap."""
    frames = [f for f in capture.static if f.depth is not None]
    valid = []
    for f in frames:
        ok = np.isfinite(f.depth) & (f.depth > 0)
        valid.append(np.flatnonzero(ok if f.mask is None else ok & f.mask))
    counts = np.array([len(v) for v in valid], dtype=np.int64)
    total = int(counts.sum())
    keep = subsample(total, cap, seed)
    thinning = 1.0 if keep is None else float(np.sqrt(total / max(len(keep), 1)))
    starts = np.concatenate([[0], np.cumsum(counts)])
    pts, cols, rads = [np.zeros((0, 3), np.float32)], [np.zeros((0, 3), np.uint8)], \
        [np.zeros(0, np.float32)]
    for k, f in enumerate(frames):
        chosen = valid[k] if keep is None else \
            valid[k][keep[(keep >= starts[k]) & (keep < starts[k + 1])] - starts[k]]
        selected = np.zeros(f.depth.size, bool)
        selected[chosen] = True
        world, idx = f.camera.backproject(f.depth, selected.reshape(f.depth.shape))
        pts.append(world.astype(np.float32))
        cols.append(f.rgb.reshape(-1, 3)[idx])
        rads.append((thinning * 0.5 * f.depth.reshape(-1)[idx] / float(f.camera.K[0, 0]))
                    .astype(np.float32))
    return np.concatenate(pts), np.concatenate(cols), np.concatenate(rads), total


def write_preview(capture: Capture, path: str | Path, max_points: int) -> CapturePreview:
    """Write the preview file of ``capture`` (at most ``max_points`` points) atomically."""
    frames = capture.frames
    points, colors, radius, total = capture_points(capture, max_points)
    preview = CapturePreview(
        K=np.stack([f.camera.K for f in frames]).astype(np.float64),
        c2w=np.stack([f.camera.c2w for f in frames]).astype(np.float64),
        width=np.array([f.camera.width for f in frames], np.int32),
        height=np.array([f.camera.height for f in frames], np.int32),
        phase=np.array([f.phase for f in frames], dtype=str),
        time=np.array([-1 if f.time is None else f.time for f in frames], np.int64),
        file_path=np.array([f.file_path for f in frames], dtype=str),
        points=points, colors=colors, radius=radius, points_total=total,
        summary=summarize(capture))
    arrays = {k: getattr(preview, k) for k in KEYS}
    arrays["points_total"] = np.int64(total)
    arrays["summary"] = np.array(json.dumps(preview.summary))
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        np.savez(fh, **arrays)
    return preview


def read_preview(path: str | Path) -> CapturePreview:
    """Read a preview file written by :func:`write_preview` (numpy only, no pickles)."""
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as data:
            missing = [k for k in KEYS if k not in data.files]
            if missing:
                raise InputError(path, f"no {', '.join(missing)}: written by another version of "
                                 "the engine? Install the same ArtGS version in both")
            arrays = {k: data[k] for k in KEYS}
    except (OSError, ValueError) as exc:
        raise InputError(path, f"not a readable capture preview ({exc})") from exc
    arrays["points_total"] = int(arrays["points_total"])
    arrays["summary"] = json.loads(str(arrays["summary"]))
    return CapturePreview(**arrays)
