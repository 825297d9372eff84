"""Capture folders (shared/spec/capture-format.md) read into typed data, validated up front.

``load_capture(path)`` either returns a fully valid :class:`Capture` or raises
:class:`~.errors.InputError` naming the file (``transforms.json`` or the image), the frame
(``index ('file_path')``) and the field. It checks everything in ``transforms.json`` for every
frame and that every referenced file exists before it decodes any image, and it writes nothing.

Decisions where the format leaves room (also the documentation of what is accepted):

- Intrinsics ``fl_x fl_y cx cy w h``, ``camera_model`` and the distortion ``k1 k2 p1 p2 k3`` may be
  at the top level or per frame; the frame's value wins. ``cx``, ``cy`` use the project's pixel
  convention (pixel (i, j) has its centre at (j + 0.5, i + 0.5)), as nerfstudio and COLMAP do.
- ``camera_model`` is ``PINHOLE`` or ``OPENCV`` (case-insensitive); without it, the model is
  ``OPENCV`` when a distortion coefficient is non-zero. ``PINHOLE`` with non-zero distortion and
  non-zero ``k4``..``k6`` are refused. Distorted frames are undistorted on load to a pinhole camera
  with the same ``K`` and size (cv2: RGB bilinear, depth and mask nearest-neighbour), which
  matches ``cv2.undistort`` with ``cx - 0.5, cy - 0.5`` (OpenCV's pixel convention) except that
  the half-pixel band at the image border is not blended with black. Pixels that see outside the
  source image get RGB 0, depth 0 and mask False (a mask is created if there was none).
- RGB must be 8-bit. Greyscale is converted to RGB; alpha is dropped. EXIF orientation is ignored
  (pixels are used as stored, which is what the intrinsics describe).
- Depth: 16-bit single-channel PNG times ``depth_unit_scale_factor`` (default 0.001 m; 8-bit PNG is
  refused), or floating-point ``.npy``/``.exr`` in metres (an EXR with several equal channels is
  accepted). Non-finite or negative depth becomes 0 (no measurement). A frame whose depth is all 0
  is refused.
- Masks: any 8/16-bit image; a pixel is object where any colour channel is non-zero (alpha ignored).
- ``time`` is required for ``interaction`` frames and must be a non-negative integer (an integral
  JSON number such as ``3.0`` is accepted); it is kept, and checked the same way, on static frames.
- A capture must have at least one ``static`` frame with depth (reconstruction needs them); this
  is checked here so every command refuses such a capture before any work.
- Poses: ``transform_matrix`` must be a finite 4x4 rigid transform: bottom row ``[0, 0, 0, 1]``,
  rotation part orthonormal within 1e-3 with determinant +1 (scaled or mirrored poses are refused).
- ``robot_joint_positions``: finite numbers; when ``robot`` is one of core/model/robots.py, as many
  as its actuated joints (or its arm joints alone). ``robot_base_pose`` (optional, top level, world
  <- robot base) is checked like a camera pose.
- Unknown keys are ignored.
"""

from __future__ import annotations

import math
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .cameras import Camera
from .errors import InputError
from .frame_files import cv2_module, read_depth, read_mask, read_rgb, undistort_maps, working_size
from .transforms import (DEFAULT_DEPTH_UNIT, TRANSFORMS, FrameSpec, check_robot_joints, is_number,
                         parse_frame, parse_pose, read_transforms)


@dataclass
class Frame:
    """One RGB-D frame, loaded and validated.

    ``rgb`` (H,W,3) uint8; ``depth`` (H,W) float32 metres, 0 where there is no measurement;
    ``mask`` (H,W) bool or None (None: every pixel is object).
    """

    index: int
    file_path: str
    camera: Camera
    rgb: np.ndarray
    depth: np.ndarray | None
    mask: np.ndarray | None
    phase: str = "static"
    time: int | None = None
    robot_joint_positions: list[float] | None = None


@dataclass
class Capture:
    """A whole capture: frames in file order, plus the optional robot model name.

    ``meta`` from :func:`load_capture`: ``transforms`` (the top-level keys of transforms.json except
    ``frames``, as read), ``depth_unit_scale_factor`` and ``undistorted`` (indices of the frames
    that were undistorted on load).
    """

    root: Path
    frames: list[Frame]
    robot: str | None = None
    meta: dict = field(default_factory=dict)
    robot_base_pose: np.ndarray | None = None   # 4x4 world <- robot base (None: not given)

    @property
    def static(self) -> list[Frame]:
        return [f for f in self.frames if f.phase == "static"]

    @property
    def interaction(self) -> list[Frame]:
        return [f for f in self.frames if f.phase == "interaction"]

    @property
    def times(self) -> list[int]:
        """Sorted distinct interaction steps."""
        return sorted({f.time for f in self.interaction if f.time is not None})


def load_capture(path: str | Path, max_side: int | None = None) -> Capture:
    """Read and validate the capture folder ``path`` (or its transforms.json); see the module doc.

    ``max_side``: the working resolution; frames whose longer side is larger are shrunk to it
    on load (intrinsics scaled with them), so big frames cost no more memory than small ones.
    """
    if max_side is not None and (not isinstance(max_side, int) or max_side < 8):
        raise InputError("--max-side", f"must be a whole number of pixels >= 8, not {max_side!r}")
    path = Path(path)
    root = path.parent if path.name == TRANSFORMS and path.is_file() else path
    if not root.is_dir():
        raise InputError(root, "capture folder not found")
    tj = root / TRANSFORMS
    top = read_transforms(tj)
    frames_raw = top.get("frames")
    if not isinstance(frames_raw, list) or not frames_raw:
        raise InputError(tj, "needs a non-empty list of frames", field="frames")
    scale = top.get("depth_unit_scale_factor", DEFAULT_DEPTH_UNIT)
    if not is_number(scale) or not math.isfinite(scale) or scale <= 0:
        raise InputError(tj, f"must be a positive number of metres per depth-PNG unit, not {scale!r}",
                         field="depth_unit_scale_factor")
    robot = top.get("robot")
    if robot is not None and not isinstance(robot, str):
        raise InputError(tj, f"must be a robot model name (a string), not {robot!r}", field="robot")

    base = top.get("robot_base_pose")
    base = None if base is None else parse_pose(base, tj, None, "robot_base_pose")
    specs = [parse_frame(i, raw, top, tj, root) for i, raw in enumerate(frames_raw)]
    check_robot_joints(specs, robot, tj)
    if not any(s.phase == "static" and s.depth_path is not None for s in specs):
        raise InputError(tj, "no static frame with depth: reconstruction needs static RGB-D views "
                         "(phase 'static' and a depth_file_path)", field="frames")
    for s in specs:
        for key, p in (("file_path", s.rgb_path), ("depth_file_path", s.depth_path),
                       ("mask_path", s.mask_path)):
            if p is not None and not p.is_file():
                raise InputError(p, "file not found", frame=s.label, field=key)

    maps: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}
    for s in specs:  # undistortion tables first, so the decoding threads only read the cache
        if s.distortion is not None:
            undistort_maps(s, maps)
    # cv2 decodes without the GIL; map() yields in order, so the first bad frame is reported.
    pool = ThreadPoolExecutor(max_workers=min(4, os.cpu_count() or 1))
    try:
        frames = list(pool.map(lambda s: _load_frame(s, float(scale), maps, max_side), specs))
    finally:
        pool.shutdown(cancel_futures=True)
    meta = {"transforms": {k: v for k, v in top.items() if k != "frames"},
            "depth_unit_scale_factor": float(scale),
            "undistorted": [s.index for s in specs if s.distortion is not None],
            "max_side": max_side,
            "resized": {s.index: [s.width, s.height] for s, f in zip(specs, frames)
                        if f.camera.width != s.width}}
    return Capture(root=root, frames=frames, robot=robot, meta=meta, robot_base_pose=base)


def resolution_note(capture: Capture) -> str | None:
    """A line for the log when frames were shrunk to the working resolution, else None."""
    resized = capture.meta.get("resized") or {}
    if not resized:
        return None
    index = next(iter(resized))
    frame = next(f for f in capture.frames if f.index == index)
    w, h = resized[index]
    return (f"working resolution {frame.camera.width}x{frame.camera.height} "
            f"(--max-side {capture.meta['max_side']}; {len(resized)} frame(s) captured at up to "
            f"{w}x{h}, intrinsics scaled)")


def _load_frame(s: FrameSpec, scale: float, maps: dict, max_side: int | None = None) -> Frame:
    rgb = read_rgb(s)
    depth = read_depth(s, scale) if s.depth_path is not None else None
    mask = read_mask(s) if s.mask_path is not None else None
    if s.distortion is not None:
        cv2 = cv2_module()
        mx, my = undistort_maps(s, maps)
        # The source image covers [-0.5, size - 0.5] in OpenCV pixel coordinates.
        seen = (mx >= -0.5) & (mx <= s.width - 0.5) & (my >= -0.5) & (my <= s.height - 0.5)
        rgb = cv2.remap(rgb, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        rgb[~seen] = 0
        if depth is not None:
            depth = cv2.remap(depth, mx, my, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT)
            depth[~seen] = 0
        if mask is not None:
            mask = cv2.remap(mask.view(np.uint8), mx, my, cv2.INTER_NEAREST,
                             borderMode=cv2.BORDER_CONSTANT).astype(bool) & seen
        elif not seen.all():
            mask = seen
    K, width, height = s.K, s.width, s.height
    if max_side is not None and max(width, height) > max_side:
        K, width, height = working_size(K, width, height, max_side)
        cv2 = cv2_module()
        size = (width, height)
        rgb = cv2.resize(rgb, size, interpolation=cv2.INTER_AREA)
        # nearest (pixel-centre exact): depths and mask labels are never blended across edges
        if depth is not None:
            depth = cv2.resize(depth, size, interpolation=cv2.INTER_NEAREST_EXACT)
        if mask is not None:
            mask = cv2.resize(mask.view(np.uint8), size,
                              interpolation=cv2.INTER_NEAREST_EXACT).astype(bool)
    return Frame(index=s.index, file_path=s.file_path,
                 camera=Camera(K, s.c2w, width, height), rgb=rgb, depth=depth, mask=mask,
                 phase=s.phase, time=s.time, robot_joint_positions=s.robot_joint_positions)


# --- `artgs validate` --------------------------------------------------------------------------

def summarize(capture: Capture) -> dict[str, Any]:
    """Plain-JSON summary of a loaded capture (what ``artgs validate`` prints)."""
    depths = [f.depth[f.depth > 0] for f in capture.frames if f.depth is not None]
    valid = np.concatenate(depths) if depths else np.zeros(0, np.float32)
    return {
        "capture": str(capture.root),
        "frames": len(capture.frames),
        "static_frames": len(capture.static),
        "interaction_frames": len(capture.interaction),
        "image_sizes": [list(wh) for wh in sorted({(f.camera.width, f.camera.height)
                                                   for f in capture.frames})],
        "interaction_times": capture.times,
        "frames_with_depth": len(depths),
        "depth_min_m": float(valid.min()) if valid.size else None,
        "depth_max_m": float(valid.max()) if valid.size else None,
        "frames_with_mask": sum(f.mask is not None for f in capture.frames),
        "undistorted_frames": len(capture.meta.get("undistorted", [])),
        "robot": capture.robot,
    }
